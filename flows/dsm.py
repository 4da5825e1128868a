"""Flow ``dsm`` (``gcpfree dsm``, :mod:`flows.commands.dsm`): a stereo pair's DSM by dense
matching, on Dask tiles.

relative orientation of the pair (``flows.relative``) -> tiles rectified and sized from the
reference DEM -> each tile matched (SGM) and triangulated -> median per cell in the local UTM
zone, small holes filled -> ``DSM.tif``, ``DSM_mask.tif``, ``DSM.json``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

from prefect import flow

from core.matching.dense import MatchingConfig
from core.matching.dense_tile import TileStats
from tasks.dense.dem import DemSummary, DenseConfig, DensePlan
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
    there is no reference DEM (default for RPCs: their height offset +- scale).
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


@flow(name="dsm", log_prints=True)
def dsm_flow(params: DsmParams) -> DemSummary:
    """Orient the pair -> plan the tiles -> match and triangulate them -> grid the DSM."""
    return pair_dem(oriented_pair(params), Path(params.out), params.config(), params.roi,
                    params.height_range_m)
