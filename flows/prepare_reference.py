"""Flow: SRTM tiles + EGM96 geoid -> ellipsoidal reference DEM (COG), void mask, summary."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from prefect import flow

from core.geodesy import BBox
from tasks.io.geoid import BUNDLED_SRTM_DIR
from tasks.io.reference import ReferenceSummary, build_reference, locate_tiles, render_hillshade


@dataclass(frozen=True)
class ReferenceParams:
    """Parameters of :func:`prepare_reference`. ``srtm_dir=None`` uses the bundled tile."""

    bbox: tuple[float, float, float, float]
    out: Path
    srtm_dir: Path | None = None
    margin_deg: float = 0.0
    allow_missing_tiles: bool = False
    geoid: Path | None = None
    hillshade_png: Path | None = None

    def box(self) -> BBox:
        return BBox(*self.bbox).expanded(self.margin_deg)


@flow(name="prepare-reference", log_prints=True)
def prepare_reference(params: ReferenceParams) -> ReferenceSummary:
    """Find the SRTM tiles, mosaic, convert to ellipsoidal heights, write the COG."""
    box = params.box()
    tiles = locate_tiles(Path(params.srtm_dir or BUNDLED_SRTM_DIR), box, params.allow_missing_tiles)
    summary = build_reference(tiles, box, Path(params.out), params.geoid)
    if params.hillshade_png is not None:
        render_hillshade(Path(summary.path), Path(params.hillshade_png))
    return summary
