"""The block chosen from a ``gcpfree scenes`` catalog, its ground control from every stereo
pair's windows (a pair too flat gives none: its images are held by their tie points), and
report.json from the solution."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from core.errors import InputError, InsufficientDataError, InsufficientReliefError
from core.matching.fusion import FusionConfig
from core.orientation.absolute import AbsoluteConfig
from core.orientation.adjust import ControlSet
from core.orientation.frames import REFERENCE, FramePrior
from tasks.absolute.control import GroundControl
from tasks.archive.catalog import read_catalog
from tasks.block.pairs import PairControl
from tasks.block.products import BlockPair, BlockReport, block_images
from tasks.io.pair import PairInputs


@dataclass(frozen=True)
class BlockSelection:
    """A block of the catalog: its scenes (names, images, model files), the first fixed in
    the relative orientation, and its stereo pairs (id, left index, right index)."""

    id: str
    names: tuple[str, ...]
    images: tuple[Path, ...]
    models: tuple[Path | None, ...]
    pairs: tuple[tuple[str, int, int], ...]

    def pair_inputs(self, ground: PairInputs) -> PairInputs:
        """The ground options of ``ground`` with this block's first two images."""
        return replace(ground, left=self.images[0], right=self.images[1],
                       left_model=self.models[0], right_model=self.models[1])

    def fusion(self) -> FusionConfig:
        return FusionConfig()


def select_block(catalog: Path, block_id: str | None = None) -> BlockSelection:
    """The block ``block_id`` (default the catalog's first) of a ``gcpfree scenes`` catalog;
    InputError when the catalog has no blocks, no such block, or a block without a stereo
    pair."""
    cat = read_catalog(catalog)
    if not cat.blocks:
        raise InputError(f"{catalog} lists no blocks; give the catalog gcpfree scenes wrote")
    blocks = {b.id: b for b in cat.blocks}
    if block_id is not None and block_id not in blocks:
        raise InputError(f"{catalog} has no block {block_id!r}; it has {', '.join(blocks)}")
    b = blocks[block_id] if block_id is not None else cat.blocks[0]
    scenes = {s.id: s for s in cat.scenes}
    names = tuple(b.scenes)
    index = {str(scenes[n].image.resolve()): k for k, n in enumerate(names)}
    pairs = []
    for p in cat.pairs:
        if p.id in b.pairs:
            i, j = index.get(str(p.left.resolve())), index.get(str(p.right.resolve()))
            if i is not None and j is not None:
                pairs.append((p.id, i, j))
    if not pairs:
        raise InputError(f"block {b.id} of {catalog} has no stereo pair: gcpfree block needs "
                         "one at least (a relative DEM to match against the reference)")
    if len(names) < 2:
        raise InputError(f"block {b.id} of {catalog} holds one scene; a block needs two")
    return BlockSelection(b.id, names, tuple(scenes[n].image for n in names),
                          tuple(scenes[n].model for n in names), tuple(pairs))


def block_control(controls: Sequence[PairControl], config: AbsoluteConfig,
                  min_windows: int) -> GroundControl:
    """The GCPs of every pair whose windows have the relief and match (``min_windows`` GCPs at
    least, as a pair alone needs), in the reference's frame; a pair refused says so (its
    images are held by their tie points: a flat scene's two GCPs on 41 windows would hold it
    by two weak points). InsufficientReliefError when
    no pair has the relief, InsufficientDataError with too few GCPs in all."""
    held = [c for c in controls if c.verdict.enough and len(c.gcps) >= min_windows]
    notes = [f"pair {c.pair.id}: "
             + (c.verdict.message() if not c.verdict.enough else
                f"{len(c.gcps)} of its windows matched ({min_windows} needed: "
                f"{', '.join(f'{k} {v}' for k, v in c.windows.counts().items())})")
             + "; its images are held by their tie points to their neighbours"
             for c in controls if c not in held]
    gcps = tuple(p for c in held for p in c.gcps)
    if not held:
        flat = all(c.verdict.reason == "too_flat" for c in controls)
        raise (InsufficientReliefError if flat else InsufficientDataError)(
            f"no stereo pair of the block has the windows it needs ({min_windows}): "
            + "; ".join(f"{c.pair.id}: {c.verdict.message()}" for c in controls))
    if len(gcps) < config.min_gcps:
        raise InsufficientDataError(
            f"only {len(gcps)} GCPs from the block's pairs ({config.min_gcps} needed): "
            + "; ".join(f"{c.pair.id} {c.windows.counts()}" for c in controls))
    return GroundControl((ControlSet("surface", gcps, FramePrior(
        REFERENCE, config.reference_sigma_m, source="the reference's stated registration "
                                                    "(--reference-sigma)")),), True,
        tuple(notes))


def block_report(params: Any, block: BlockSelection, rel: Any, datum: Any, pairs: Any,
                 controls: Sequence[PairControl], absolute: Any, finals: Any, fused: Any,
                 exports: dict[str, Any], checkpoints: Any) -> BlockReport:
    """report.json of the block (:class:`tasks.block.products.BlockReport`)."""
    from tasks.absolute.orientation import check_point_report

    s = absolute.solution
    files = {n: (str(im), str(Path(params.out) / "models" / f"{n}.json"))
             for n, im in zip(block.names, block.images, strict=True)}
    out_pairs = tuple(BlockPair(
        id=c.pair.id, images=c.pair.names, b_over_h=c.pair.b_over_h,
        verdict=c.verdict.to_dict(), windows=c.windows.counts(), gcps=len(c.gcps),
        dsm=str(Path("pairs") / c.pair.id / "dsm.tif")) for c in controls)
    adj = s.adjustment
    cps = before = None
    if checkpoints is not None:
        cps = check_point_report(s.models, checkpoints, s, s.names)
        before = check_point_report(tuple(v.model for v in rel.models_before), checkpoints,
                                    None, s.names)
    summary = getattr(fused, "dem", fused)
    return BlockReport(
        images=block_images(s, files, exports), pairs=out_pairs,
        connectivity=s.connectivity.to_dict() if s.connectivity else {},
        frames=tuple(f.to_dict() for f in s.frames()), gcps=s.gcp_summary(),
        tie_points={"n": adj.n_ties, "rms_px": adj.tie_rms_px},
        adjustment={k: v for k, v in adj.to_dict().items() if k != "images"},
        self_calibration=s.self_calibration.to_dict() if s.self_calibration else None,
        dsm={"dem_path": str(getattr(summary, "dem_path", "dsm.tif")),
             "views_path": str(getattr(fused, "views_path", "dsm_views.tif")),
             "completeness_pct": float(getattr(summary, "completeness_pct", float("nan")))},
        reference={"path": str(rel.reference), "vertical": datum.datum,
                   "vertical_source": datum.source},
        check_points=cps, check_points_before=before, settings=params.settings())
