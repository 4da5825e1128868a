"""Flow ``dsm`` (``gcpfree dsm``, :mod:`flows.commands.dsm`): a stereo pair's DSM by dense
matching, on Dask tiles, or the DSM of N views.

relative orientation of the pair (``flows.relative``) -> tiles rectified and sized from the
reference DEM -> each tile matched (SGM) and triangulated -> median per cell in the local UTM
zone, small holes filled -> ``DSM.tif``, ``DSM_mask.tif``, ``DSM.json``.

With ``images`` (``--images A B C ...``): one joint relative orientation of all of them (the
first fixed, ``flows.relative.views_models``) -> every overlapping pair matched as above ->
their heights fused per cell (:mod:`core.matching.fusion`) -> ``DSM.tif``, ``DSM_mask.tif``,
``DSM_views.tif`` (images per cell), ``DSM.json`` (with ``pairwise_median_m``).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

from prefect import flow

from core.matching.dense import MatchingConfig
from core.matching.dense_tile import TileStats
from core.matching.fusion import FusionConfig
from tasks.dense.dem import DemSummary, DenseConfig, DensePlan
from tasks.dense.multiview import MatchedViewPair, ViewsDemSummary
from tasks.io.pair import PairInputs
from tasks.io.sensors import LoadedModel

VERTICALS = ("ellipsoidal", "egm96")


@dataclass(frozen=True)
class DsmParams:
    """Parameters of :func:`dsm_flow` (see ``gcpfree dsm --help``): the pair (its reference
    optional), the output DSM and the settings.

    ``orient``: orient the pair first (``flows.relative.relative_models``); without it the
    models are used as they are (consistent models, e.g. the simulator's truth or RPCs
    trusted relative to each other). ``height_range_m``: the scene's ellipsoidal heights when
    there is no reference DEM (default for RPCs: their height offset +- scale). ``images``:
    the DSM of these N views (``roi`` in the first), the pair's options for them all.
    """

    pair: PairInputs
    out: Path
    roi: tuple[int, int, int, int] | None = None
    resolution_m: float | None = None
    height_range_m: tuple[float, float] | None = None
    vertical: str = "ellipsoidal"
    orient: bool = True
    margin_m: float = 50.0
    tile_px: int = 1000
    min_match_rate: float = 0.2
    pointing_correction: bool = True
    workers: int | None = None
    progress: bool = True
    images: tuple[Path, ...] = ()  # N views (the pair's left and right are the first two)
    fusion: str = "weighted_median"  # of the views' pairs: core.matching.fusion.FUSION_METHODS

    def fusion_config(self) -> FusionConfig:
        """How the views' pairs are fused (checked: a bad value raises InputError)."""
        return FusionConfig(method=self.fusion)

    def config(self) -> DenseConfig:
        """The tasks' settings (checked: a bad value raises InputError)."""
        return DenseConfig(
            tile_px=self.tile_px, margin_m=self.margin_m, resolution_m=self.resolution_m,
            vertical=self.vertical, min_match_rate=self.min_match_rate,
            num_workers=self.workers, progress=self.progress,
            matching=replace(MatchingConfig(), pointing_correction=self.pointing_correction))


@dataclass(frozen=True, eq=False)
class OrientedPair:
    """The two models ready for matching and the reference DEM (with its vertical datum)."""

    left: LoadedModel
    right: LoadedModel
    reference: Path | None
    reference_vertical: str


def oriented_pair(params: DsmParams) -> OrientedPair:
    """The pair relatively oriented by ``flows.relative.relative_models`` (its products in
    ``<out>_relative/``), or with ``orient=False`` the models as found; a reference prepared
    from ``srtm_dir`` when that is what was given."""
    out, pair = Path(params.out), params.pair
    if params.orient:
        from flows.relative import relative_models

        outcome = relative_models(pair, out.parent / f"{out.stem}_relative", params.workers)
        same = pair.reference is not None and outcome.reference is not None and \
            Path(outcome.reference).resolve() == pair.reference.resolve()
        # a reference prepared from SRTM tiles says its datum in its own tag
        return OrientedPair(outcome.left, outcome.right, outcome.reference,
                            pair.reference_vertical if same else "auto")
    left, right = pair.load()
    if pair.srtm_dir is None:
        return OrientedPair(left, right, pair.reference, pair.reference_vertical)
    from core.sensors.footprint import ANY_TERRAIN_H_M
    from tasks.io.reference import build_reference, locate_tiles
    from tasks.relative.orientation import pair_box

    box = pair_box(left, right, params.height_range_m or ANY_TERRAIN_H_M)
    tiles = locate_tiles(pair.dem_source, box, True)
    ref = build_reference(tiles, box, out.with_name(out.stem + ".reference.tif"))
    return OrientedPair(left, right, Path(ref.path), "auto")


@dataclass(frozen=True, eq=False)
class MatchedPair:
    """A pair matched tile by tile: the plan, each tile's figures and the folder of their
    point files (which also hold the matches, for :func:`tasks.dense.dem.retriangulate_tiles`)."""

    plan: DensePlan
    stats: tuple[TileStats, ...]
    work: Path


def match_pair(pair: OrientedPair, out: Path, cfg: DenseConfig,
               roi: tuple[int, int, int, int] | None = None,
               height_range_m: tuple[float, float] | None = None) -> MatchedPair:
    """Plan the tiles -> match and triangulate them into ``.<out>.work``."""
    from tasks.dense.dem import match_tiles, plan_dense, scene_height_range

    out = Path(out)
    h_range = scene_height_range(pair.left, pair.right, height_range_m, pair.reference)
    plan = plan_dense(pair.left, pair.right, roi, pair.reference, h_range,
                      pair.reference_vertical, cfg)
    work = out.parent / f".{out.name}.work"
    return MatchedPair(plan, match_tiles(plan, pair.left, pair.right, work, cfg), work)


def pair_dem(pair: OrientedPair, out: Path, cfg: DenseConfig,
             roi: tuple[int, int, int, int] | None = None,
             height_range_m: tuple[float, float] | None = None) -> DemSummary:
    """Plan the tiles -> match and triangulate them -> grid the DEM into ``out``."""
    from tasks.dense.dem import grid_dem_cog

    m = match_pair(pair, out, cfg, roi, height_range_m)
    return grid_dem_cog(m.plan, m.stats, m.work, Path(out), cfg)


@dataclass(frozen=True, eq=False)
class OrientedViews:
    """N views ready for matching (``views``, jointly oriented; ``before`` as delivered), the
    reference DEM and its datum, and the tie points' heights (None when not oriented)."""

    views: tuple[LoadedModel, ...]
    before: tuple[LoadedModel, ...]
    reference: Path | None
    reference_vertical: str
    h_range_m: tuple[float, float] | None


def oriented_views(params: DsmParams) -> OrientedViews:
    """The views jointly oriented by ``flows.relative.views_models`` (its products in
    ``<out>_relative/``), or with ``orient=False`` the models as found; a reference prepared
    from the DEM tiles when that is what was given."""
    out, pair = Path(params.out), params.pair
    if params.orient:
        from flows.relative import views_models

        o = views_models(pair, params.images, out.parent / f"{out.stem}_relative",
                         params.workers)
        same = pair.reference is not None and o.reference is not None and \
            Path(o.reference).resolve() == pair.reference.resolve()
        return OrientedViews(o.views, o.models_before, o.reference,
                             pair.reference_vertical if same else "auto", o.h_range_m)
    from tasks.relative.orientation import load_views, reference_ground

    views = tuple(load_views(pair, params.images))
    if pair.srtm_dir is None:
        return OrientedViews(views, views, pair.reference, pair.reference_vertical, None)
    ground = reference_ground(pair, list(views), out, params.height_range_m)
    return OrientedViews(views, views, ground.path, "auto", None)


def match_views(v: OrientedViews, params: DsmParams, cfg: DenseConfig) -> list[MatchedViewPair]:
    """Every overlapping pair of the views planned (the ROI of the first image in each pair's
    left one), matched and, after a joint orientation, triangulated with the delivered models
    too, into ``.<out>.work/I-J``. Without a reference DEM or a height range given, the
    search spans the tie points' heights and ``margin_m`` (an RPC's own range, 1050 m on the
    Marseille triplet, made the wide pair search 528 disparities, 144 with the tie points')."""
    from core.sensors.footprint import scene_height_range_m
    from tasks.dense.dem import match_tiles, plan_dense, retriangulate_tiles
    from tasks.dense.multiview import b_over_h, pair_roi, unify_plans
    from tasks.relative.orientation import overlapping_pairs

    out, views = Path(params.out), list(v.views)
    h_range = scene_height_range_m([m.model for m in views], params.height_range_m,
                                   any_terrain=v.reference is not None)
    if v.h_range_m is not None:  # the tie points' heights: the search without a reference
        h_roi = (v.h_range_m[0] - cfg.margin_m, v.h_range_m[1] + cfg.margin_m)
        h_range = h_roi if v.reference is None and params.height_range_m is None else h_range
    else:
        h_roi = h_range
    pairs = overlapping_pairs(views, 0.5 * sum(h_range), h_range)
    plans = unify_plans([plan_dense(views[i], views[j], pair_roi(views, i, params.roi, h_roi),
                                    v.reference, h_range, v.reference_vertical, cfg)
                         for i, j in pairs])
    matched = []
    for (i, j), plan in zip(pairs, plans, strict=True):
        work = out.parent / f".{out.name}.work" / f"{i}-{j}"
        stats = match_tiles(plan, views[i], views[j], work, cfg)
        bh = b_over_h(views[i], views[j], 0.5 * sum(plan.h_range_m))
        if not params.orient:
            matched.append(MatchedViewPair((i, j), plan, stats, work, bh))
            continue
        before = work.with_name(f"{i}-{j}.before")
        b = retriangulate_tiles(plan, stats, work, before, v.before[i].model,
                                v.before[j].model, cfg)
        matched.append(MatchedViewPair((i, j), plan, stats, work, bh, b, before))
    return matched


@flow(name="dsm", log_prints=True)
def dsm_flow(params: DsmParams) -> DemSummary | ViewsDemSummary:
    """Orient the pair -> plan the tiles -> match and triangulate them -> grid the DSM; with
    ``images``, orient them jointly -> match every pair -> fuse their heights."""
    if params.images:
        from tasks.dense.multiview import grid_views_cog

        cfg, fusion = params.config(), params.fusion_config()
        matched = match_views(oriented_views(params), params, cfg)
        return grid_views_cog(matched, tuple(str(im) for im in params.images),
                              Path(params.out), cfg, fusion)
    return pair_dem(oriented_pair(params), Path(params.out), params.config(), params.roi,
                    params.height_range_m)
