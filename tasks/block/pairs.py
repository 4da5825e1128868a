"""A block's stereo pairs before the adjustment: each pair's relative DEM (its images under the
block's joint relative orientation, on one grid for the whole block) and the surface-matching
windows around its tie points against the reference, whose good ones are GCPs measured in the
pair's two images (named as the block names them), with the pair's relief verdict; after the
adjustment, each pair's matches intersected again with the oriented models."""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

from core.geodesy import ARCSEC
from core.matching.relief import ReliefVerdict
from core.matching.surface import SurfaceMatchConfig
from core.orientation.ties import TieObservations
from core.points import ControlPoint
from core.sensors.base import SensorModel
from tasks.absolute.surface_match import SurfaceMatchResult, match_surfaces
from tasks.block.ties import pair_ties
from tasks.dense.dem import (
    DemSummary,
    DenseConfig,
    DensePlan,
    TileStats,
    grid_dem_cog,
    match_tiles,
    plan_dense,
    retriangulate_tiles,
    scene_height_range,
)
from tasks.dense.multiview import MatchedViewPair, b_over_h, unify_plans
from tasks.io.dem import read_reference
from tasks.io.products import WINDOWS
from tasks.io.sensors import LoadedModel
from tasks.relative.orientation import pair_box


@dataclass(frozen=True, eq=False)
class StereoPair:
    """One stereo pair of the block: its id, its images (indices into the block's and their
    names), its plan, matched tiles and their folder, its B/H."""

    id: str
    images: tuple[int, int]
    names: tuple[str, str]
    plan: DensePlan
    stats: tuple[TileStats, ...]
    work: Path
    b_over_h: float


@dataclass(frozen=True, eq=False)
class PairControl:
    """A stereo pair's relative DEM, its windows (GCPs measured in its two images) and the
    relief verdict on them."""

    pair: StereoPair
    dem: DemSummary
    windows: SurfaceMatchResult
    verdict: ReliefVerdict

    @property
    def gcps(self) -> tuple[ControlPoint, ...]:
        return self.windows.gcps if self.verdict.enough else ()


def match_stereo_pairs(views: tuple[LoadedModel, ...], names: tuple[str, ...],
                       pairs: tuple[tuple[str, int, int], ...], reference: Path,
                       vertical: str, out: Path, cfg: DenseConfig) -> tuple[StereoPair, ...]:
    """Every stereo pair (id, left index, right index) planned on one grid (the first pair's
    UTM zone, origin and cell size: :func:`tasks.dense.multiview.unify_plans`) and matched
    into ``out/.ID.work``."""
    plans = []
    for _, i, j in pairs:
        h_range = scene_height_range(views[i], views[j], None, reference)
        plans.append(plan_dense(views[i], views[j], None, reference, h_range, vertical, cfg))
    out_pairs = []
    for (pid, i, j), plan in zip(pairs, unify_plans(plans), strict=True):
        work = Path(out) / f".{pid}.work"
        stats = match_tiles(plan, views[i], views[j], work, cfg)
        out_pairs.append(StereoPair(pid, (i, j), (names[i], names[j]), plan, stats, work,
                                    b_over_h(views[i], views[j], 0.5 * sum(plan.h_range_m))))
    return tuple(out_pairs)


def pair_control(pair: StereoPair, views: tuple[LoadedModel, ...], ties: TieObservations,
                 reference: Path, vertical: str, out: Path, cfg: DenseConfig,
                 surface: SurfaceMatchConfig, spacing_m: float | None, min_windows: int,
                 first_id: int, workers: int | None = None) -> PairControl:
    """The pair's relative DEM (``out/ID/relative_dem.tif``, its matches kept for the final
    DSM) and its surface-matching windows (``out/ID/windows.json``), GCPs numbered from
    ``first_id``."""
    i, j = pair.images
    folder = Path(out) / pair.id
    folder.mkdir(parents=True, exist_ok=True)
    dem = grid_dem_cog(pair.plan, pair.stats, pair.work, folder / "relative_dem.tif", cfg,
                       keep_work=True)
    margin = (surface.shift_max_arcsec + 5.0) * ARCSEC
    box = pair_box(views[i], views[j], (dem.h_min_m, dem.h_max_m)).expanded(margin)
    ref = read_reference(reference, box, vertical)
    windows = match_surfaces(folder / "relative_dem.tif", pair_ties(ties, i, j), ref, surface,
                             spacing_m, names=pair.names, out=None, progress=False,
                             workers=workers, models=(views[i].model, views[j].model))
    windows = replace(windows, gcps=tuple(replace(p, id=first_id + k)
                                          for k, p in enumerate(windows.gcps)))
    WINDOWS.write(folder / "windows.json", windows.document())
    return PairControl(pair, dem, windows, windows.verdict(surface, min_windows,
                                                           ref.cell_size_m()))


def final_pair(pair: StereoPair, models: tuple[SensorModel, ...], out: Path,
               cfg: DenseConfig) -> tuple[MatchedViewPair, DemSummary]:
    """The pair's matches intersected again with the oriented ``models`` (into
    ``out/.ID.final``) and its DSM ``out/ID/dsm.tif``; the matched pair as the multi-view
    fusion takes it."""
    i, j = pair.images
    work = Path(out) / f".{pair.id}.final"
    stats = retriangulate_tiles(pair.plan, pair.stats, pair.work, work, models[i], models[j],
                                cfg)
    dsm = grid_dem_cog(pair.plan, stats, work, Path(out) / pair.id / "dsm.tif", cfg,
                       keep_work=True)
    return MatchedViewPair(pair.images, pair.plan, stats, work, pair.b_over_h), dsm
