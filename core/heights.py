"""Heights as files store them: a vertical datum and a unit, brought to metres in one datum.

WGS84 ellipsoidal heights ``h`` and orthometric heights ``H`` above a geoid (EGM96, as SRTM's;
EGM2008, as Copernicus DEM's; or the geoid of a grid the user names), related by ``h = H + N``
(``N`` from a :class:`core.geoid.GeoidGrid`); the rule that decides a DEM's datum and the grid
its heights go through is :func:`decide_datum`. Three units: the metre, the
international foot (0.3048 m) and the US survey foot (1200/3937 m), under the names rasters,
CRSs and GeoTIFF keys give them. No I/O here: ``tasks`` read the names and codes from the files.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.choices import DATUMS, VERTICAL_CHOICES
from core.errors import InputError
from core.geoid import GeoidGrid

FloatArray = NDArray[np.float64]

#: metres per unit of the height units gcpfree reads
Z_UNITS: dict[str, float] = {"m": 1.0, "ft": 0.3048, "us-ft": 1200.0 / 3937.0}
UNIT_NAMES = {  # unit strings met in rasters and CRSs -> Z_UNITS key
    "m": "m", "metre": "m", "meter": "m", "metres": "m", "meters": "m",
    "ft": "ft", "foot": "ft", "feet": "ft", "international foot": "ft",
    "us-ft": "us-ft", "ftus": "us-ft", "us survey foot": "us-ft", "us_survey_foot": "us-ft",
    "foot_us": "us-ft", "us foot": "us-ft", "survey foot": "us-ft",
}
EPSG_UNITS = {9001: "m", 9002: "ft", 9003: "us-ft"}  # GeoTIFF VerticalUnitsGeoKey values


def unit_key(name: str | None, what: str) -> str | None:
    """Z_UNITS key of a unit string; None when empty; InputError when unknown."""
    if name is None or not str(name).strip():
        return None
    key = UNIT_NAMES.get(str(name).strip().lower().replace("_", " ").replace("  ", " "))
    key = key or UNIT_NAMES.get(str(name).strip().lower())
    if key is None:
        raise InputError(f"{what}: unit {name!r} not understood; convert the heights to metres "
                         "or feet, or give the unit explicitly")
    return key


@dataclass(frozen=True)
class HeightFrame:
    """How a height value is stored: its vertical ``datum`` (``"ellipsoidal"`` WGS84 or
    ``"egm96"`` orthometric) and ``z_factor_m``, metres per stored unit (0.3048 for the
    international foot, 1200/3937 for the US survey foot)."""

    datum: str
    z_factor_m: float = 1.0

    def __post_init__(self) -> None:
        if self.datum not in DATUMS:
            raise InputError(f"vertical datum {self.datum!r} unknown; use one of {DATUMS}")
        if not (self.z_factor_m > 0 and math.isfinite(self.z_factor_m)):
            raise InputError(f"height unit factor must be positive, got {self.z_factor_m}")


def height_difference_m(dem_z: ArrayLike, dem: HeightFrame, ref_z: ArrayLike, ref: HeightFrame,
                        lon_deg: ArrayLike | None = None, lat_deg: ArrayLike | None = None,
                        geoid: GeoidGrid | None = None) -> FloatArray:
    """``dz = DEM - reference`` in metres, both in the DEM's datum.

    Heights are scaled to metres; when the datums differ, the EGM96 heights are made
    ellipsoidal with ``h = H + N`` (``N`` from ``geoid`` at ``lon_deg``, ``lat_deg``), which
    then must be given. Equal datums need no geoid (N cancels).
    """
    d = np.asarray(dem_z, dtype=np.float64) * dem.z_factor_m
    r = np.asarray(ref_z, dtype=np.float64) * ref.z_factor_m
    if dem.datum == ref.datum:
        return d - r
    if geoid is None or lon_deg is None or lat_deg is None:
        raise InputError(f"DEM heights are {dem.datum} and reference heights {ref.datum}: "
                         "give the geoid and the points' lon/lat to convert them")
    n_m = geoid.undulation_m(lon_deg, lat_deg)
    return d - r + (n_m if dem.datum == "egm96" else -n_m)


# ---- the vertical datum of a DEM: one rule ----------------------------------------------------

#: orthometric datums a DEM's heights may refer to (``h = H + N``), by name; ``orthometric``:
#: heights above the geoid of the grid the user names (``--geoid``), whatever its model
GEOID_DATUMS = {"egm96": "EGM96", "egm2008": "EGM2008", "orthometric": "orthometric"}
DECIDED_DATUMS = ("ellipsoidal", *GEOID_DATUMS)
#: where users get the EGM2008 grid (PROJ's, 2.5' GeoTIFF), named in the refusals
EGM2008_GRID_HINT = ("PROJ's us_nga_egm08_25.tif, from https://cdn.proj.org/us_nga_egm08_25.tif "
                     "or `projsync --file us_nga_egm08_25`")


def _file_name(path: str) -> str:
    return path.replace("\\", "/").rsplit("/", 1)[-1]


@dataclass(frozen=True)
class DatumDecision:
    """The vertical datum of a DEM's heights, why, and the geoid they go through.

    ``datum``: ``"ellipsoidal"`` (WGS84), ``"egm96"``, ``"egm2008"``, or ``"orthometric"``
    (above the geoid of the grid given); ``source``: what decided it (the option given, the
    ``vertical_datum`` tag, the CRS's vertical part, a product's file name). ``geoid``: the grid
    N comes from for orthometric heights, None for the bundled EGM96 grid (or for ellipsoidal
    heights); ``geoid_source`` says where that grid came from (``--geoid``, PROJ's data)."""

    datum: str
    source: str
    geoid: str | None = None
    geoid_source: str | None = None

    def __post_init__(self) -> None:
        if self.datum not in DECIDED_DATUMS:
            raise InputError(f"vertical datum {self.datum!r} unknown; use one of "
                             f"{DECIDED_DATUMS}")
        if self.datum in ("egm2008", "orthometric") and self.geoid is None:
            raise InputError(f"{self.datum} heights need the geoid grid they refer to")

    @property
    def orthometric(self) -> bool:
        """Heights above a geoid, made ellipsoidal with ``h = H + N``."""
        return self.datum != "ellipsoidal"

    @property
    def geoid_label(self) -> str:
        """The geoid N comes from, for tags and lines: ``EGM96`` (the bundled grid),
        ``EGM2008, grid us_nga_egm08_25.tif``, ``geoid of grid x.gtx``; empty for ellipsoidal
        heights."""
        if not self.orthometric:
            return ""
        if self.geoid is None:
            return GEOID_DATUMS[self.datum]
        grid = f"grid {_file_name(self.geoid)}"
        return f"geoid of {grid}" if self.datum == "orthometric" else \
            f"{GEOID_DATUMS[self.datum]}, {grid}"

    def describe(self) -> str:
        """One line for the terminal: the datum, why, and what gcpfree does with it."""
        if not self.orthometric:
            return f"WGS84 ellipsoidal heights, used as they are ({self.source})"
        what = f"{GEOID_DATUMS[self.datum]} orthometric heights, converted with h = H + N"
        if self.datum == "orthometric":
            what = "orthometric heights, converted with h = H + N"
        if self.geoid is not None:
            what += f", N from {_file_name(self.geoid)} ({self.geoid_source})"
        return f"{what} ({self.source})"

    def to_dict(self) -> dict[str, str]:
        """``vertical`` and ``vertical_source``, and ``geoid`` / ``geoid_source`` when the
        heights go through a grid other than the bundled EGM96."""
        out = {"vertical": self.datum, "vertical_source": self.source}
        if self.geoid is not None:
            out.update(geoid=self.geoid, geoid_source=str(self.geoid_source))
        return out


def datum_of_tag(text: str) -> str | None:
    """``ellipsoidal``, ``egm96`` or ``egm2008`` from the text of a ``vertical_datum`` tag or a
    vertical CRS's name (gcpfree writes ``WGS84 ellipsoid ...`` or ``EGM96 ...``); None when
    the text names none of them."""
    t = text.lower()
    if "ellipsoid" in t:  # "WGS84 ellipsoid (h = SRTM H + EGM96 N)": ellipsoidal heights
        return "ellipsoidal"
    compact = t.replace(" ", "").replace("-", "").replace("_", "")
    if "egm96" in compact:
        return "egm96"
    if "egm2008" in compact or "egm08" in compact:
        return "egm2008"
    return None


def decide_datum(what: str, option: str, *, given: str = "auto", tag: str | None = None,
                 crs_datum: str | None = None, crs_vertical_name: str | None = None,
                 srtm_name: str | None = None, named: tuple[str, str] | None = None,
                 geoid: str | None = None, proj_grid: str | None = None,
                 geoid_option: str | None = None) -> DatumDecision:
    """The one rule for the vertical datum of a DEM, first that speaks wins:

    1. ``given`` (``ellipsoidal`` or ``egm96`` from the command line's ``option``);
    2. the file's ``vertical_datum`` tag (gcpfree writes one on every height raster);
    3. the vertical part of the file's CRS (a compound CRS such as EPSG:4326+5773 or
       EPSG:4326+3855, or a 3-D geographic/projected CRS, which is ellipsoidal): ``crs_datum``
       as read, with ``crs_vertical_name`` naming it;
    4. a product's file name: an SRTM file (``srtm_name``: a ``.hgt``, or a file named after
       its tile like ``N44E005.tif``) is EGM96; ``named`` gives ``(datum, reason)`` for the
       others (NASADEM: EGM96, Copernicus DEM: EGM2008);
    5. a geoid grid given (``geoid``, the command's ``geoid_option``): heights above it;
    6. else refused: guessing costs the geoid undulation (about 50 m in southern France).

    Then the geoid the heights go through: EGM96 heights through the bundled grid unless
    ``geoid`` replaces it; EGM2008 heights through ``geoid``, else PROJ's own grid
    (``proj_grid``), else refused in one line naming ``geoid_option``. A command that cannot
    take a geoid grid (``geoid_option`` None) refuses every datum but EGM96 and ellipsoidal;
    a datum gcpfree does not know (NAVD88...) is read only through a ``geoid`` given.

    Raises:
        InputError: unknown ``given``, unconvertible datum, no grid, or nothing says it.
    """
    if given not in VERTICAL_CHOICES:
        raise InputError(f"{option} {given!r} unknown; use one of {VERTICAL_CHOICES}")
    found = _datum_said(what, option, given, tag, crs_datum, crs_vertical_name, srtm_name,
                        named, geoid, geoid_option)
    if found is None:
        give = f"give {option} egm96 or {option} ellipsoidal"
        if geoid_option is not None:
            give += f", or {geoid_option} GRID for heights above another geoid"
        raise InputError(f"{what} does not say whether its heights are ellipsoidal or EGM96 "
                         "(no vertical_datum tag, no vertical CRS, not an SRTM, NASADEM or "
                         f"Copernicus tile name); {give}")
    datum, source = found
    return _with_geoid(what, DatumDecision(datum, source) if datum in DATUMS else None,
                       datum, source, geoid, proj_grid, geoid_option)


def _datum_said(what: str, option: str, given: str, tag: str | None, crs_datum: str | None,
                crs_vertical_name: str | None, srtm_name: str | None,
                named: tuple[str, str] | None, geoid: str | None,
                geoid_option: str | None) -> tuple[str, str] | None:
    """Steps 1-5 of :func:`decide_datum`: ``(datum, source)``, or None when nothing says."""
    if given != "auto":
        return given, f"given: {option} {given}"
    if tag is not None and tag.strip():
        datum = datum_of_tag(tag)
        if datum is None:
            return _unknown(what, f"its vertical_datum tag {tag!r} names", option, geoid,
                            geoid_option, f"tag vertical_datum={tag!r}")
        return datum, f"tag vertical_datum={tag!r}"
    if crs_vertical_name is not None:
        datum = crs_datum or datum_of_tag(crs_vertical_name)
        if datum is None:
            return _unknown(what, f"its heights are {crs_vertical_name!r},", option, geoid,
                            geoid_option, f"CRS: {crs_vertical_name}")
        return datum, f"CRS: {crs_vertical_name}"
    if srtm_name is not None:
        return "egm96", f"SRTM file {srtm_name}: EGM96"
    if named is not None:
        return named
    if geoid is not None and geoid_option is not None:
        return "orthometric", f"given: {geoid_option} {_file_name(geoid)}"
    return None


def _unknown(what: str, says: str, option: str, geoid: str | None, geoid_option: str | None,
             source: str) -> tuple[str, str]:
    """A datum gcpfree does not know: heights above the grid given, else refused."""
    if geoid is not None and geoid_option is not None:
        return "orthometric", source
    through = (f"; give the geoid grid they refer to with {geoid_option} GRID"
               if geoid_option is not None else "")
    raise InputError(f"{what}: {says} a vertical datum gcpfree cannot convert by itself "
                     f"(EGM96, EGM2008 and WGS84 ellipsoidal only){through}; or convert the "
                     f"heights first, or declare them with {option} egm96|ellipsoidal")


def _with_geoid(what: str, plain: DatumDecision | None, datum: str, source: str,
                geoid: str | None, proj_grid: str | None,
                geoid_option: str | None) -> DatumDecision:
    """The decision with the grid its heights go through (the last part of the rule)."""
    if datum == "ellipsoidal":
        if geoid is not None:
            raise InputError(f"{what}: its heights are WGS84 ellipsoidal ({source}), so no "
                             f"geoid applies: drop {geoid_option or '--geoid'}")
        return plain  # type: ignore[return-value]
    if geoid is not None:
        return DatumDecision(datum, source, geoid, f"given: {geoid_option or '--geoid'}")
    if datum == "egm96":
        return plain  # type: ignore[return-value]
    if geoid_option is None:
        raise InputError(f"{what}: its heights are {GEOID_DATUMS[datum]} ({source}), which this "
                         "command does not convert; make an ellipsoidal reference of it first: "
                         "gcpfree prepare-reference --dem-dir DIR --geoid GRID")
    if proj_grid is not None:
        return DatumDecision(datum, source, proj_grid, "PROJ's grid")
    raise InputError(f"{what}: its heights are {GEOID_DATUMS[datum]} ({source}) and PROJ has no "
                     f"{GEOID_DATUMS[datum]} grid here: give it with {geoid_option} GRID "
                     f"({EGM2008_GRID_HINT}); never read as EGM96")
