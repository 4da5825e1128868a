"""Heights as files store them: a vertical datum and a unit, brought to metres in one datum.

Two datums: WGS84 ellipsoidal heights ``h`` and EGM96 orthometric heights ``H``, related by
``h = H + N`` (``N`` from a :class:`core.geoid.GeoidGrid`). Three units: the metre, the
international foot (0.3048 m) and the US survey foot (1200/3937 m), under the names rasters,
CRSs and GeoTIFF keys give them. No I/O here: ``tasks`` read the names and codes from the files.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.errors import InputError
from core.geoid import GeoidGrid

FloatArray = NDArray[np.float64]

DATUMS = ("ellipsoidal", "egm96")
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

VERTICAL_CHOICES = ("auto", *DATUMS)


@dataclass(frozen=True)
class DatumDecision:
    """The vertical datum of a DEM's heights and why: ``datum`` is ``"ellipsoidal"`` or
    ``"egm96"``; ``source`` says what decided it (the option given, the ``vertical_datum``
    tag, the CRS's vertical part, or an SRTM file name)."""

    datum: str
    source: str

    def describe(self) -> str:
        """One line for the terminal: the datum, why, and what gcpfree does with it."""
        what = ("EGM96 orthometric heights, converted with h = H + N" if self.datum == "egm96"
                else "WGS84 ellipsoidal heights, used as they are")
        return f"{what} ({self.source})"

    def to_dict(self) -> dict[str, str]:
        return {"vertical": self.datum, "vertical_source": self.source}


def datum_of_tag(text: str) -> str | None:
    """``ellipsoidal`` or ``egm96`` from the text of a ``vertical_datum`` tag (gcpfree writes
    ``WGS84 ellipsoid ...`` or ``EGM96 ...``); None when the text names neither."""
    t = text.lower()
    if "ellipsoid" in t:  # "WGS84 ellipsoid (h = SRTM H + EGM96 N)": ellipsoidal heights
        return "ellipsoidal"
    if "egm96" in t.replace(" ", "") or "egm 96" in t:
        return "egm96"
    return None


def decide_datum(what: str, option: str, *, given: str = "auto", tag: str | None = None,
                 crs_datum: str | None = None, crs_vertical_name: str | None = None,
                 srtm_name: str | None = None) -> DatumDecision:
    """The one rule for the vertical datum of a DEM, first that speaks wins:

    1. ``given`` (``ellipsoidal`` or ``egm96`` from the command line's ``option``);
    2. the file's ``vertical_datum`` tag (gcpfree writes one on every height raster);
    3. the vertical part of the file's CRS (a compound CRS such as EPSG:4326+5773, or a 3-D
       geographic/projected CRS, which is ellipsoidal): ``crs_datum`` as read, with
       ``crs_vertical_name`` naming it;
    4. an SRTM file (``srtm_name``: a ``.hgt``, or a file named after its tile like
       ``N44E005.tif``), whose heights are EGM96;
    5. else refused: guessing costs the geoid undulation (about 50 m in southern France).

    ``what`` names the file in messages (``reference DEM x.tif``). A tag or a vertical CRS in
    a datum gcpfree does not convert is refused too.

    Raises:
        InputError: unknown ``given``, unconvertible datum, or nothing says the datum.
    """
    if given not in VERTICAL_CHOICES:
        raise InputError(f"{option} {given!r} unknown; use one of {VERTICAL_CHOICES}")
    if given != "auto":
        return DatumDecision(given, f"given: {option} {given}")
    if tag is not None and tag.strip():
        datum = datum_of_tag(tag)
        if datum is None:
            raise InputError(f"{what}: its vertical_datum tag {tag!r} names a datum gcpfree "
                             f"cannot convert (EGM96 and WGS84 ellipsoidal only); convert the "
                             f"heights first, or declare them with {option} egm96|ellipsoidal")
        return DatumDecision(datum, f"tag vertical_datum={tag!r}")
    if crs_vertical_name is not None:
        if crs_datum not in DATUMS:
            raise InputError(f"{what}: its heights are {crs_vertical_name!r}, a vertical datum "
                             "gcpfree cannot convert (EGM96 and WGS84 ellipsoidal only); "
                             f"convert them first, or declare them with {option} "
                             "egm96|ellipsoidal")
        return DatumDecision(crs_datum, f"CRS: {crs_vertical_name}")
    if srtm_name is not None:
        return DatumDecision("egm96", f"SRTM file {srtm_name}: EGM96")
    raise InputError(f"{what} does not say whether its heights are ellipsoidal or EGM96 (no "
                     "vertical_datum tag, no vertical CRS, not an SRTM tile name); give "
                     f"{option} egm96 or {option} ellipsoidal")
