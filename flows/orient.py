"""Flow of ``gcpfree orient``: steps 1-4 of the chain, a stereo pair oriented with no GCP.

relative orientation (``flows.relative``) -> relative DEM (``flows.dsm.pair_dem``) -> windows of
it around the tie points matched to the reference (SRTM) -> simulated GCPs -> relief verdict ->
absolute orientation of both images (optionally with lens self-calibration) -> final DSM (the
relative DEM's matches intersected again with the oriented models, ellipsoidal and EGM96) ->
check points -> ``OUT/report.json`` (+ ``report.html``, ``report.md``), ``OUT/left.json``, ``OUT/right.json``, ``OUT/gcps.json``,
``OUT/dsm.tif``, ``OUT/dsm_egm96.tif``.
"""

from __future__ import annotations

import json
import shutil
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

from prefect import flow

from core.orientation.absolute import AbsoluteConfig
from core.surface_match import SurfaceMatchConfig

FORMAT = "gcpfree.orient"


@dataclass(frozen=True)
class OrientParams:
    """Parameters of :func:`orient_flow` (see ``gcpfree orient --help``).

    ``corrections``: the terms adjusted per image (``linear``: pushbroom attitude biases and
    rates, RPC affine; ``offset``: biases, RPC shift). ``self_calibrate``: try lens terms on
    pushbroom images, keep the significant ones. ``spacing_m``: distance between surface
    matching windows (default their radius). ``min_windows``: windows whose relief must
    qualify, else InsufficientReliefError.
    """

    left: Path
    right: Path
    out: Path
    left_model: Path | None = None
    right_model: Path | None = None
    band: int | None = None
    reference: Path | None = None
    reference_vertical: str = "auto"
    srtm_dir: Path | None = None
    checkpoints: Path | None = None
    self_calibrate: bool = False
    corrections: str = "linear"
    spacing_m: float | None = None
    min_windows: int = 8
    workers: int | None = None
    progress: bool = True
    surface: SurfaceMatchConfig = field(default_factory=SurfaceMatchConfig)
    absolute: AbsoluteConfig = field(default_factory=AbsoluteConfig)


@dataclass(frozen=True, eq=False)
class OrientOutcome:
    """What :func:`orient_flow` wrote and its report."""

    report_path: Path
    report: dict[str, Any]

    def lines(self) -> list[str]:
        r = self.report
        g = r["gcps"]
        out = [f"report                {self.report_path}",
               (f"GCPs from SRTM        {g['used']} used, {g['rejected']} rejected "
                f"({r['surface_matching']['windows']} windows, "
                f"{r['surface_matching']['qualified']} with enough relief)")]
        for name, a in r["absolute"]["images"].items():
            out.append(f"GCP residuals {name:<6}  P {a['rms_col_px']:.3f} px  "
                       f"L {a['rms_row_px']:.3f} px RMS")
        lens = r["absolute"].get("self_calibration")
        if lens is not None:
            out.append("lens terms            " + (
                ", ".join(f"{n}: {', '.join(t)}" for n, t in lens["significant"].items())
                if lens["applied"] else "none significant (not applied)"))
        for name, c in r.get("check_points", {}).items():
            out.append(f"check points {name:<6}  P {c['rms_col_px']:.3f} px  "
                       f"L {c['rms_row_px']:.3f} px RMS ({c['n']} points)")
        d = r["dsm"]["summary"]
        out.append(f"final DSM             {d['dem_path']} ({d['resolution_m']:g} m, "
                   f"EPSG:{d['epsg']}, {d['completeness_pct']:.1f} % complete) and "
                   f"{r['dsm']['egm96']} (EGM96)")
        return out


@flow(name="orient", log_prints=True)
def orient_flow(params: OrientParams) -> OrientOutcome:
    """Relative orientation -> relative DEM -> surface matching -> absolute orientation."""
    from core.errors import InputError, InsufficientDataError, InsufficientReliefError
    from core.surface_match import relief_sufficiency
    from flows.dsm import OrientedPair, match_pair
    from flows.relative import relative_models
    from tasks.io.dem import dem_datum, read_reference
    from tasks.dense.dem import DenseConfig, grid_dem_cog, pair_box, retriangulate_tiles
    from tasks.absolute.orientation import check_point_report, orient_absolute, read_checkpoints, write_gcps
    from tasks.io.rasters import atomic_write_json, json_ready
    from tasks.absolute.surface_match import TieGround, match_surfaces

    out = Path(params.out)
    if params.reference is None and params.srtm_dir is None:
        raise InputError("GCP-free orientation needs a reference DEM: give --srtm-dir or "
                         "--reference")
    checkpoints = read_checkpoints(params.checkpoints) if params.checkpoints else None
    out.mkdir(parents=True, exist_ok=True)
    rel = relative_models(params.left, params.right, left_model=params.left_model,
                          right_model=params.right_model, band=params.band,
                          reference=params.reference,
                          reference_vertical=params.reference_vertical,
                          srtm_dir=params.srtm_dir, out_dir=out / "relative")
    # a reference prepared from SRTM tiles says its datum in its own tag
    datum = dem_datum(rel.reference, params.reference_vertical if params.reference else "auto")
    pair = OrientedPair(rel.left, rel.right, rel.reference, datum.datum)
    dense_cfg = DenseConfig(num_workers=params.workers, progress=params.progress)
    matched = match_pair(pair, out / "relative_dem.tif", dense_cfg)
    dem = grid_dem_cog(matched.plan, matched.stats, matched.work, out / "relative_dem.tif",
                       dense_cfg, keep_work=True)
    for line in dem.lines():
        print(line)

    cfg = params.surface
    margin = (cfg.shift_max_arcsec + 5.0) / 3600.0
    box = pair_box(rel.left, rel.right, (dem.h_min_m, dem.h_max_m)).expanded(margin)
    reference = read_reference(rel.reference, box, datum.datum)
    ties = TieGround.from_tiepoints_json(rel.rel_json.with_suffix(".tiepoints.json"))
    windows = match_surfaces(out / "relative_dem.tif", ties, reference, cfg, params.spacing_m,
                             out=out / "windows.json", progress=params.progress)
    verdict = relief_sufficiency(windows.matches, cfg, params.min_windows,
                                 reference.cell_size_m())
    if not verdict.enough:  # the true reason: too flat, or too small, or reference voids
        raise (InsufficientReliefError if verdict.reason == "too_flat"
               else InsufficientDataError)(verdict.message())
    gcps = windows.gcps
    if len(gcps) < params.absolute.min_gcps:
        raise InsufficientDataError(
            f"only {len(gcps)} surface-matching windows gave a GCP "
            f"({params.absolute.min_gcps} needed): {windows.counts()}; the relative DEM does "
            f"not correlate with the reference: terrain too flat for its noise (median relief "
            f"{verdict.relief_found_m:.1f} m per window), clouds, voids or a wrong reference")
    write_gcps(out / "gcps.json", gcps)
    absolute = orient_absolute(rel.left, rel.right, gcps, out, params.corrections,
                               params.self_calibrate, params.absolute)
    report: dict[str, Any] = {
        "format": FORMAT, "version": 1,
        "relative": json.loads(rel.rel_json.read_text()),
        "relative_dem": dem.to_dict(),
        "surface_matching": {"settings": {**asdict(cfg), "spacing_m": params.spacing_m,
                                          "min_windows": params.min_windows},
                             "windows": len(windows.matches), "counts": windows.counts(),
                             "qualified": verdict.n_qualified, "relief": verdict.to_dict(),
                             "windows_file": "windows.json"},
        "gcps": {**absolute.gcp_summary(gcps), "file": "gcps.json"},
        "absolute": {**absolute.adjustment.to_dict(), "corrections": params.corrections,
                     "self_calibration": (absolute.self_calibration.to_dict()
                                          if absolute.self_calibration else None)},
        "models": {"left": "left.json", "right": "right.json"},
        "reference": {"path": str(rel.reference), **datum.to_dict(),
                      "given": None if params.reference is None else str(params.reference),
                      "srtm_dir": None if params.srtm_dir is None else str(params.srtm_dir)},
    }
    final = {}
    for vert, name in (("ellipsoidal", "dsm.tif"), ("egm96", "dsm_egm96.tif")):
        vcfg = replace(dense_cfg, vertical=vert)
        work = out / f".{name}.work"
        stats = retriangulate_tiles(matched.plan, matched.stats, matched.work, work,
                                    absolute.models[0], absolute.models[1], vcfg)
        final[vert] = grid_dem_cog(matched.plan, stats, work, out / name, vcfg).to_dict()
    shutil.rmtree(matched.work, ignore_errors=True)
    report["dsm"] = {"ellipsoidal": "dsm.tif", "egm96": "dsm_egm96.tif",
                     "summary": final["ellipsoidal"]}
    if checkpoints is not None:
        report["check_points"] = check_point_report(absolute.models, checkpoints)
        report["check_points_before"] = check_point_report(
            (rel.left.model, rel.right.model), checkpoints)
    report = json_ready(report)
    path = atomic_write_json(out / "report.json", report)
    from tasks.report.build import write_report

    # report.html/.md and their figures; it adds its own "report" key to report.json
    write_report(out, reference=params.reference, checkpoints=params.checkpoints,
                 reference_vertical=params.reference_vertical, surface=params.surface)
    outcome = OrientOutcome(path, json.loads(path.read_text()))
    for line in outcome.lines():
        print(line)
    return outcome
