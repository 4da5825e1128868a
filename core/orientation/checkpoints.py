"""Check points: the paper's Table 2 for one image (residuals of independent check points in P
(col) and L (row)), beside what the adjustment predicts at them."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.errors import InsufficientDataError
from core.orientation.uncertainty import (
    PredictedAccuracy,
)
from core.sensors.base import SensorModel

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class CheckPointStats:
    """The paper's Table 2 for one image: residuals (measured - projected, px) of independent
    check points in P (col) and L (row); beside the measured RMS, the RMS the adjustment
    predicts at those points (:class:`~core.orientation.uncertainty.PredictedAccuracy`), when
    one was made."""

    name: str
    n: int
    min_col_px: float
    max_col_px: float
    mean_col_px: float
    std_col_px: float
    rms_col_px: float
    min_row_px: float
    max_row_px: float
    mean_row_px: float
    std_row_px: float
    rms_row_px: float
    predicted_rms_col_px: float | None = None
    predicted_rms_row_px: float | None = None
    predicted_relative_rms_col_px: float | None = None
    predicted_relative_rms_row_px: float | None = None
    predicted_reference_rms_col_px: float | None = None
    predicted_reference_rms_row_px: float | None = None

    def with_prediction(self, pred: PredictedAccuracy) -> CheckPointStats:
        """These figures with the RMS ``pred`` predicts at the same points: in total and its
        two parts (relative to the control's frames, and the frames' own registration)."""
        return replace(self, predicted_rms_col_px=pred.predicted_rms_col_px,
                       predicted_rms_row_px=pred.predicted_rms_row_px,
                       predicted_relative_rms_col_px=pred.predicted_relative_rms_col_px,
                       predicted_relative_rms_row_px=pred.predicted_relative_rms_row_px,
                       predicted_reference_rms_col_px=pred.predicted_reference_rms_col_px,
                       predicted_reference_rms_row_px=pred.predicted_reference_rms_row_px)

    def to_dict(self) -> dict[str, Any]:
        """The figures (the predicted RMS only when there is one)."""
        return {k: v for k, v in vars(self).items()
                if v is not None or not k.startswith("predicted_")}


def check_point_stats(model: SensorModel, lon_deg: ArrayLike, lat_deg: ArrayLike,
                      h_m: ArrayLike, col: ArrayLike, row: ArrayLike,
                      name: str = "image") -> CheckPointStats:
    """Min, max, mean, std and RMS of the check points' residuals in one image."""
    pc, pr = model.project(lon_deg, lat_deg, h_m)
    dc = np.asarray(col, dtype=np.float64) - pc
    dr = np.asarray(row, dtype=np.float64) - pr
    if dc.size == 0:
        raise InsufficientDataError(f"no check point in image {name}")

    def five(v: FloatArray) -> tuple[float, ...]:
        return (float(v.min()), float(v.max()), float(v.mean()), float(v.std()), _rms(v))

    return CheckPointStats(name, int(dc.size), *five(dc), *five(dr))


def _rms(v: FloatArray) -> float:
    return float(np.sqrt(np.mean(v**2))) if v.size else float("nan")
