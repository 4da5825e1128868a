"""Ortho-versus-ortho check (step 5's quality control without ground truth): the two orthos of
a pair, on one lattice, correlated on a grid of windows; the shift of each window and the
statistics of the discrepancy.

Each window of the left ortho (``window_px`` cells a side) is searched for in the right one
within ``+-search_px`` cells by normalised cross-correlation (:func:`window_shift`, with the
NCC, integer peak and quadratic of :mod:`core.matching.peaks`); the integer peak is refined to
sub-pixel by resampling the right ortho (cubic B-spline) at the current shift and a quarter cell
around it and fitting a quadratic to those 3x3 correlations,
a few times over. The quadratic fit on whole-cell neighbours alone is biased towards whole
cells ("pixel locking", and by the correlation peak's asymmetry); on close neighbours centred
on the current estimate the bias vanishes: shifts of an exactly known texture come back
within 0.01 cell.

Shifts are in grid cells of the north-up lattice (:class:`core.matching.grid.GridSpec`):
``dx_px`` east, ``dy_px`` north, the displacement of the right ortho's content relative to the
left's (what is at ``p`` in the left ortho is at ``p + d`` in the right one). No I/O here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import map_coordinates, spline_filter

from core.errors import InputError
from core.matching.peaks import integer_peak, ncc, ncc_surface, quadratic_peak

FloatArray = NDArray[np.float64]


class ShiftStatus(IntEnum):
    """Why a window has (or has no) shift."""

    OK = 0
    NODATA = 1  # the window or its search area has cells without value
    FLAT = 2  # no texture: the window's standard deviation is at most min_std
    LOW_NCC = 3  # the best correlation is below min_ncc
    AT_EDGE = 4  # the correlation peak is on the border of the search area


@dataclass(frozen=True)
class CompareConfig:
    """Windows of ``window_px`` cells every ``step_px`` cells, searched over ``+-search_px``
    cells; a shift is kept when its correlation reaches ``min_ncc`` and the window's standard
    deviation exceeds ``min_std`` (image units); ``refine_iterations`` sub-pixel rounds."""

    window_px: int = 64
    step_px: int = 128
    search_px: int = 8
    min_ncc: float = 0.5
    min_std: float = 0.0
    refine_iterations: int = 4

    def __post_init__(self) -> None:
        if self.window_px < 8:
            raise InputError(f"the correlation window must be >= 8 cells, got {self.window_px}")
        if self.step_px < 1:
            raise InputError(f"the window step must be >= 1 cell, got {self.step_px}")
        if self.search_px < 2:
            raise InputError(f"the search radius must be >= 2 cells, got {self.search_px}")
        if not -1.0 <= self.min_ncc < 1.0:
            raise InputError(f"min_ncc must be in [-1, 1), got {self.min_ncc}")
        if not self.min_std >= 0:
            raise InputError(f"min_std must be >= 0, got {self.min_std}")
        if self.refine_iterations < 0:
            raise InputError(f"refine_iterations must be >= 0, got {self.refine_iterations}")

    @property
    def margin_px(self) -> int:
        """Cells needed around a window on each side: the search and two more for the
        spline resampling."""
        return self.search_px + 2


@dataclass(frozen=True, eq=False)
class WindowShifts:
    """Shifts of windows: ``dx_px`` east and ``dy_px`` north in cells (NaN unless ``OK``),
    ``ncc`` the correlation at the shift, ``status`` a :class:`ShiftStatus` code."""

    dx_px: FloatArray
    dy_px: FloatArray
    ncc: FloatArray
    status: NDArray[np.uint8]


def window_origins(first: int, last: int, cfg: CompareConfig) -> NDArray[np.intp]:
    """First cells of the windows along one axis so that each window and its search area lie
    within cells ``first .. last - 1``; spaced ``step_px`` and centred in the span."""
    lo, hi = first + cfg.margin_px, last - cfg.margin_px - cfg.window_px
    if hi < lo:
        return np.zeros(0, dtype=np.intp)
    n = (hi - lo) // cfg.step_px + 1
    start = lo + ((hi - lo) - (n - 1) * cfg.step_px) // 2
    return start + cfg.step_px * np.arange(n, dtype=np.intp)


_E = np.array([-1.0, 0.0, 1.0])
REFINE_STEP_PX = 0.25  # spacing of the 3x3 correlations of a refinement round


def window_shift(template: FloatArray, search: FloatArray, cfg: CompareConfig
                 ) -> tuple[float, float, float, ShiftStatus]:
    """Shift (d_col, d_row) of ``template`` (w x w) inside ``search`` ((w + 2 m) a side with
    ``m = cfg.margin_px``, centred on the template's place), its correlation and status."""
    w, m, s = template.shape[0], cfg.margin_px, cfg.search_px
    if not (np.isfinite(template).all() and np.isfinite(search).all()):
        return math.nan, math.nan, math.nan, ShiftStatus.NODATA
    if float(template.std()) <= cfg.min_std:
        return math.nan, math.nan, math.nan, ShiftStatus.FLAT
    area = search[m - s:m + s + w, m - s:m + s + w]
    ix, iy, peak, nb = integer_peak(ncc_surface(area, template))
    if peak < cfg.min_ncc:
        return math.nan, math.nan, peak, ShiftStatus.LOW_NCC
    if nb is None:
        return math.nan, math.nan, peak, ShiftStatus.AT_EDGE
    dx, dy = quadratic_peak(nb)
    d = np.array([ix - s + dx[0], iy - s + dy[0]])
    coeffs = spline_filter(search.astype(np.float64), order=3)
    rr, cc = np.mgrid[0:w, 0:w].astype(np.float64) + m
    h = REFINE_STEP_PX
    for _ in range(cfg.refine_iterations):
        z = np.empty((3, 3))
        for a, ey in enumerate(_E):
            for b, ex in enumerate(_E):
                patch = map_coordinates(coeffs, [rr + d[1] + h * ey, cc + d[0] + h * ex], order=3,
                                        prefilter=False, mode="nearest")
                z[a, b] = ncc(template, patch)
        if not np.isfinite(z).all():
            break
        step_x, step_y = quadratic_peak(z)
        step = h * np.array([step_x[0], step_y[0]])
        d = d + step
        if abs(d[0]) > s or abs(d[1]) > s:
            return math.nan, math.nan, peak, ShiftStatus.AT_EDGE
        if float(np.abs(step).max()) < 1e-3:
            break
    patch = map_coordinates(coeffs, [rr + d[1], cc + d[0]], order=3, prefilter=False,
                            mode="nearest")
    return float(d[0]), float(d[1]), float(ncc(template, patch)), ShiftStatus.OK


def match_windows(left: FloatArray, right: FloatArray, rows: NDArray[np.intp],
                  cols: NDArray[np.intp], cfg: CompareConfig) -> WindowShifts:
    """Shifts of the windows whose first cells are ``rows x cols`` (a grid) between two
    arrays on the same lattice (``right[i, j]`` is the same ground cell as ``left[i, j]``;
    NaN = no value). Every window with its margin must lie inside the arrays."""
    w, m = cfg.window_px, cfg.margin_px
    shape = (rows.size, cols.size)
    dx, dy, ncc = (np.full(shape, np.nan) for _ in range(3))
    status = np.zeros(shape, np.uint8)
    for a, r in enumerate(rows):
        for b, c in enumerate(cols):
            if r - m < 0 or c - m < 0 or r + w + m > left.shape[0] or c + w + m > left.shape[1]:
                raise InputError("a correlation window and its search area leave the arrays")
            dc, dr, v, st = window_shift(left[r:r + w, c:c + w],
                                         right[r - m:r + w + m, c - m:c + w + m], cfg)
            dx[a, b], dy[a, b], ncc[a, b], status[a, b] = dc, -dr, v, st
    return WindowShifts(dx, dy, ncc, status)


@dataclass(frozen=True)
class DiscrepancyStats:
    """Statistics of the valid window shifts, in cells (``_px``) and metres (``_m``):
    medians of dx (east), dy (north) and of the norm, the norm's 95th percentile and RMS."""

    n_windows: int
    n_valid: int
    median_dx_px: float
    median_dy_px: float
    median_norm_px: float
    p95_norm_px: float
    rms_norm_px: float
    cell_m: float

    def to_dict(self) -> dict[str, Any]:
        px = {"median_dx": self.median_dx_px, "median_dy": self.median_dy_px,
              "median_norm": self.median_norm_px, "p95_norm": self.p95_norm_px,
              "rms_norm": self.rms_norm_px}
        return {"n_windows": self.n_windows, "n_valid": self.n_valid, "cell_m": self.cell_m,
                "px": px, "m": {k: v * self.cell_m for k, v in px.items()}}


def discrepancy_stats(shifts: WindowShifts, cell_m: float) -> DiscrepancyStats:
    """:class:`DiscrepancyStats` of the ``OK`` windows (NaN figures when there is none)."""
    ok = shifts.status == ShiftStatus.OK
    dx, dy = shifts.dx_px[ok], shifts.dy_px[ok]
    norm = np.hypot(dx, dy)
    if norm.size == 0:
        nan = math.nan
        return DiscrepancyStats(int(shifts.status.size), 0, nan, nan, nan, nan, nan, cell_m)
    return DiscrepancyStats(
        int(shifts.status.size), int(norm.size), float(np.median(dx)), float(np.median(dy)),
        float(np.median(norm)), float(np.percentile(norm, 95)),
        float(np.sqrt(np.mean(norm * norm))), float(cell_m))
