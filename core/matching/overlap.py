"""The overlap of a stereo pair on the ground, counted in tie-point cells.

Left pixels are sampled on a grid and kept when they project inside the right image at some
height of their range (the terrain height is only known to lie in ``[h_lo, h_hi]``, the
reference DEM's local envelope or the scene's range): the range is walked in steps short
against the right image, so a small crop of a wide-baseline pair, seen by the right image only
at intermediate heights, still overlaps. :func:`overlap_cells` gives the ground cells the
overlap fills, :func:`overlap_cell_m` the cell size that gives a small overlap enough cells.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from core.geodesy import geodetic_to_enu
from core.matching.tiepoints import HeightPrior, cell_ids, ground_sampling_m
from core.sensors.base import SensorModel

FloatArray = NDArray[np.float64]

MIN_CELLS_PER_SIDE = 8  # a smaller overlap gets smaller cells: at least 8 x 8 of them
_SAMPLES_PER_SIDE = 64  # left-image samples per side when measuring the overlap's area
_MAX_LEVELS = 65  # heights tried per sample, at most


def overlap_samples(left_model: SensorModel, right_model: SensorModel,
                    left_size: tuple[int, int], right_size: tuple[int, int],
                    heights: HeightPrior, step_px: float
                    ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(col, row, h) of the left pixels, every ``step_px``, that project inside the right
    image at some height of their range; ``h`` is their prior height.

    The heights tried go from ``h_lo`` to ``h_hi`` in steps whose image motion (the epipolar
    segment's longest, in right pixels) is at most a quarter of the right image's smaller
    side, between 3 and 65 levels.
    """
    n_cols, n_rows = left_size
    cc, rr = np.meshgrid(np.arange(0.0, n_cols, step_px), np.arange(0.0, n_rows, step_px))
    cc, rr = cc.ravel(), rr.ravel()
    h, h_lo, h_hi = heights.heights(left_model, cc, rr)
    ok = np.isfinite(h) & np.isfinite(h_lo) & np.isfinite(h_hi)
    cc, rr, h, h_lo, h_hi = cc[ok], rr[ok], h[ok], h_lo[ok], h_hi[ok]

    def right_px(hh: FloatArray) -> tuple[FloatArray, FloatArray]:
        pc, pr = right_model.project(*left_model.localize(cc, rr, hh), hh)
        return np.asarray(pc, np.float64), np.asarray(pr, np.float64)

    ends = [right_px(h_lo), right_px(h_hi)]
    segment_px = np.hypot(ends[1][0] - ends[0][0], ends[1][1] - ends[0][1])
    longest = float(np.nanmax(segment_px)) if segment_px.size else 0.0
    quarter = 0.25 * max(min(right_size), 1)
    n_levels = int(np.clip(math.ceil(longest / quarter) + 1, 3, _MAX_LEVELS))
    inside = np.zeros(cc.size, bool)
    for t in np.linspace(0.0, 1.0, n_levels):
        pc, pr = ends[0] if t == 0.0 else ends[1] if t == 1.0 else right_px(
            h_lo + t * (h_hi - h_lo))
        inside |= (pc >= 0) & (pc <= right_size[0] - 1) & (pr >= 0) & (pr <= right_size[1] - 1)
    pc, pr = right_px(h)
    inside |= (pc >= 0) & (pc <= right_size[0] - 1) & (pr >= 0) & (pr <= right_size[1] - 1)
    return cc[inside], rr[inside], h[inside]


def overlap_cells(left_model: SensorModel, right_model: SensorModel,
                  left_size: tuple[int, int], right_size: tuple[int, int],
                  heights: HeightPrior, origin: tuple[float, float, float], cell_m: float,
                  ) -> NDArray[np.int64]:
    """Ids of the ground cells of the overlap (:func:`core.matching.tiepoints.cell_ids` in the
    local frame at ``origin`` (lon, lat, h)): left pixels are sampled about four times per cell
    side, at their heights; a cell belongs to the overlap when at least half of its samples
    project inside the right image at some height of their range (slivers on the border do
    not count)."""
    n_cols, n_rows = left_size
    gsd = ground_sampling_m(left_model, (n_cols - 1) / 2.0, (n_rows - 1) / 2.0,
                            heights.typical_h_m)
    step = max(1.0, cell_m / 4.0 / gsd)
    cc, rr, h = overlap_samples(left_model, right_model, left_size, right_size, heights, step)
    lon, lat = left_model.localize(cc, rr, h)
    e, n, _ = geodetic_to_enu(lon, lat, h, origin)
    ids, counts = np.unique(cell_ids(e, n, cell_m), return_counts=True)
    full = (cell_m / (step * gsd)) ** 2
    return ids[(ids >= 0) & (counts >= 0.5 * full)]


def overlap_area_m2(left_model: SensorModel, right_model: SensorModel,
                    left_size: tuple[int, int], right_size: tuple[int, int],
                    heights: HeightPrior) -> float:
    """The overlap's ground area (square metres, at the left image's central ground
    sampling), from about 64 x 64 samples of the left image."""
    n_cols, n_rows = left_size
    gsd = ground_sampling_m(left_model, (n_cols - 1) / 2.0, (n_rows - 1) / 2.0,
                            heights.typical_h_m)
    step = max(1.0, max(n_cols, n_rows) / _SAMPLES_PER_SIDE)
    cc, _, _ = overlap_samples(left_model, right_model, left_size, right_size, heights, step)
    return float(cc.size * (step * gsd) ** 2)


def overlap_cell_m(left_model: SensorModel, right_model: SensorModel,
                   left_size: tuple[int, int], right_size: tuple[int, int],
                   heights: HeightPrior, cell_m: float,
                   min_cells_per_side: int = MIN_CELLS_PER_SIDE) -> float:
    """``cell_m``, or the smaller cell that cuts the overlap into at least
    ``min_cells_per_side`` squared cells (its area over that count, square-rooted): a crop
    smaller than the requested cell still gets tie points spread over it. ``cell_m``
    unchanged when there is no overlap (the caller reports it) or ``min_cells_per_side`` is
    0."""
    if min_cells_per_side <= 0:
        return float(cell_m)
    area = overlap_area_m2(left_model, right_model, left_size, right_size, heights)
    if not area > 0:
        return float(cell_m)
    return float(min(cell_m, math.sqrt(area) / min_cells_per_side))
