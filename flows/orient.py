"""Flow ``orient`` (``gcpfree orient``, :mod:`flows.commands.orient`): steps 1-4 of the chain,
a stereo pair oriented with no GCP (step 4 alone, the absolute orientation, is
:mod:`tasks.absolute`; the whole chain of a pair is the flow ``pair``).

relative orientation (``flows.relative``) -> relative DEM (``flows.dsm.match_pair``) -> windows
of it around the tie points matched to the reference (SRTM) -> simulated GCPs -> relief verdict
-> absolute orientation of both images (optionally with lens self-calibration) -> final DSM (the
relative DEM's matches intersected again with the oriented models, ellipsoidal and EGM96) ->
check points -> ``OUT/report.json`` (:class:`tasks.absolute.report.OrientReport`; + the run
report ``report.html``, ``report.md``), ``OUT/left.json``, ``OUT/right.json``,
``OUT/gcps.json``, ``OUT/dsm.tif``, ``OUT/dsm_egm96.tif``.
"""

from __future__ import annotations

import shutil
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any

from prefect import flow

from core.choices import CORRECTIONS, Corrections
from core.errors import InputError
from core.geodesy import ARCSEC
from core.matching.surface import SurfaceMatchConfig
from core.orientation.absolute import AbsoluteConfig
from core.orientation.adjust import AdjustConfig
from tasks.absolute.report import REPORT, OrientReport
from tasks.io.pair import PairInputs


@dataclass(frozen=True)
class OrientParams:
    """Parameters of :func:`orient_flow` (see ``gcpfree orient --help``): the pair (its
    reference, or SRTM tiles, required), the output folder and the settings.

    ``corrections``: the terms adjusted per image (``linear``: pushbroom attitude biases and
    rates, RPC affine; ``offset``: biases, RPC shift). ``self_calibrate``: try lens terms on
    pushbroom images, keep the significant ones. ``along_track``: estimate the attitude's
    along-track profile of pushbroom images (harmonics in time, as many as the data choose,
    none included). ``spacing_m``: distance between surface
    matching windows (default their radius). ``min_windows``: windows whose relief must
    qualify, else InsufficientReliefError, unless a SAR scene is given: ``sar`` (its image;
    its model beside it or ``sar_model``) adds SAR-optical GCPs
    (:mod:`core.orientation.sar_gcps`) to the SRTM ones, or replaces them where the relief
    verdict refuses SRTM matching; ``sar_sigma_m``: its product's stated geolocation (default
    the mission's), the prior of the SAR GCPs' frame. ``write_report``: the run report
    (report.html, .md) at the end; ``gcpfree pair`` writes it once, after its orthos and
    evaluation.
    """

    pair: PairInputs
    out: Path
    checkpoints: Path | None = None
    self_calibrate: bool = False
    along_track: bool = True
    corrections: Corrections = "linear"
    spacing_m: float | None = None
    min_windows: int = 8
    workers: int | None = None
    progress: bool = True
    surface: SurfaceMatchConfig = field(default_factory=SurfaceMatchConfig)
    absolute: AbsoluteConfig = field(default_factory=AbsoluteConfig)
    sar: Path | None = None
    sar_model: Path | None = None
    write_report: bool = True
    sar_sigma_m: float | None = None

    # what only changes how the orientation runs, not what it is
    RUN_ONLY = ("out", "workers", "progress", "write_report")

    def __post_init__(self) -> None:
        """The options checked, in one line each: they come from the command line, an
        archive's catalog or a deployment's parameters (:mod:`flows.options`)."""
        if self.corrections not in CORRECTIONS:
            raise InputError(f"--corrections {self.corrections!r} unknown; use one of "
                             f"{', '.join(CORRECTIONS)}")
        if self.min_windows < 1:
            raise InputError(f"--min-windows must be at least 1 (got {self.min_windows})")
        if self.sar_sigma_m is not None and not self.sar_sigma_m > 0:
            raise InputError(f"--sar-sigma {self.sar_sigma_m:g} is the SAR product's "
                             "geolocation sigma: give a sigma > 0 m")

    def sar_config(self, sar: Any) -> Any:
        """The SAR GCPs' settings: the product's geolocation sigma as ``sar_sigma_m`` states
        it, else the mission's (:func:`core.orientation.sar_gcps.geolocation_sigma_m`)."""
        from core.orientation.sar_gcps import geolocation_sigma_m
        from core.orientation.sar_matching import SarGcpConfig
        from tasks.absolute.sar_control import mission_of

        return SarGcpConfig(geolocation_sigma_m=self.sar_sigma_m if self.sar_sigma_m
                            else geolocation_sigma_m(mission_of(sar)))

    def adjust_config(self) -> AdjustConfig:
        """The estimator's configuration (:class:`core.orientation.adjust.AdjustConfig`)."""
        return AdjustConfig(absolute=self.absolute, corrections=self.corrections,  # type: ignore[arg-type]
                            lens=self.self_calibrate, along_track=self.along_track)

    def settings(self) -> dict[str, Any]:
        """What the orientation is made from, as JSON values (report.json's ``settings``): the
        pair's inputs, the check points and every option that changes a product, paths made
        absolute; ``gcpfree pair`` keeps an orientation only when they are unchanged."""
        from core.jsonio import json_ready

        def absolute(v: Any) -> Any:
            return str(Path(v).resolve()) if isinstance(v, Path) else v

        mine = {f.name: getattr(self, f.name) for f in fields(self)
                if f.name not in ("pair", *self.RUN_ONLY)}
        mine["surface"], mine["absolute"] = asdict(self.surface), asdict(self.absolute)
        pair = {f.name: absolute(getattr(self.pair, f.name)) for f in fields(self.pair)}
        return json_ready({**pair, **{k: absolute(v) for k, v in mine.items()}})


@dataclass(frozen=True, eq=False)
class OrientOutcome:
    """What :func:`orient_flow` wrote and its report."""

    report_path: Path
    report: OrientReport

    def lines(self) -> list[str]:
        return [f"report                {self.report_path}", *self.report.lines()]


@flow(name="orient", log_prints=True)
def orient_flow(params: OrientParams) -> OrientOutcome:
    """Relative orientation -> relative DEM -> surface matching -> absolute orientation."""
    from flows.dsm import OrientedPair, match_pair
    from flows.relative import relative_models
    from tasks.absolute.control import ground_control
    from tasks.absolute.orientation import orient_absolute, read_checkpoints, write_gcps
    from tasks.absolute.surface_match import TieGround, match_surfaces
    from tasks.dense.dem import DenseConfig, grid_dem_cog
    from tasks.io.dem import dem_datum, read_reference
    from tasks.relative.orientation import pair_box

    out, given = Path(params.out), params.pair
    checkpoints = read_checkpoints(params.checkpoints) if params.checkpoints else None
    sar_scene = _sar_scene(params)  # bad SAR input refused before any work
    out.mkdir(parents=True, exist_ok=True)
    rel = relative_models(given, out / "relative", params.workers)
    # a reference prepared from SRTM tiles says its datum in its own tag
    datum = dem_datum(rel.reference, given.reference_vertical if given.reference else "auto")
    pair = OrientedPair(rel.left, rel.right, rel.reference, datum.datum)
    dense_cfg = DenseConfig(num_workers=params.workers, progress=params.progress)
    matched = match_pair(pair, out / "relative_dem.tif", dense_cfg)
    dem = grid_dem_cog(matched.plan, matched.stats, matched.work, out / "relative_dem.tif",
                       dense_cfg, keep_work=True)
    _say(dem.lines())
    cfg = params.surface
    margin = (cfg.shift_max_arcsec + 5.0) * ARCSEC
    box = pair_box(rel.left, rel.right, (dem.h_min_m, dem.h_max_m)).expanded(margin)
    reference = read_reference(rel.reference, box, datum.datum)
    ties = TieGround.from_tiepoints_json(rel.rel_json.with_suffix(".tiepoints.json"))
    windows = match_surfaces(out / "relative_dem.tif", ties, reference, cfg, params.spacing_m,
                             out=out / "windows.json", progress=params.progress,
                             workers=params.workers, models=(rel.left.model, rel.right.model))
    verdict = windows.verdict(cfg, params.min_windows, reference.cell_size_m())
    sar = None
    if sar_scene is not None:
        from tasks.absolute.sar_control import sar_ground_control

        first = max((p.id for p in windows.gcps), default=0) + 1
        sar = sar_ground_control(sar_scene, {"left": rel.left, "right": rel.right}, reference,
                                 out / "sar_points.json", params.sar_config(sar_scene),
                                 workers=params.workers, first_id=first,
                                 surface=out / "relative_dem.tif")
        _say(sar.lines())
    control = ground_control(windows, verdict, sar, params.absolute)
    _say(control.notes)
    write_gcps(out / "gcps.json", control.gcps)
    absolute = orient_absolute((("left", rel.left), ("right", rel.right)), control.sets, out,
                               params.adjust_config(), ties)
    final = _final_dsm(matched, absolute.models, dense_cfg, out)
    report = _report(params, rel, dem, windows, verdict, control, absolute, datum, final, sar,
                     checkpoints)
    path = REPORT.write(out / "report.json", report)
    if params.write_report:
        from tasks.report.build import write_report

        # report.html/.md and their figures; it adds its own "report" key to report.json
        write_report(out, reference=given.reference, checkpoints=params.checkpoints,
                     reference_vertical=given.reference_vertical, surface=params.surface)
    outcome = OrientOutcome(path, REPORT.read(path))
    _say(outcome.lines())
    return outcome


def _say(lines: Any) -> None:
    for line in lines:
        print(line)


def _sar_scene(params: OrientParams) -> Any:
    """The SAR scene's model (checked to overlap the pair), or None without ``--sar``."""
    from core.errors import InputError

    if not params.pair.has_ground:
        raise InputError("GCP-free orientation needs a reference DEM: give --srtm-dir or "
                         "--reference")
    if params.sar is None:
        return None
    from tasks.absolute.sar_control import check_overlap, load_sar

    left, right = params.pair.load()
    sar_scene = load_sar(params.sar, params.sar_model)
    check_overlap(sar_scene, {"left": left, "right": right}, 0.0)
    return sar_scene


def _final_dsm(matched: Any, models: Any, dense_cfg: Any, out: Path) -> Any:
    """The relative DEM's matches intersected again with the oriented models: the final DSM,
    ellipsoidal (``dsm.tif``) and its EGM96 twin (``dsm_egm96.tif``, each cell ``h - N``, in
    the same pass); the ellipsoidal one's summary."""
    from tasks.dense.dem import grid_dem_cog, retriangulate_tiles

    vcfg = replace(dense_cfg, vertical="ellipsoidal")
    work = out / ".dsm.tif.work"
    stats = retriangulate_tiles(matched.plan, matched.stats, matched.work, work,
                                models[0], models[1], vcfg)
    final = grid_dem_cog(matched.plan, stats, work, out / "dsm.tif", vcfg,
                         egm96_out=out / "dsm_egm96.tif")
    shutil.rmtree(matched.work, ignore_errors=True)
    return final


def _report(params: OrientParams, rel: Any, dem: Any, windows: Any, verdict: Any,
            control: Any, absolute: Any, datum: Any, final: Any, sar: Any,
            checkpoints: Any) -> OrientReport:
    """report.json of the orientation (:class:`tasks.absolute.report.OrientReport`)."""
    from tasks.absolute.orientation import check_point_report
    from tasks.absolute.report import (
        Absolute,
        FinalDsm,
        GcpSummary,
        ReferenceUsed,
        SurfaceMatching,
        check_points_of,
    )
    from tasks.io.rasters import read_json

    solution = absolute.solution
    report = OrientReport(
        relative=read_json(rel.rel_json, "relative orientation record"), relative_dem=dem,
        surface_matching=SurfaceMatching.of(params.surface, params.spacing_m,
                                            params.min_windows, windows, verdict),
        gcps=GcpSummary.of(absolute), absolute=Absolute.of(absolute, params.corrections),
        reference=ReferenceUsed.of(rel.reference, datum, params.pair, solution),
        dsm=FinalDsm("dsm.tif", "dsm_egm96.tif", final),
        sar=None if sar is None else sar.summary(
            control.srtm_used, {"left": absolute.models[0], "right": absolute.models[1]},
            solution.frame("sar"), tuple(p for p in control.gcps if p.source == "sar")),
        settings=params.settings())
    if checkpoints is not None:
        report = replace(
            report, check_points=check_points_of(check_point_report(
                absolute.models, checkpoints, solution)),
            check_points_before=check_points_of(check_point_report(
                (rel.left.model, rel.right.model), checkpoints)))
    return report
