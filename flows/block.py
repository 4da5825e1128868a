"""Flow ``block`` (``gcpfree block``, :mod:`flows.commands.block`): a block of overlapping
scenes oriented in one adjustment against the reference, with no GCP.

catalog (``gcpfree scenes``) -> tie points of every overlapping image and their joint relative
orientation (:func:`flows.relative.views_relative_flow`) -> each stereo pair's relative DEM
and surface-matching GCPs (:mod:`tasks.block.pairs`) -> one adjustment of every image
(:func:`core.orientation.adjust.adjust`: the GCPs in the reference's frame, the tracks as tie
points; a pair too flat to give GCPs held by its tie points to its neighbours) -> each pair's
DSM and the fused multi-view DSM, an ortho and an RPC export per image -> ``OUT/report.json``
(:class:`tasks.block.products.BlockReport`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from prefect import flow

from flows.orient import OrientParams
from tasks.block.products import BlockReport


@dataclass(frozen=True)
class BlockParams:
    """Parameters of :func:`block_flow` (``gcpfree block --help``): the catalog ``gcpfree
    scenes`` wrote and which of its blocks (default its first), and the orientation's
    parameters (``orient``, as ``gcpfree orient`` takes them: its ``pair`` the ground (the
    reference or DEM tiles, their datum and geoid, the tie-point measure; its two images the
    block's first two), its ``out`` the block's folder, its check points keyed by image
    name, its settings)."""

    catalog: Path
    orient: OrientParams
    block: str | None = None

    @property
    def out(self) -> Path:
        return Path(self.orient.out)

    def settings(self) -> dict[str, Any]:
        """What the block is made from, as JSON values (report.json's ``settings``)."""
        from core.jsonio import json_ready

        return json_ready({"catalog": str(Path(self.catalog).resolve()), "block": self.block,
                           **self.orient.settings()})


@dataclass(frozen=True, eq=False)
class BlockOutcome:
    report_path: Path
    report: BlockReport

    def lines(self) -> list[str]:
        return [(f"report                {self.report_path} and "
                f"{self.report_path.with_suffix('.html').name}"), *self.report.lines()]


@flow(name="block", log_prints=True)
def block_flow(params: BlockParams) -> BlockOutcome:
    """Tie points and joint relative orientation -> pairs' relative DEMs and GCPs -> one
    adjustment -> DSMs, orthos, RPC exports, report."""
    from flows.relative import RelativeParams, views_relative_flow
    from tasks.absolute.orientation import orient_absolute, read_checkpoints, write_gcps
    from tasks.archive.catalog import read_catalog
    from tasks.block.control import block_control, select_block
    from tasks.block.pairs import match_stereo_pairs, pair_control
    from tasks.block.products import BLOCK
    from tasks.block.report_html import write_block_html
    from tasks.block.ties import read_tracks
    from tasks.dense.dem import DenseConfig
    from tasks.io.dem import dem_datum

    o, out = params.orient, params.out
    block = select_block(params.catalog, params.block)
    checkpoints = read_checkpoints(o.checkpoints, block.names) if o.checkpoints else None
    out.mkdir(parents=True, exist_ok=True)
    rel = views_relative_flow(RelativeParams(
        pair=block.pair_inputs(o.pair), out=out / "relative" / "relative.json",
        workers=o.workers, images=block.images))
    datum = dem_datum(rel.reference, "auto")
    ties, _ = read_tracks(str(rel.rel_json.with_suffix(".tracks.json")),
                          [v.model for v in rel.views], o.absolute.matching_sigma_px)
    dense = DenseConfig(num_workers=o.workers, progress=o.progress)
    pairs = match_stereo_pairs(rel.views, block.names, block.pairs, rel.reference,
                               datum.datum, out / "pairs", dense)
    controls, first = [], 1
    for p in pairs:
        controls.append(pair_control(p, rel.views, ties, rel.reference, datum.datum,
                                     out / "pairs", dense, o.surface, o.spacing_m,
                                     o.min_windows, first, o.workers))
        first += len(controls[-1].windows.gcps)
    control = block_control(controls, o.absolute, o.min_windows)
    for line in control.notes:
        print(line)
    write_gcps(out / "gcps.json", control.gcps)
    absolute = orient_absolute(tuple(zip(block.names, rel.views, strict=True)), control.sets,
                               out / "models", o.adjust_config(), ties)
    report = _products(params, block, rel, datum, pairs, controls, absolute, dense,
                       checkpoints)
    path = BLOCK.write(out / "report.json", report)
    write_block_html(out, read_catalog(params.catalog).scenes)
    outcome = BlockOutcome(path, report)
    for line in outcome.lines():
        print(line)
    return outcome


def _products(params: BlockParams, block: Any, rel: Any, datum: Any, pairs: Any,
              controls: Any, absolute: Any, dense: Any, checkpoints: Any) -> BlockReport:
    """Each pair's DSM, the fused DSM, each image's ortho and RPC export, report.json."""
    from tasks.block.control import block_report
    from tasks.block.pairs import final_pair
    from tasks.block.products import export_rpc
    from tasks.dense.multiview import grid_views_cog
    from tasks.ortho.inputs import describe_dem
    from tasks.ortho.orthorectify import OrthoConfig, orthorectify, plan_ortho

    out = Path(params.out)
    finals = [final_pair(p, absolute.models, out / "pairs", dense) for p in pairs]
    fused = grid_views_cog([f[0] for f in finals], block.names, out / "dsm.tif", dense,
                           block.fusion(), extent="all")
    oriented = [r for r in _oriented(rel.views, absolute.models)]
    dem = describe_dem(out / "dsm.tif")
    heights = (fused.dem.h_min_m, fused.dem.h_max_m)  # the fused DSM's, as its JSON states
    exports, grid = {}, (None, None)
    for name, view in zip(block.names, oriented, strict=True):
        plan = plan_ortho(view, dem, *grid)
        grid = (plan.grid.res_m, plan.epsg)
        (out / "orthos").mkdir(exist_ok=True)
        orthorectify(plan, out / "orthos" / f"{name}.tif", OrthoConfig(), params.orient.workers)
        exports[name] = export_rpc(view.model, Path(view.image or view.source), view.size,
                                   heights, out / "models" / name)
    return block_report(params, block, rel, datum, pairs, controls, absolute, finals, fused,
                        exports, checkpoints)


def _oriented(views: Any, models: Any) -> list[Any]:
    from dataclasses import replace

    return [replace(v, model=m) for v, m in zip(views, models, strict=True)]
