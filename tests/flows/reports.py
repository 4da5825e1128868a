"""Small finished products written through their own schemas, for tests that need a pair's
figures without orienting one: a report.json (:class:`tasks.absolute.report.OrientReport`) and
an eval.json with its overall statistics (:class:`core.evaluation.DzStats`)."""

from __future__ import annotations

import math
from typing import Any

from core.evaluation.evaluation import DzStats
from core.jsonio import json_ready
from core.matching.relief import ReliefVerdict
from core.orientation.checkpoints import CheckPointStats
from tasks.absolute.report import (
    REPORT,
    Absolute,
    FinalDsm,
    GcpSummary,
    ImageFit,
    OrientReport,
    ReferenceUsed,
    SurfaceMatching,
)
from tasks.dense.dem import DemSummary
from tasks.io.products import EVALUATION_STATS, EvaluationStats

SIDES = ("left", "right")


def _dem(path: str) -> DemSummary:
    return DemSummary(
        dem_path=path, mask_path=path.replace(".tif", "_mask.tif"),
        json_path=path.replace(".tif", ".json"), epsg=32631, vertical="ellipsoidal",
        resolution_m=80.0, width=10, height=10, roi=(0, 0, 100, 100), n_tiles=1, n_tiles_roi=1,
        completeness_pct=95.0, mismatch_cells_pct=1.0, overlap_cells=100, grid_valid_pct=90.0,
        h_min_m=100.0, h_max_m=900.0, match_rate_pct=90.0, mismatched_pct=2.0,
        occluded_pct=1.0, y_residual_max_px=0.01, pointing_dy_px=(0.0, 0.0),
        n_disp_range=(16, 64))


def _check_points(rms: dict[str, tuple[float, float]]) -> dict[str, CheckPointStats]:
    return {s: CheckPointStats(s, 50, -1.0, 1.0, 0.0, c, c, -1.0, 1.0, 0.0, r, r)
            for s, (c, r) in rms.items()}


def finished_report(used: int, gcp_rms: dict[str, tuple[float, float]],
                    cp_rms: dict[str, tuple[float, float]] | None = None) -> dict[str, Any]:
    """report.json of a finished orientation with ``used`` GCPs, these GCP residual RMS per
    image (col, row px) and check-point RMS (None: no check points)."""
    images = {s: ImageFit(s, used, c, r, 0.0, 0.0, ("roll",), (0.0,), (1.0,), (0.1,))
              for s, (c, r) in gcp_rms.items()}
    relief = ReliefVerdict(40, 36, 8, 149.0, 20.0, 10.0, 0, 0, 900, 100, 90.0, 4000.0)
    report = OrientReport(
        relative={"format": "gcpfree.relative"}, relative_dem=_dem("relative_dem.tif"),
        surface_matching=SurfaceMatching({"radius_m": 4000.0}, 40, {"OK": used}, 36, relief),
        gcps=GcpSummary(used, used, 0),
        absolute=Absolute(images, 1.0, used, (), 3, True, "linear"),
        reference=ReferenceUsed("ref.tif", "ellipsoidal", "given: --reference-vertical"),
        dsm=FinalDsm("dsm.tif", "dsm_egm96.tif", _dem("dsm.tif")),
        check_points=_check_points(cp_rms) if cp_rms else None,
        check_points_before=_check_points(cp_rms) if cp_rms else None)
    return json_ready(REPORT.dump(report))  # as the file holds it (NaN as null)


def finished_evaluation(le68_m: float, count: int = 100) -> dict[str, Any]:
    """eval.json whose overall LE68 is ``le68_m`` (the statistics a summary reads)."""
    nan = math.nan
    stats = DzStats(count, 0.1, 1.0, 1.0, 0.0, 1.0, le68_m, 2.0, 3.0, -5.0, 5.0, (nan, nan),
                    0.95, "exact", 0.0)
    return {"format": "gcpfree.evaluation", "version": 1,
            **EVALUATION_STATS.dump(EvaluationStats(classes={}, all=stats))}
