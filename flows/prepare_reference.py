"""Flow: DEM tiles + their geoid -> ellipsoidal reference DEM (COG), void mask, summary."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from prefect import flow

from core.geodesy import BBox
from tasks.io.dem_tiles import MAX_HEIGHT_ERROR_M, DemSource
from tasks.io.geoid import BUNDLED_SRTM_DIR
from tasks.io.reference import ReferenceSummary, build_reference, locate_tiles, render_hillshade


@dataclass(frozen=True)
class ReferenceParams:
    """Parameters of :func:`prepare_reference`. ``srtm_dir``: the folder of DEM tiles
    (``--dem-dir``, ``--srtm-dir``; None uses the bundled tile); ``geoid``: the grid their
    heights refer to when not EGM96, or one replacing the bundled EGM96; ``vertical``: the
    heights of unnamed DEMs that do not say (``--dem-vertical``)."""

    bbox: tuple[float, float, float, float]
    out: Path
    srtm_dir: Path | None = None
    margin_deg: float = 0.0
    allow_missing_tiles: bool = False
    geoid: Path | None = None
    hillshade_png: Path | None = None
    vertical: str = "auto"
    max_height_error_m: float = MAX_HEIGHT_ERROR_M

    def box(self) -> BBox:
        return BBox(*self.bbox).expanded(self.margin_deg)

    def source(self) -> DemSource:
        return DemSource(Path(self.srtm_dir or BUNDLED_SRTM_DIR), self.vertical, self.geoid,
                         self.max_height_error_m)


@flow(name="prepare-reference", log_prints=True)
def prepare_reference(params: ReferenceParams) -> ReferenceSummary:
    """Find the DEM tiles, decide their datum, mosaic, convert to ellipsoidal heights, write
    the COG."""
    box = params.box()
    tiles = locate_tiles(params.source(), box, params.allow_missing_tiles, "--dem-vertical")
    summary = build_reference(tiles, box, Path(params.out))
    if params.hillshade_png is not None:
        render_hillshade(Path(summary.path), Path(params.hillshade_png))
    return summary
