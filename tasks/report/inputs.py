"""The products of an orient output folder the run report reads, each read once; a missing or
unreadable one is None and noted, never raised (:mod:`tasks.report.build` says it is not available).

Read: ``windows.json``, ``relative/rel.tiepoints.json``, ``gcps.json`` and the reference DEM
over the relative DEM's extent. No maths here and no drawing.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import rasterio

from core.dem import GeoDEM
from core.errors import InputError
from core.geodesy import ARCSEC, BBox
from core.matching.surface import SurfaceMatchConfig
from core.points import ControlPoint
from tasks.absolute.report import OrientReport
from tasks.absolute.surface_match import TieGround
from tasks.io.crs import Projection
from tasks.io.dem import dem_datum, read_reference
from tasks.io.products import GCPS
from tasks.io.rasters import read_json

log = logging.getLogger(__name__)

TIEPOINTS = Path("relative") / "rel.tiepoints.json"
MADE_REFERENCE = Path("relative") / "rel.reference.tif"  # made from SRTM tiles (--srtm-dir)


def read_optional_json(path: Path) -> Any:
    """A JSON product, or None when it is missing or unreadable."""
    try:
        return read_json(path, "product")
    except InputError:
        return None


@dataclass(frozen=True, eq=False)
class ReportInputs:
    """The products beside report.json (None: missing or unreadable)."""

    windows: list[dict[str, Any]] | None
    ties: TieGround | None
    tie_doc: dict[str, Any] | None
    gcps: tuple[ControlPoint, ...] | None
    reference: GeoDEM | None
    surface: SurfaceMatchConfig


def _attempt(missing: list[str], what: str, read: Callable[[], Any]) -> Any:
    """``read()``, or None with the reason appended to ``missing`` when it fails."""
    try:
        return read()
    except Exception as exc:  # a report never fails the run
        log.warning("report: cannot read %s", what, exc_info=True)
        missing.append(f"{what} ({type(exc).__name__}: {exc})")
        return None


def read_inputs(out: Path, reference: Path | None, vertical: str, surface: SurfaceMatchConfig,
                missing: list[str], orientation: OrientReport | None = None) -> ReportInputs:
    """Read the products of ``out`` (and ``reference`` over the relative DEM's extent); what
    cannot be read is appended to ``missing`` with its reason. The windows and the GCPs are
    read from the files ``orientation`` (report.json) names, by default those orient writes."""
    windows_file = orientation.surface_matching.windows_file if orientation else "windows.json"
    gcps_file = orientation.gcps.file if orientation else "gcps.json"
    wdoc = read_optional_json(out / windows_file)
    tie_path = out / TIEPOINTS
    tie_doc = read_optional_json(tie_path)
    ties = (_attempt(missing, "the tie points", lambda: TieGround.from_tiepoints_json(tie_path))
            if tie_doc is not None else None)
    gdoc = read_optional_json(out / gcps_file)
    gcps = (_attempt(missing, gcps_file, lambda: GCPS.load(gdoc, gcps_file).points)
            if gdoc is not None else None)
    ref = None
    if reference is not None and (out / "relative_dem.tif").is_file():
        ref = _attempt(missing, f"the reference DEM {reference}", lambda: read_reference(
            reference, dem_box(out / "relative_dem.tif", surface),
            dem_datum(reference, vertical).datum))
    windows = wdoc.get("windows") if isinstance(wdoc, dict) else None
    return ReportInputs(windows, ties, tie_doc if isinstance(tie_doc, dict) else None, gcps,
                        ref, surface)


def dem_box(dem_path: Path, cfg: SurfaceMatchConfig) -> BBox:
    """The relative DEM's extent in lon/lat, widened by the shifts searched and a margin."""
    with rasterio.open(dem_path) as src:
        b, epsg = src.bounds, src.crs.to_epsg()
    lon, lat = Projection(epsg).to_lonlat(np.array([b.left, b.right, b.left, b.right]),
                                          np.array([b.bottom, b.bottom, b.top, b.top]))
    box = BBox(float(lon.min()), float(lat.min()), float(lon.max()), float(lat.max()))
    return box.expanded((cfg.shift_max_arcsec + 10.0) * ARCSEC)


def best_window(inp: ReportInputs) -> tuple[dict[str, Any], float, float] | None:
    """The matched window with the sharpest peak (smallest precision) and its centre (lon,
    lat degrees: its tie point's relative ground position)."""
    if inp.windows is None or inp.ties is None:
        return None
    ok = [w for w in inp.windows if w.get("status") == "OK"
          and w.get("precision_m") is not None and w.get("tie_point") is not None]
    if not ok:
        return None
    w = min(ok, key=lambda w: w["precision_m"])
    i = int(w["tie_point"])
    if not 0 <= i < inp.ties.lon_deg.size:
        return None
    return w, float(inp.ties.lon_deg[i]), float(inp.ties.lat_deg[i])
