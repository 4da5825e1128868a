"""CRSs of the files ``gcpfree evaluate`` reads (pyproj): the horizontal part, the vertical
datum and height unit of the vertical part, and how the report names a CRS.

Shared by the lidar reader (:mod:`tasks.io.lidar`) and the raster reader
(:mod:`tasks.io.rasters_at_points`); the rules they follow are in :mod:`tasks.evaluation.lidar`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pyproj

from core.errors import InputError
from core.evaluation.evaluation_report import CrsInfo


def existing_file(path: Path, what: str, hint: str) -> Path:
    """``path`` as a Path; InputError naming ``what`` and saying ``hint`` when it is no file."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{what} {path} does not exist; {hint}")
    return path


def vertical_datum(vcrs: pyproj.CRS) -> str | None:
    """``egm96`` for EGM96 gravity-related heights, ``ellipsoidal`` for ellipsoidal heights,
    None for any other vertical datum."""
    if vcrs.is_geographic or vcrs.is_projected:  # a 3-D CRS: its height is ellipsoidal
        return "ellipsoidal"
    datum = vcrs.datum.name if vcrs.datum else ""
    if "egm96" in datum.lower().replace(" ", "") or vcrs.to_epsg() == 5773:
        return "egm96"
    return None


@dataclass(frozen=True, eq=False)
class VerticalPart:
    """The vertical part of a CRS: datum (None: not convertible), unit, where it came from."""

    datum: str | None
    datum_name: str
    z_factor_m: float
    z_unit: str


def split_crs(crs: pyproj.CRS) -> tuple[pyproj.CRS, VerticalPart | None]:
    """The 2-D horizontal CRS and the vertical part (None when the CRS has none)."""
    if crs.is_compound:
        horiz, vert = crs.sub_crs_list[0], crs.sub_crs_list[-1]
        ax = vert.axis_info[0]
        return horiz, VerticalPart(vertical_datum(vert), vert.name, ax.unit_conversion_factor,
                                   ax.unit_name)
    if crs.is_vertical or crs.is_geocentric:
        raise InputError(f"CRS {crs.name!r} has no horizontal part; give a projected or "
                         "geographic CRS")
    if len(crs.axis_info) == 3:
        ax = crs.axis_info[2]
        return crs.to_2d(), VerticalPart("ellipsoidal", "ellipsoidal height",
                                         ax.unit_conversion_factor, ax.unit_name)
    return crs, None


def crs_info(crs: pyproj.CRS) -> CrsInfo:
    """How the report names a CRS: its name, authority code (``EPSG:32631+5773`` for a
    compound of two EPSG CRSs) and WKT."""
    auth = crs.to_authority(min_confidence=90)
    if auth is None and crs.is_compound:
        parts = [s.to_authority(min_confidence=90) for s in crs.sub_crs_list]
        if all(parts):
            auth = (parts[0][0], "+".join(p[1] for p in parts))  # type: ignore[index]
    return CrsInfo(crs.name, ":".join(auth) if auth else None, crs.to_wkt())


def unsupported_datum(what: str, name: str, option: str) -> InputError:
    """The error for heights in a vertical datum gcpfree does not convert."""
    return InputError(f"{what} heights are {name!r}, a vertical datum gcpfree cannot convert "
                      f"(EGM96 and WGS84 ellipsoidal only); convert them first, or declare "
                      f"them with {option} egm96|ellipsoidal")
