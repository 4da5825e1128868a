"""Tasks of step 2: dense matching of a pair into a DEM (COG), tile by tile with Dask.

1. :func:`plan_dense`: the left region of interest is cut into tiles of about
   ``tile_px``; each tile is rectified and its disparity range sized from the reference DEM
   (:func:`core.matching.rectify.plan_tile_on_dem`, one Dask task per tile). Tiles the right
   image does not see are dropped; none left is "no overlap".
2. :func:`match_tiles`: each tile reads its two sensor windows, runs
   :func:`core.matching.dense_tile.dense_tile` (rectify, pointing correction, SGM, left-right
   check, triangulation) and saves its ground points to a small file in a work folder. The
   overall match rate is checked here: a pair that does not correlate stops with one line.
3. :func:`grid_dem_cog`: the DEM grid (local UTM zone) is computed block by block
   (1024 x 1024 cells, each with a halo of cells for the hole filling and the island test)
   from the point files of the tiles whose ground reaches the block
   (:func:`core.matching.grid.grid_dem`)
   and written as two COGs in one streamed pass: ``DEM.tif`` (float32 heights, NaN nodata)
   and ``DEM_mask.tif`` (0 valid, 1 mismatch, 2 occluded/outside), plus ``DEM.json``.

Nothing holds a whole-scene array: windows, one tile's points, or one block's points and
cells; freed memory is handed back after each tile and block, so the peak stays flat (SPOT
scene: 1.41 GB for half of it, 1.42 GB for all of it). Tiles run in Dask worker processes
from 8 tiles on (part of the resampling holds Python's lock), in threads below; OpenCV is set
to one thread in each. Scripts that call these tasks need the ``if __name__ == "__main__":``
guard (worker processes are spawned). The per-tile and per-block functions the workers run
are in :mod:`tasks.dense.blocks`.
"""

from __future__ import annotations

import math
import shutil
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import dask
import dask.array as darr
import numpy as np
from prefect import task
from prefect.cache_policies import NO_CACHE

from core.dem import GeoDEM
from core.errors import CoverageError, GeometryError, InputError, InsufficientDataError
from core.geodesy import utm_epsg
from core.matching.dense import MatchingConfig
from core.matching.dense_tile import TileStats
from core.matching.grid import MASK_MISMATCH, MASK_VALID, GridSpec
from core.matching.rectify import RectifyConfig, TilePlan, plan_tile_on_dem
from core.sensors.base import SensorModel
from core.sensors.footprint import PixelBox, footprint_box, scene_height_range_m
from core.sensors.viewing import point_geometry
from tasks.dense.blocks import (
    SensorImage,
    check_roi,
    dense_block,
    geoid_block,
    grid_block,
    retriangulate_block,
    tile_boxes,
    tile_points_path,
)
from tasks.io.crs import Projection
from tasks.io.dem import dem_datum, read_reference
from tasks.io.documents import layout
from tasks.io.geoid import load_geoid
from tasks.io.rasters import CHUNK, CogItem, CogOptions, atomic_write_json, write_arrays_cog
from tasks.io.sensors import LoadedModel
from tasks.scheduling import compute, threads

VERTICAL_DATUMS = ("ellipsoidal", "egm96")
VERTICAL_TAGS = {"ellipsoidal": "WGS84 ellipsoid (EPSG:4979 heights)",
                 "egm96": "EGM96 geoid (EPSG:5773), H = h - N"}


@dataclass(frozen=True)
class DenseConfig:
    """Settings of the DEM tasks.

    ``tile_px``: left-image tiles; ``margin_m``: height uncertainty searched around the
    reference (its error plus trees and buildings); ``resolution_m``: DEM cells (default
    ``2 x`` the left image's GSD); ``vertical``: ``"ellipsoidal"`` or ``"egm96"``;
    ``max_hole_cells``: holes smaller than this are filled; ``min_island_cells``: isolated
    groups of valid cells smaller than this are blanked; ``min_match_rate``: below it the
    pair is refused; ``num_workers``: parallel tiles (default one per core), in processes
    when ``processes`` (None: when there are at least 8 tiles; part of the resampling holds
    Python's lock, so threads alone gained only 10 % on 2 cores) else in threads.
    """

    tile_px: int = 1000
    margin_m: float = 50.0
    resolution_m: float | None = None
    vertical: str = "ellipsoidal"
    max_hole_cells: int = 5
    min_island_cells: int = 5
    min_match_rate: float = 0.2
    num_workers: int | None = None
    processes: bool | None = None
    progress: bool = True
    matching: MatchingConfig = field(default_factory=MatchingConfig)
    rectify: RectifyConfig = field(default_factory=RectifyConfig)

    def __post_init__(self) -> None:
        if not 64 <= self.tile_px <= 8192:
            raise InputError(f"tile_px must be in 64..8192, got {self.tile_px}")
        if not self.margin_m >= 0:
            raise InputError(f"the height margin must be >= 0 m, got {self.margin_m}")
        if self.resolution_m is not None and not self.resolution_m > 0:
            raise InputError(f"--resolution must be > 0 m, got {self.resolution_m}")
        if self.vertical not in VERTICAL_DATUMS:
            raise InputError(f"vertical datum {self.vertical!r} unknown; use one of "
                             f"{VERTICAL_DATUMS}")
        if not 0 <= self.min_match_rate < 1:
            raise InputError(f"the minimum match rate must be in [0, 1), got "
                             f"{self.min_match_rate}")
        if self.max_hole_cells < 0 or self.min_island_cells < 0:
            raise InputError("max_hole_cells and min_island_cells must be >= 0")

    @property
    def halo_cells(self) -> int:
        """The cells each grid block reads around itself: a hole the halo cuts is not
        filled, and the edge cells it would blank stay in the halo."""
        return max(self.max_hole_cells, self.min_island_cells, 1) + 1


@dataclass(frozen=True, eq=False)
class DensePlan:
    """The tiles of a pair and where their points go: ``origin_m`` is the projected point
    the point files are stored relative to (float32 offsets), ``epsg`` the UTM zone."""

    tiles: tuple[TilePlan, ...]
    n_tiles_roi: int
    roi: PixelBox  # the --roi checked (check_roi): (col0, row0, col1, row1) of the left image
    epsg: int
    origin_m: tuple[float, float]
    resolution_m: float
    gsd_m: float
    h_range_m: tuple[float, float]
    reference: str | None
    reference_vertical: dict[str, str] | None = None  # DatumDecision.to_dict()


@dataclass(frozen=True)
class DemSummary:
    """What the DEM tasks produced and measured."""

    dem_path: str
    mask_path: str
    json_path: str
    epsg: int
    vertical: str
    resolution_m: float
    width: int
    height: int
    roi: PixelBox  # as DensePlan.roi
    n_tiles: int
    n_tiles_roi: int
    completeness_pct: float
    mismatch_cells_pct: float
    overlap_cells: int
    grid_valid_pct: float
    h_min_m: float
    h_max_m: float
    match_rate_pct: float
    mismatched_pct: float
    occluded_pct: float
    y_residual_max_px: float
    pointing_dy_px: tuple[float, float]
    n_disp_range: tuple[int, int]
    tiles: tuple[dict[str, Any], ...] = ()
    reference: dict[str, str] | None = None  # the reference DEM's path and vertical datum

    def to_dict(self) -> dict[str, Any]:
        return {"format": "gcpfree.dem", "version": 1, **asdict(self)}

    def lines(self) -> list[str]:
        lo, hi = self.pointing_dy_px
        return [
            (f"DEM            {self.dem_path} ({self.width} x {self.height} cells of "
            f"{self.resolution_m:g} m, EPSG:{self.epsg}, heights {VERTICAL_TAGS[self.vertical]})"),
            f"mask           {self.mask_path} (0 valid, 1 mismatch, 2 occluded/outside)",
            (f"completeness   {self.completeness_pct:.1f} % of the {self.overlap_cells} cells "
            f"seen by both images have a height, {self.mismatch_cells_pct:.1f} % are "
            f"mismatched ({self.grid_valid_pct:.1f} % of the grid)"),
            f"heights        {self.h_min_m:.1f} .. {self.h_max_m:.1f} m",
            (f"matching       {self.match_rate_pct:.1f} % of the overlap matched, "
            f"{self.mismatched_pct:.1f} % mismatched, {self.occluded_pct:.1f} % occluded "
            f"({self.n_tiles} tiles searching {self.n_disp_range[0]}..{self.n_disp_range[1]} "
            "disparities)"),
            (f"rectification  residual y-parallax <= {self.y_residual_max_px:.3f} px; pointing "
            f"correction {lo:+.2f} .. {hi:+.2f} px"),
        ]


# as report.json holds it (relative_dem, dsm.summary): the format checked, the version 1
layout(DemSummary, tag=("format", "gcpfree.dem"), computed={"version": lambda s: 1},
       order=("format", "version"))


# ---------------------------------------------------------------------------- 1. plan


def scene_height_range(left: LoadedModel, right: LoadedModel,
                       given: tuple[float, float] | None, reference: Path | None
                       ) -> tuple[float, float]:
    """Ellipsoidal heights to assume where the reference has none (or when there is none), by
    the one rule of :func:`core.sensors.footprint.scene_height_range_m`: the range given,
    else the RPCs' own; with a reference the plan takes its range and this is only a
    fallback (any terrain), without one a rigorous pair needs heights given. The relative
    orientation uses it too, so both steps read the scene's heights the same way."""
    return scene_height_range_m([left.model, right.model], given,
                                any_terrain=reference is not None)


def _reference_dem(reference: Path, datum: str, model: SensorModel, roi: PixelBox,
                   h_range: tuple[float, float]) -> GeoDEM:
    box = footprint_box([(model, roi)], h_range)
    dem = read_reference(reference, box, datum)
    if not np.isfinite(dem.h_m).any():
        raise CoverageError(f"reference DEM {reference} has no height over the region of "
                            "interest; give a DEM covering the scene")
    return dem


@task(name="plan-dense-tiles", cache_policy=NO_CACHE)
def plan_dense(left: LoadedModel, right: LoadedModel, roi: tuple[int, int, int, int] | None,
               reference: Path | None, h_range_m: tuple[float, float],
               reference_vertical: str = "auto", cfg: DenseConfig = DenseConfig()) -> DensePlan:
    """Tiles of the ROI, rectified and sized (see the module docstring), the UTM zone and
    the cell size.

    Raises:
        InputError: the ROI is outside the left image.
        GeometryError: the right image sees no part of the ROI.
    """
    box = check_roi(roi, left.size)
    lo, hi = map(float, h_range_m)
    decision = dem_datum(reference, reference_vertical) if reference is not None else None
    dem = (_reference_dem(Path(reference), decision.datum, left.model, box, (lo, hi))
           if decision is not None else None)
    if dem is not None:
        lo, hi = dem.height_range_m()
    pad = int(cfg.matching.pointing_max_px) + 3 if cfg.matching.pointing_correction else 3
    boxes = tile_boxes(box, cfg.tile_px)
    parts = [dask.delayed(plan_tile_on_dem)(
        i, left.model, right.model, b, right.size, dem, (lo, hi), cfg.margin_m,
        right_pad_px=pad, config=cfg.rectify) for i, b in enumerate(boxes)]
    plans = [p for p in compute(parts, workers=cfg.num_workers) if p is not None]
    if not plans:
        raise GeometryError(
            f"the right image {right.image or right.source} sees no part of the left region "
            f"{box} at the terrain heights ({lo:.0f}..{hi:.0f} m): the images do not overlap "
            "there; check the pair, its models or --roi")
    plans = [replace(p, index=i) for i, p in enumerate(plans)]
    cc, rc = 0.5 * (box[0] + box[2] - 1), 0.5 * (box[1] + box[3] - 1)
    h_c = 0.5 * (lo + hi)
    geo = point_geometry(left.model, cc, rc, h_c)
    lon_c, lat_c = float(geo.lon_deg), float(geo.lat_deg)
    epsg = utm_epsg(lon_c, lat_c)
    x, y = Projection(epsg).to_xy(np.array([lon_c]), np.array([lat_c]))
    gsd = float(0.5 * (geo.gsd_across_m + geo.gsd_along_m))
    res = cfg.resolution_m if cfg.resolution_m is not None else float(f"{2.0 * gsd:.2g}")
    return DensePlan(tuple(plans), len(boxes), box, epsg,
                     (float(round(x[0], -3)), float(round(y[0], -3))), float(res), gsd, (lo, hi),
                     str(reference) if reference is not None else None,
                     None if decision is None else decision.to_dict())


# ---------------------------------------------------------------------------- 2. match


def _compute(parts: list[Any], cfg: DenseConfig, label: str) -> list[Any]:
    """The tiles as :func:`tasks.scheduling.schedule` runs them (processes from 8 tiles on,
    unless ``cfg.processes`` says)."""
    return compute(parts, workers=cfg.num_workers, processes=cfg.processes,
                   progress=cfg.progress, label=label)


@task(name="match-dense-tiles", cache_policy=NO_CACHE)
def match_tiles(plan: DensePlan, left: LoadedModel, right: LoadedModel, work: Path,
                cfg: DenseConfig = DenseConfig()) -> tuple[TileStats, ...]:
    """Match and triangulate every tile into ``work`` (see the module docstring).

    Raises:
        InsufficientDataError: the overall match rate is below ``cfg.min_match_rate``.
    """
    work = Path(work)
    shutil.rmtree(work, ignore_errors=True)  # no point file of an earlier run stays
    work.mkdir(parents=True)
    geoid = load_geoid() if cfg.vertical == "egm96" else None
    images = [SensorImage(str(m.image or m.source), m.model, m.size) for m in (left, right)]
    parts = [dask.delayed(dense_block)(
        t, *images, plan.epsg, plan.origin_m, geoid, cfg.matching,
        str(tile_points_path(work, t.index))) for t in plan.tiles]
    stats = tuple(_compute(parts, cfg, "dense matching"))
    check_match_rate(stats, cfg.min_match_rate)
    return stats


@task(name="retriangulate-tiles", cache_policy=NO_CACHE)
def retriangulate_tiles(plan: DensePlan, stats: tuple[TileStats, ...], work_in: Path,
                        work_out: Path, left: SensorModel, right: SensorModel,
                        cfg: DenseConfig = DenseConfig()) -> tuple[TileStats, ...]:
    """The matches :func:`match_tiles` saved in ``work_in`` intersected again with other
    models (the absolutely oriented ones) into ``work_out``: the final DSM without matching
    again."""
    work_out = Path(work_out)
    shutil.rmtree(work_out, ignore_errors=True)
    work_out.mkdir(parents=True)
    geoid = load_geoid() if cfg.vertical == "egm96" else None
    parts = [dask.delayed(retriangulate_block)(s, str(work_in), str(work_out), left, right,
                                               plan.epsg, plan.origin_m, geoid) for s in stats]
    return tuple(_compute(parts, cfg, "triangulation"))


def check_match_rate(stats: tuple[TileStats, ...], min_rate: float) -> None:
    """Refuse, in one line that says why, a pair whose overlap mostly failed to match."""
    n_overlap = sum(s.n_overlap for s in stats)
    if n_overlap == 0:
        raise GeometryError("no pixel of the region of interest is seen by both images: they "
                            "do not overlap there; check the pair, its models or --roi")
    rate = sum(s.n_valid for s in stats) / n_overlap
    if rate >= min_rate:
        return
    with_sparse = [s for s in stats if s.pointing_matches >= 3]
    dy = np.median([s.pointing_dy_px for s in with_sparse]) if with_sparse else math.nan
    raise InsufficientDataError(
        f"only {100 * rate:.1f} % of the overlap matched (threshold {100 * min_rate:.0f} %; "
        f"patches correlated on {len(with_sparse)} of {len(stats)} tiles, median y-parallax "
        f"{dy:.2f} px): the images do not correlate, being textureless (water, snow, "
        "shadow), clouded or too different in time, or their models disagree by more than "
        "the pointing correction's search; check the pair and its orientation")


# ---------------------------------------------------------------------------- 3. grid


def grid_spec(plan: DensePlan, stats: tuple[TileStats, ...]) -> GridSpec:
    bounds = [s.bounds_m for s in stats if s.bounds_m is not None and s.n_valid > 0]
    if not bounds:
        raise InsufficientDataError("no pixel was matched; the DEM would be empty")
    b = np.array(bounds)
    return GridSpec.covering((b[:, 0].min(), b[:, 1].min(), b[:, 2].max(), b[:, 3].max()),
                             plan.resolution_m)


@task(name="grid-dem", cache_policy=NO_CACHE)
def grid_dem_cog(plan: DensePlan, stats: tuple[TileStats, ...], work: Path, out: Path,
                 cfg: DenseConfig = DenseConfig(), keep_work: bool = False,
                 egm96_out: Path | None = None) -> DemSummary:
    """Grid the tiles' points into ``out`` (heights) and ``<out>_mask.tif``, write
    ``<out>.json``; remove the work folder unless ``keep_work``.

    With ``egm96_out`` (ellipsoidal points only), the same DEM in EGM96 heights too, in the
    same pass: ``egm96_out``, its mask and JSON, each cell's ``H = h - N`` with the bundled
    geoid at the cell's centre (:func:`tasks.dense.blocks.geoid_block`), instead of a second
    triangulation and gridding of the points; the mask is the same. Returns the summary of
    ``out``.
    """
    out = Path(out)
    if egm96_out is not None and cfg.vertical != "ellipsoidal":
        raise InputError(f"an EGM96 twin is made from ellipsoidal heights; the points are "
                         f"{cfg.vertical}")
    spec = grid_spec(plan, stats)
    halo = cfg.halo_cells
    base = darr.zeros(spec.shape, chunks=CHUNK, dtype=np.float32)
    stack = darr.map_blocks(grid_block, base, spec=spec, stats=stats, work=str(work),
                            origin_m=plan.origin_m, halo=halo,
                            max_hole_cells=cfg.max_hole_cells,
                            min_island_cells=cfg.min_island_cells, new_axis=0,
                            chunks=((3,),) + base.chunks, dtype=np.float32)
    z, mask, overlap = stack[0], stack[1].astype(np.uint8), stack[2] > 0
    mask_path = out.with_name(out.stem + "_mask.tif")
    georef = grid_georef(plan.epsg, spec, cfg.vertical)
    counts = [(mask == v).sum() for v in (MASK_VALID, MASK_MISMATCH)] + [overlap.sum()]
    items = dem_items(z, mask, out, mask_path, georef, cfg.vertical)
    extra = [*counts, darr.nanmin(z), darr.nanmax(z)]
    if egm96_out is not None:
        egm96_out = Path(egm96_out)
        big_h = darr.map_blocks(geoid_block, z, spec=spec, epsg=plan.epsg, geoid=load_geoid(),
                                dtype=np.float32)
        egm96_mask = egm96_out.with_name(egm96_out.stem + "_mask.tif")
        items += dem_items(big_h, mask, egm96_out, egm96_mask,
                           grid_georef(plan.epsg, spec, "egm96"), "egm96")
        extra += [darr.nanmin(big_h), darr.nanmax(big_h)]
    with threads(cfg.num_workers):
        n_ok, n_mis, n_overlap, zmin, zmax, *h_range = write_arrays_cog(items, extra=extra)
    n_cells = spec.n_rows * spec.n_cols
    cells = (int(n_ok), int(n_mis), int(n_overlap))
    summary = dem_summary(plan, stats, spec, out, mask_path, cfg.vertical, n_cells, cells,
                          (float(zmin), float(zmax)))
    if egm96_out is not None:
        twin = dem_summary(plan, stats, spec, egm96_out, egm96_mask, "egm96", n_cells, cells,
                           (float(h_range[0]), float(h_range[1])))
        atomic_write_json(egm96_out.with_suffix(".json"), twin.to_dict())
    atomic_write_json(out.with_suffix(".json"), summary.to_dict())
    if not keep_work:
        shutil.rmtree(work, ignore_errors=True)
    return summary


def grid_georef(epsg: int, spec: GridSpec, vertical: str) -> dict[str, Any]:
    """The DEM grid's transform and CRS; EGM96 heights carry their vertical CRS too (UTM +
    EGM96 height, a compound CRS)."""
    return {"transform": spec.geotransform(),
            "crs": f"EPSG:{epsg}" + ("+5773" if vertical == "egm96" else "")}


def dem_items(z: Any, mask: Any, out: Path, mask_path: Path, georef: dict[str, Any],
              vertical: str) -> list[CogItem]:
    """The heights and the mask of a DEM as COGs, with their tags."""
    tags = {"vertical_datum": VERTICAL_TAGS[vertical], "units": "m",
            "long_name": "height" if vertical == "ellipsoidal" else "orthometric height",
            "software": "gcpfree dsm"}
    return [CogItem(z, out, CogOptions(nodata=np.nan, tags=tags, **georef)),
            CogItem(mask, mask_path, CogOptions(
                resampling="nearest", tags={"values": "0 valid, 1 mismatch, 2 occluded or "
                                                      "outside"}, **georef))]


def dem_summary(plan: DensePlan, stats: tuple[TileStats, ...], spec: GridSpec, out: Path,
             mask_path: Path, vertical: str, n_cells: int, counts: tuple[int, int, int],
             z_range: tuple[float, float]) -> DemSummary:
    n_overlap = max(sum(s.n_overlap for s in stats), 1)
    dys = [s.pointing_dy_px for s in stats if s.pointing_applied] or [0.0]
    return DemSummary(
        dem_path=str(out), mask_path=str(mask_path), json_path=str(out.with_suffix(".json")),
        epsg=plan.epsg, vertical=vertical, resolution_m=spec.res_m, width=spec.n_cols,
        height=spec.n_rows, roi=plan.roi, n_tiles=len(stats), n_tiles_roi=plan.n_tiles_roi,
        completeness_pct=100.0 * counts[0] / max(counts[2], 1),
        mismatch_cells_pct=100.0 * counts[1] / max(counts[2], 1),
        overlap_cells=counts[2], grid_valid_pct=100.0 * counts[0] / n_cells,
        h_min_m=z_range[0], h_max_m=z_range[1],
        match_rate_pct=100.0 * sum(s.n_valid for s in stats) / n_overlap,
        mismatched_pct=100.0 * sum(s.n_mismatch for s in stats) / n_overlap,
        occluded_pct=100.0 * sum(s.n_occluded for s in stats) / n_overlap,
        y_residual_max_px=max(s.y_residual_max_px for s in stats),
        pointing_dy_px=(float(min(dys)), float(max(dys))),
        n_disp_range=(min(s.n_disp for s in stats), max(s.n_disp for s in stats)),
        tiles=tuple(s.to_dict() for s in stats),
        reference=(None if plan.reference is None else
                   {"path": plan.reference, **(plan.reference_vertical or {})}))
