"""Flow ``evaluate`` (``gcpfree evaluate``, :mod:`flows.commands.evaluate`): accuracy of a DEM
against lidar, per class.

DEM + lidar (+ land cover) -> the DEM interpolated at every lidar point, streamed in chunks ->
bias, std, RMSE, NMAD, LE68 (with a bootstrap interval), LE90 per class and overall ->
eval.json.
"""

from __future__ import annotations

from prefect import flow

from core.evaluation.evaluation_report import EvaluationReport
from tasks.evaluation.lidar import EvaluationOptions, evaluate_lidar, write_evaluation


@flow(name="evaluate", log_prints=True)
def evaluate_flow(options: EvaluationOptions) -> EvaluationReport:
    """Stream the lidar against the DEM, then write eval.json (when ``options.out``)."""
    report = evaluate_lidar(options)
    if options.out is not None:
        write_evaluation(report, options.out)
    return report
