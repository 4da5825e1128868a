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

from core.geodesy import ARCSEC
from core.matching.surface import SurfaceMatchConfig
from core.orientation.absolute import AbsoluteConfig
from tasks.absolute.report import OrientReport
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
    verdict refuses SRTM matching. ``write_report``: the run report (report.html, .md) at the
    end; ``gcpfree pair`` writes it once, after its orthos and evaluation.
    """

    pair: PairInputs
    out: Path
    checkpoints: Path | None = None
    self_calibrate: bool = False
    along_track: bool = True
    corrections: str = "linear"
    spacing_m: float | None = None
    min_windows: int = 8
    workers: int | None = None
    progress: bool = True
    surface: SurfaceMatchConfig = field(default_factory=SurfaceMatchConfig)
    absolute: AbsoluteConfig = field(default_factory=AbsoluteConfig)
    sar: Path | None = None
    sar_model: Path | None = None
    write_report: bool = True

    # what only changes how the orientation runs, not what it is
    RUN_ONLY = ("out", "workers", "progress", "write_report")

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
    from core.errors import InputError, InsufficientDataError, InsufficientReliefError
    from core.matching.relief import relief_sufficiency
    from flows.dsm import OrientedPair, match_pair
    from flows.relative import relative_models
    from tasks.absolute.orientation import (
        check_point_report,
        orient_absolute,
        read_checkpoints,
        write_gcps,
    )
    from tasks.absolute.report import (
        Absolute,
        FinalDsm,
        GcpSummary,
        ReferenceUsed,
        SurfaceMatching,
        check_points_of,
        read_report,
    )
    from tasks.absolute.surface_match import TieGround, match_surfaces
    from tasks.dense.dem import DenseConfig, grid_dem_cog, retriangulate_tiles
    from tasks.io.dem import dem_datum, read_reference
    from tasks.io.rasters import read_json
    from tasks.relative.orientation import pair_box

    out, given = Path(params.out), params.pair
    if not given.has_ground:
        raise InputError("GCP-free orientation needs a reference DEM: give --srtm-dir or "
                         "--reference")
    checkpoints = read_checkpoints(params.checkpoints) if params.checkpoints else None
    sar_scene = None
    if params.sar is not None:  # bad SAR input refused before any work
        from tasks.absolute.sar_control import check_overlap, load_sar

        left, right = given.load()
        sar_scene = load_sar(params.sar, params.sar_model)
        check_overlap(sar_scene, {"left": left, "right": right}, 0.0)
    out.mkdir(parents=True, exist_ok=True)
    rel = relative_models(given, out / "relative", params.workers)
    # a reference prepared from SRTM tiles says its datum in its own tag
    datum = dem_datum(rel.reference, given.reference_vertical if given.reference else "auto")
    pair = OrientedPair(rel.left, rel.right, rel.reference, datum.datum)
    dense_cfg = DenseConfig(num_workers=params.workers, progress=params.progress)
    matched = match_pair(pair, out / "relative_dem.tif", dense_cfg)
    dem = grid_dem_cog(matched.plan, matched.stats, matched.work, out / "relative_dem.tif",
                       dense_cfg, keep_work=True)
    for line in dem.lines():
        print(line)

    cfg = params.surface
    margin = (cfg.shift_max_arcsec + 5.0) * ARCSEC
    box = pair_box(rel.left, rel.right, (dem.h_min_m, dem.h_max_m)).expanded(margin)
    reference = read_reference(rel.reference, box, datum.datum)
    ties = TieGround.from_tiepoints_json(rel.rel_json.with_suffix(".tiepoints.json"))
    windows = match_surfaces(out / "relative_dem.tif", ties, reference, cfg, params.spacing_m,
                             out=out / "windows.json", progress=params.progress,
                             workers=params.workers, models=(rel.left.model, rel.right.model))
    verdict = relief_sufficiency(windows.matches, cfg, params.min_windows,
                                 reference.cell_size_m())
    sar = None
    if sar_scene is not None:
        from tasks.absolute.sar_control import sar_ground_control

        first = max((p.id for p in windows.gcps), default=0) + 1
        sar = sar_ground_control(sar_scene, {"left": rel.left, "right": rel.right}, reference,
                                 out / "sar_points.json", workers=params.workers,
                                 first_id=first, surface=out / "relative_dem.tif")
        for line in sar.lines():
            print(line)
    if not verdict.enough and sar is None:  # the true reason: too flat, too small, voids
        raise (InsufficientReliefError if verdict.reason == "too_flat"
               else InsufficientDataError)(verdict.message())
    srtm_used = verdict.enough and bool(windows.gcps)
    if sar is not None and not srtm_used:
        why = verdict.message() if not verdict.enough else \
            f"no window gave a GCP: {windows.counts()}"
        print(f"SRTM surface matching refused ({why}); the orientation proceeds on the SAR "
              "GCPs alone")
    gcps = (windows.gcps if verdict.enough else ()) + (sar.gcps if sar is not None else ())
    shift = None
    if sar is not None and srtm_used and len(sar.gcps) >= 3:
        # the SAR GCPs' common offset (the SAR's geolocation, the matching's bias at height
        # steps) measured against the models oriented on the SRTM GCPs, and removed
        import tempfile

        from core.orientation.sar_gcps import common_shift, shifted

        with tempfile.TemporaryDirectory(dir=out, prefix=".srtm_only") as tmp:
            first = orient_absolute(rel.left, rel.right, windows.gcps, Path(tmp),
                                    params.corrections, False, params.absolute, ties, False)
        shift = common_shift({"left": first.models[0], "right": first.models[1]}, sar.gcps)
        print(f"SAR GCPs' common shift against the SRTM orientation: east "
              f"{shift.east_m:+.1f} +- {shift.sigma_east_m:.1f} m, north "
              f"{shift.north_m:+.1f} +- {shift.sigma_north_m:.1f} m (removed)")
        gcps = windows.gcps + shifted(sar.gcps, shift)
    if len(gcps) < params.absolute.min_gcps and sar is not None:
        raise InsufficientDataError(
            f"only {len(gcps)} GCPs from SRTM and SAR together ({params.absolute.min_gcps} "
            f"needed): surface matching {windows.counts()}; SAR "
            f"{'; '.join(r.refused or str(r.counts()) for r in sar.results)}")
    if len(gcps) < params.absolute.min_gcps:
        raise InsufficientDataError(
            f"only {len(gcps)} surface-matching windows gave a GCP "
            f"({params.absolute.min_gcps} needed): {windows.counts()}; the relative DEM does "
            f"not correlate with the reference: terrain too flat for its noise (median relief "
            f"{verdict.relief_found_m:.1f} m per window), clouds, voids or a wrong reference")
    write_gcps(out / "gcps.json", gcps)
    absolute_cfg = params.absolute
    if sar is not None and not srtm_used:
        # the ground control is the SAR scene: what the orientation cannot see is its
        # geolocation error and the matching's bias at height steps (the module docstring
        # of core.orientation.sar_matching and sar_prediction)
        from core.orientation.sar_gcps import registration_sigma_m

        first_ok = next(r for r in sar.results if r.heights is not None)
        absolute_cfg = replace(absolute_cfg, reference_sigma_m=registration_sigma_m(
            sar.config.geolocation_sigma_m, first_ok.matches.cell_m,
            first_ok.heights.range_direction_en, params.absolute.reference_sigma_m[2],
            predicted=first_ok.prediction is not None))
    absolute = orient_absolute(rel.left, rel.right, gcps, out, params.corrections,
                               params.self_calibrate, absolute_cfg, ties,
                               params.along_track)
    final = {}
    for vert, name in (("ellipsoidal", "dsm.tif"), ("egm96", "dsm_egm96.tif")):
        vcfg = replace(dense_cfg, vertical=vert)
        work = out / f".{name}.work"
        stats = retriangulate_tiles(matched.plan, matched.stats, matched.work, work,
                                    absolute.models[0], absolute.models[1], vcfg)
        final[vert] = grid_dem_cog(matched.plan, stats, work, out / name, vcfg)
    shutil.rmtree(matched.work, ignore_errors=True)
    report = OrientReport(
        relative=read_json(rel.rel_json, "relative orientation record"), relative_dem=dem,
        surface_matching=SurfaceMatching.of(cfg, params.spacing_m, params.min_windows, windows,
                                            verdict),
        gcps=GcpSummary.of(absolute, gcps), absolute=Absolute.of(absolute, params.corrections),
        reference=ReferenceUsed.of(rel.reference, datum, given),
        dsm=FinalDsm("dsm.tif", "dsm_egm96.tif", final["ellipsoidal"]),
        sar=None if sar is None else sar.summary(
            srtm_used, {"left": absolute.models[0], "right": absolute.models[1]}, shift,
            tuple(p for p in gcps if p.source == "sar")),
        settings=params.settings())
    if checkpoints is not None:
        report = replace(
            report, check_points=check_points_of(check_point_report(
                absolute.models, checkpoints, absolute.adjustment,
                absolute_cfg.reference_sigma_m)),
            check_points_before=check_points_of(check_point_report(
                (rel.left.model, rel.right.model), checkpoints)))
    path = report.write(out / "report.json")
    if params.write_report:
        from tasks.report.build import write_report

        # report.html/.md and their figures; it adds its own "report" key to report.json
        write_report(out, reference=given.reference, checkpoints=params.checkpoints,
                     reference_vertical=given.reference_vertical, surface=params.surface)
    outcome = OrientOutcome(path, read_report(path))
    for line in outcome.lines():
        print(line)
    return outcome
