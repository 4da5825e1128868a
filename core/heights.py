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
