"""Dense matching of a rectified tile (step 2 of the chain).

:func:`match_disparity` is the matcher: OpenCV's semi-global matching (``StereoSGBM``,
``MODE_SGBM_3WAY``: Birchfield-Tomasi costs on x-Sobel pre-filtered images aggregated over a
``block_px`` window, SGM along the image paths, parabolic sub-pixel step, uniqueness and
speckle filtering), run twice (left -> right, and right -> left on the mirrored images) for an
explicit left-right check, then a correlation check (:func:`refine_disparity`: zero-mean
normalised cross-correlation over a small window at the final disparity) that refuses matches
SGM's smoothness carried into areas that changed between the dates. Pixels that fail are
*occluded* when, where they should appear in the right image, the right pixel is matched both
ways to another left pixel (something else is seen there), *mismatched* otherwise. Output:
disparity ``d = u_left - u_right`` (float32 px, NaN where invalid) in rectified geometry and a
:class:`PixelStatus` per pixel. Images enter as local (Wallis-type) normalisations
(:func:`normalize_local`), which even out the radiometry of two dates and two suns.

:func:`measure_y_offset` is s2p's pointing correction, per tile: normalised cross-correlation of
a grid of left patches over the right window, searching the disparity range and a few rows up
and down; the median row offset of the good matches is the residual y-parallax of the two
models on that tile, and the right map is moved by it before dense matching. The disparities
of the same matches narrow the dense search when the reference was far from the terrain.

The whole chain of one tile, from its sensor windows to ground points, is
:mod:`core.matching.dense_tile`. No I/O here; OpenCV runs on the caller's thread pool (set
``cv2.setNumThreads(1)`` in parallel workers).

Measured choices (simulator ``tiny``, 40 m pixels, bare-soil NMAD against the truth DSM; and
the Pleiades Reunion ROI against CARS): the local normalisation raised the match rate under a
17 % change between dates from 49 % to 74 % and cost nothing on a clean pair. SGBM's
parabolic step pulls disparities towards whole pixels (on Reunion the histogram of their
fractional parts is 3.2 times the mean at 0 and 0.27 at 0.5); averaging with a second
matching half a pixel on cancels it to first order: NMAD 11.9 -> 10.5 m (clean) and 16.5 ->
15.4 m (changed), and 0.59 -> 0.53 m against CARS, for twice the SGM time; a 3x3 median
adds 15.4 -> 15.1 m and 0.53 -> 0.52 m. A Lucas-Kanade refinement (``refine_iterations``)
removes the pull on synthetic texture (median error 0.2 -> 0.002 px) but raised the
simulator's NMAD (11.9 -> 12.7-14 m clean, 16.5 -> 25-44 m with changes: a least-squares
step is not robust to the dates' differences) and the difference to CARS, so it is off.

OpenCV's 3-way SGM aggregates costs along rows both ways but along columns top-down only: the
smoothness term drags each disparity towards those of the rows above, a shift of the
disparity map by about a quarter of a row. On slopes along the rows it is a height error that
looks like a horizontal shift of the DSM: against the truth DSM of the simulator, the
disparity error went from -0.086 px on slopes facing one way to +0.098 px on the other
(``tiny``, true models), and the DSMs were displaced by 0.4-0.5 px along track (5 m on
``spot``), which the GCP-free orientation would inherit. The second matching therefore runs
upside down (both images flipped vertically, the aggregation then comes from below): the
average cancels the drag (-0.086/+0.098 -> +0.001/+0.003 px) at no extra cost.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from core.errors import InputError
from core.matching.peaks import ncc_surface
from core.robust import nmad

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


class PixelStatus(IntEnum):
    """What became of a left pixel: matched, mismatched, occluded in the right image, or
    outside the pair (nodata, its match leaves the right image, or its matching windows
    reach into either image's nodata or edge: :func:`inner_valid`)."""

    VALID = 0
    MISMATCH = 1
    OCCLUDED = 2
    OUTSIDE = 3


@dataclass(frozen=True)
class MatchingConfig:
    """Settings of the matcher and of the pointing correction.

    SGM: penalties ``P1 = p1 * block_px**2`` and ``P2 = p2 * block_px**2`` (OpenCV's
    recommended 8 and 32); ``uniqueness_pct``: the best cost must beat the second by this
    margin; speckles: regions smaller than ``speckle_window_px`` whose disparity varies by
    less than ``speckle_range_px`` are removed (0 disables); ``lr_max_diff_px``: the
    left-right check's tolerance. Images: ``normalize_px`` the window of the local
    normalisation (0: a plain stretch between the ``stretch_pct`` percentiles). After SGM:
    ``refine_iterations`` Lucas-Kanade steps over ``refine_px`` windows (0: none), matches
    whose ``refine_px`` ZNCC is below ``min_zncc`` refused, a ``median_px`` median filter of
    the disparities (0: none), and ``half_pixel`` the average with a second matching half a
    pixel on (see :func:`average_half_pixel`), ``second_upside_down`` of the images flipped
    vertically (cancels the 3-way SGM's drag along columns, see the module docstring). Pointing correction: ``pointing_grid`` squared
    patches of ``pointing_patch_px`` searched ``pointing_max_px`` rows up and down, kept above
    ``pointing_min_score``; applied from ``pointing_min_matches`` matches and
    ``pointing_min_px``. ``narrow_search``: the dense search is cut to the patches'
    disparities plus ``narrow_margin_px`` or ``narrow_margin_frac`` of their span.
    """

    block_px: int = 5
    p1: int = 8
    p2: int = 32
    uniqueness_pct: int = 10
    speckle_window_px: int = 50
    speckle_range_px: int = 2
    prefilter_cap: int = 63
    lr_max_diff_px: float = 1.0
    stretch_pct: tuple[float, float] = (0.5, 99.5)
    normalize_px: int = 61
    refine_px: int = 7
    refine_iterations: int = 0
    min_zncc: float = 0.3
    median_px: int = 3
    half_pixel: bool = True
    second_upside_down: bool = True
    pointing_correction: bool = True
    pointing_max_px: int = 10
    pointing_patch_px: int = 21
    pointing_grid: int = 12
    pointing_min_score: float = 0.7
    pointing_min_matches: int = 12
    pointing_min_px: float = 0.1
    narrow_search: bool = True
    narrow_margin_px: float = 16.0
    narrow_margin_frac: float = 0.25

    def __post_init__(self) -> None:
        if self.block_px < 1 or self.block_px % 2 == 0:
            raise InputError(f"block_px must be odd and >= 1, got {self.block_px}")
        if not 0 < self.p1 < self.p2:
            raise InputError(f"SGM penalties need 0 < p1 < p2, got {self.p1}, {self.p2}")
        if not 0 <= self.uniqueness_pct <= 100:
            raise InputError(f"uniqueness_pct must be in 0..100, got {self.uniqueness_pct}")
        if self.speckle_window_px < 0 or self.speckle_range_px < 0 or self.lr_max_diff_px < 0:
            raise InputError("speckle and left-right settings must be >= 0")
        lo, hi = self.stretch_pct
        if not 0 <= lo < hi <= 100:
            raise InputError(f"stretch_pct must be 0 <= low < high <= 100, got {self.stretch_pct}")
        if self.pointing_patch_px < 5 or self.pointing_patch_px % 2 == 0:
            raise InputError("pointing_patch_px must be odd and >= 5")
        if self.pointing_max_px < 1 or self.pointing_grid < 2 or self.pointing_min_matches < 3:
            raise InputError("pointing correction needs max_px >= 1, grid >= 2, min_matches >= 3")
        if not 0 < self.pointing_min_score < 1:
            raise InputError("pointing_min_score must be in (0, 1)")
        if self.median_px not in (0, 1, 3, 5):
            raise InputError(f"median_px must be 0, 1, 3 or 5, got {self.median_px}")
        if self.refine_px < 3 or self.refine_px % 2 == 0 or self.refine_iterations < 0:
            raise InputError("refine_px must be odd and >= 3, refine_iterations >= 0")
        if not -1.0 <= self.min_zncc <= 1.0:
            raise InputError(f"min_zncc must be in [-1, 1], got {self.min_zncc}")
        if self.normalize_px < 0 or self.narrow_margin_px < 0 or self.narrow_margin_frac < 0:
            raise InputError("normalize_px and the search margins must be >= 0")


def to_uint8(image: NDArray, valid: BoolArray, pct: tuple[float, float]) -> NDArray[np.uint8]:
    """Linear stretch of the valid pixels between two percentiles to 1..255; invalid -> 128
    (see :func:`quantize`)."""
    out = np.full(image.shape, 128, dtype=np.uint8)
    if not valid.any():
        return out
    lo, hi = np.percentile(image[valid], pct)
    if not hi > lo:
        hi = lo + 1.0
    scaled = np.clip((image.astype(np.float32) - lo) * (254.0 / (hi - lo)) + 1.0, 1.0, 255.0)
    out[valid] = (scaled[valid] + 0.5).astype(np.uint8)
    return out


def normalize_local(image: NDArray, valid: BoolArray, window_px: int, floor: float = 0.1
                    ) -> NDArray[np.float32]:
    """Wallis-type normalisation: each valid pixel's difference to the mean of its
    ``window_px`` neighbourhood over the neighbourhood's standard deviation (floored at
    ``floor`` times the window's robust global spread, so flat areas keep their noise level);
    0 where invalid. Evens out contrast and the radiometric differences between dates."""
    out = np.zeros(image.shape, dtype=np.float32)
    if not valid.any():
        return out
    w = valid.astype(np.float32)
    f = np.where(valid, image.astype(np.float32), np.float32(0.0))
    k = (window_px, window_px)
    n = np.maximum(cv2.boxFilter(w, -1, k, normalize=False), 1.0)
    mean = cv2.boxFilter(f, -1, k, normalize=False) / n
    var = cv2.boxFilter(f * f, -1, k, normalize=False) / n - mean * mean
    lo, hi = np.percentile(image[valid], (25.0, 75.0))
    sd_floor = max(floor * float(hi - lo) / 1.349, 1e-6)
    z = (f - mean) / np.maximum(np.sqrt(np.maximum(var, 0.0)), sd_floor)
    out[valid] = z[valid]
    return out


def quantize(z: NDArray[np.float32], valid: BoolArray) -> NDArray[np.uint8]:
    """Normalised values to 8 bits for the matcher: ``128 + 32 z`` clipped to 1..255, and 128
    (the mean) where invalid: a dark fill would draw an edge along every image border and
    nodata area, which the two images then match to each other, consistently both ways."""
    out = np.clip(128.0 + 32.0 * z, 1.0, 255.0) + 0.5
    return np.where(valid, out, 128.0).astype(np.uint8)


def _sgbm(n_disp: int, cfg: MatchingConfig) -> cv2.StereoSGBM:
    b = cfg.block_px
    return cv2.StereoSGBM_create(
        minDisparity=0, numDisparities=n_disp, blockSize=b, P1=cfg.p1 * b * b,
        P2=cfg.p2 * b * b, disp12MaxDiff=-1, preFilterCap=cfg.prefilter_cap,
        uniquenessRatio=cfg.uniqueness_pct, speckleWindowSize=cfg.speckle_window_px,
        speckleRange=cfg.speckle_range_px, mode=cv2.STEREO_SGBM_MODE_SGBM_3WAY)


def sgbm_disparity(left8: NDArray[np.uint8], right8: NDArray[np.uint8], n_disp: int,
                   cfg: MatchingConfig = MatchingConfig(),
                   upside_down: bool = False) -> NDArray[np.float32]:
    """One SGBM pass, left to right: disparities in px, -1 where SGBM found none. With
    ``upside_down`` the images are matched flipped vertically (and the result flipped back):
    the column-wise aggregation then runs bottom-up (see the module docstring)."""
    if upside_down:
        return sgbm_disparity(np.ascontiguousarray(left8[::-1]),
                              np.ascontiguousarray(right8[::-1]), n_disp, cfg)[::-1]
    return _sgbm(n_disp, cfg).compute(left8, right8).astype(np.float32) / np.float32(16.0)


@dataclass(frozen=True, eq=False)
class Disparity:
    """Disparity ``u_left - u_right`` (float32 px, NaN invalid), the :class:`PixelStatus` of
    each pixel and the disparity filled from the neighbours where invalid (px)."""

    disparity_px: NDArray[np.float32]
    status: NDArray[np.uint8]
    filled_px: NDArray[np.float32]


def match_disparity(left8: NDArray[np.uint8], right8: NDArray[np.uint8], left_valid: BoolArray,
                    right_valid: BoolArray, n_disp: int, cfg: MatchingConfig = MatchingConfig(),
                    left_z: NDArray[np.float32] | None = None,
                    right_z: NDArray[np.float32] | None = None) -> Disparity:
    """Semi-global matching over disparities ``0 .. n_disp - 1`` with a left-right check.

    ``left8``/``right8`` are rectified 8-bit windows of one shape; a left pixel ``u`` matches the
    right pixel ``u - d``. The first ``n_disp`` columns cannot be matched (their search leaves
    the window): the caller pads the window (:func:`core.matching.rectify.plan_tile`). With
    the normalised float windows ``left_z``/``right_z`` (and ``cfg.refine_px``), consistent
    disparities are refined and checked by correlation (:func:`refine_disparity`) before the
    failures are told apart.
    """
    if left8.shape != right8.shape or left8.dtype != np.uint8 or right8.dtype != np.uint8:
        raise InputError("match_disparity needs two 8-bit windows of the same shape")
    if n_disp < 16 or n_disp % 16:
        raise InputError(f"n_disp must be a positive multiple of 16, got {n_disp}")
    dl = sgbm_disparity(left8, right8, n_disp, cfg)
    dr = sgbm_disparity(np.ascontiguousarray(right8[:, ::-1]),
                        np.ascontiguousarray(left8[:, ::-1]), n_disp, cfg)[:, ::-1]
    h, w = dl.shape
    rows = np.arange(h)[:, None]
    cols = np.arange(w)[None, :]
    ok_l = dl >= 0
    ok_r = (dr >= 0) & right_valid
    q = np.rint(cols - np.where(ok_l, dl, 0.0)).astype(np.int64)
    inside = (q >= 0) & (q < w)
    qc = np.clip(q, 0, w - 1)
    consistent = (ok_l & inside & ok_r[rows, qc]
                  & (np.abs(dr[rows, qc] - dl) <= cfg.lr_max_diff_px) & left_valid)
    disp = np.where(consistent, dl, np.float32(np.nan)).astype(np.float32)
    if cfg.refine_px and left_z is not None and right_z is not None:
        disp = refine_disparity(left_z, right_z, right_valid, disp, cfg)
        consistent = np.isfinite(disp)
    if cfg.median_px > 1:  # a median filter of the matched disparities (as pandora does)
        smooth = cv2.medianBlur(fill_disparity(disp, 0.5 * n_disp), cfg.median_px)
        disp = np.where(consistent, smooth, np.float32(np.nan)).astype(np.float32)
    filled = fill_disparity(disp, 0.5 * n_disp)
    # occluded: where the pixel should appear in the right image, the right pixel is matched
    # both ways to another left pixel: something else is seen there
    qf = np.rint(cols - filled).astype(np.int64)
    qfc = np.clip(qf, 0, w - 1)
    back = np.rint(qfc + np.where(ok_r[rows, qfc], dr[rows, qfc], 0.0)).astype(np.int64)
    backc = np.clip(back, 0, w - 1)
    dr_q = np.where(ok_r[rows, qfc], dr[rows, qfc], np.nan)
    with np.errstate(invalid="ignore"):
        taken = ((qf >= 0) & (qf < w) & consistent[rows, backc]
                 & (np.abs(disp[rows, backc] - dr_q) <= cfg.lr_max_diff_px)
                 & (np.abs(back - cols) > cfg.lr_max_diff_px))
    status = np.where(taken, PixelStatus.OCCLUDED, PixelStatus.MISMATCH).astype(np.uint8)
    status[consistent] = PixelStatus.VALID
    # pixels whose matching windows reach into either image's nodata are outside the pair
    right_inner = inner_valid(right_valid, cfg)
    edge = ~inner_valid(left_valid, cfg) | ((qf >= 0) & (qf < w) & ~right_inner[rows, qfc])
    status[edge] = PixelStatus.OUTSIDE
    disp[edge] = np.nan
    return Disparity(disp, status, filled)


def inner_valid(valid: BoolArray, cfg: MatchingConfig = MatchingConfig()) -> BoolArray:
    """The valid pixels far enough from invalid ones (nodata, the image's edge) to be matched
    without bias: ``block_px // 2 + 2`` px along the rows, ``block_px // 2`` across them.

    Near an edge the SGBM block, its x-Sobel prefilter and the Birchfield-Tomasi costs see the
    flat fill beyond it (:func:`quantize`). On a synthetic pair of constant disparity matched
    as :func:`core.matching.dense_tile.dense_tile` does (checked, then averaged with the
    half-pixel upside-down second matching), the disparities 1-3 px inside a left or right edge
    of the left image's valid area were off by 0.04-0.16 px (too large at left edges, too
    small at right ones), and those whose match fell 1-3 px before a nodata band of the right
    image 0.19-0.48 px too large; past these margins 0.01-0.09 px, as in the interior. Across
    the rows the two matchings, top-down and bottom-up, cancel most of it. On the simulator's
    relative DEMs these pixels put the cells one ring in from the footprint's edge 14 m
    outwards (tiny seed 4; 4.6 m without them).
    """
    ru, rv = cfg.block_px // 2 + 2, cfg.block_px // 2
    kernel = np.ones((2 * rv + 1, 2 * ru + 1), np.uint8)
    return cv2.erode(valid.astype(np.uint8), kernel, borderType=cv2.BORDER_CONSTANT,
                     borderValue=0).astype(bool)


def refine_disparity(left: NDArray[np.float32], right: NDArray[np.float32],
                     right_valid: BoolArray, disparity_px: NDArray[np.float32],
                     cfg: MatchingConfig = MatchingConfig()) -> NDArray[np.float32]:
    """Sub-pixel refinement of the valid (finite) disparities, and a correlation check;
    returns the refined disparities, NaN where invalid or rejected.

    SGBM's parabola over whole-pixel costs pulls disparities towards whole pixels (by up to
    0.25 px on synthetic pairs). Here each disparity is refined by a few Lucas-Kanade steps
    along the rows: the right image, interpolated by cubic B-splines, is sampled at
    ``u - d`` and ``u - d +- 0.5``, and ``d`` moves by ``-sum(e g) / sum(g^2)`` over a
    ``refine_px`` window (``e`` the difference to the left, ``g`` the right's slope), by at
    most half a pixel a step and one pixel in all. Then the zero-mean normalised
    cross-correlation over the window is computed at the final disparity; matches below
    ``min_zncc`` (left-right consistent but uncorrelated: changes between the dates, the
    smoothness of SGM carried into them) are rejected. ``left``/``right`` are the
    normalised (:func:`normalize_local`) windows.
    """
    d0 = disparity_px
    ok = np.isfinite(d0)
    out = np.full(d0.shape, np.nan, dtype=np.float32)
    if not ok.any():
        return out
    h, w = left.shape
    vv, uu = np.nonzero(ok)
    k = (cfg.refine_px, cfg.refine_px)
    if cfg.refine_iterations:  # sub-pixel steps need an interpolation free of bias
        coef = ndimage.spline_filter(right.astype(np.float64), order=3, mode="nearest")

        def at(x: NDArray[np.float64]) -> NDArray[np.float32]:
            res = np.zeros((h, w), dtype=np.float32)
            res[vv, uu] = ndimage.map_coordinates(coef, [vv.astype(np.float64), x], order=3,
                                                  prefilter=False, mode="nearest")
            return res
    else:  # the correlation check alone: bilinear (OpenCV) is enough and much faster
        rows_f = np.arange(h, dtype=np.float32)[:, None]

        def at(x: NDArray[np.float64]) -> NDArray[np.float32]:
            map_x = np.zeros((h, w), dtype=np.float32)
            map_x[vv, uu] = x
            res = cv2.remap(right, map_x, np.broadcast_to(rows_f, (h, w)).copy(),
                            cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
            return np.where(ok, res, np.float32(0.0))

    def box(a: NDArray[np.float32]) -> NDArray[np.float32]:
        return cv2.boxFilter(a, -1, k, normalize=False, borderType=cv2.BORDER_CONSTANT)

    m = ok.astype(np.float32)
    lm = np.where(ok, left, np.float32(0.0))
    start = d0[vv, uu].astype(np.float64)
    d = start.copy()
    for _ in range(cfg.refine_iterations):
        x = uu - d
        rw, g = at(x), at(x + 0.5) - at(x - 0.5)
        e = (lm - rw) * m
        num, den = box(e * g)[vv, uu], box(g * g * m)[vv, uu]
        step = np.where(den > 1e-6, -num / np.maximum(den, 1e-6), 0.0)
        d = start + np.clip(d - start + np.clip(step, -0.5, 0.5), -1.0, 1.0)
    rw = at(uu - d)
    n = np.maximum(box(m), 1.0)
    sl, sr = box(lm * m), box(rw * m)
    cov = box(lm * rw * m) - sl * sr / n
    var_l = box(lm * lm * m) - sl * sl / n
    var_r = box(rw * rw * m) - sr * sr / n
    zncc = (cov / np.sqrt(np.maximum(var_l * var_r, 1e-12)))[vv, uu]
    xr = np.rint(uu - d).astype(np.int64)
    keep = ((zncc >= cfg.min_zncc) & (xr >= 0) & (xr < w)
            & right_valid[vv, np.clip(xr, 0, w - 1)])
    out[vv[keep], uu[keep]] = d[keep]
    return out


def average_half_pixel(first: Disparity, second_px: NDArray[np.float32]) -> Disparity:
    """Average a checked matching with a plain SGBM pass (:func:`sgbm_disparity`) whose right
    image was moved half a pixel (its disparities are 0.5 px smaller): SGBM's parabolic step
    pulls towards whole pixels, the two pulls are half a period apart and cancel to first
    order. Where both matched they are averaged whatever their gap: at edges the top-down first
    and the upside-down second disagree by more than a pixel, each dragged its own way along v;
    keeping the first alone there displaced hrs DEMs by its drag (0.7 m across track, 2.6 m on
    the surface-matching GCPs, 0.23-0.26 px of check-point columns). Where the second has no
    match the first stands alone; the first's checks decide what is valid."""
    d1 = first.disparity_px
    d2 = np.where(second_px >= 0, second_px + np.float32(0.5), np.float32(np.nan))
    both = np.isfinite(d1) & np.isfinite(d2)
    d = np.where(both, 0.5 * (d1 + d2), d1).astype(np.float32)
    filled = np.where(np.isfinite(d), d, first.filled_px).astype(np.float32)
    return Disparity(d, first.status, filled)


def outside_prior(disp: Disparity, d_range_px: tuple[float, float]) -> Disparity:
    """Matches whose disparity lies outside what the reference and its margin allow
    (``d_range_px``) become mismatches: SGM puts some blunders at the ends of the search,
    which the rounding to 16 disparities leaves wider than the prior."""
    d = disp.disparity_px
    with np.errstate(invalid="ignore"):
        out = np.isfinite(d) & ((d < d_range_px[0]) | (d > d_range_px[1]))
    if not out.any():
        return disp
    status = disp.status.copy()
    status[out] = PixelStatus.MISMATCH
    return Disparity(np.where(out, np.float32(np.nan), d).astype(np.float32), status,
                     disp.filled_px)


@dataclass(frozen=True)
class PointingCorrection:
    """Residual y-parallax measured on a tile: the right content lies ``dy_px`` rows below
    the left one (median of ``n_matches`` patch matches, spread ``mad_px``); the matches'
    disparities span ``d_range_px`` (min, max)."""

    dy_px: float
    n_matches: int
    mad_px: float
    applied: bool
    d_range_px: tuple[float, float] = (math.nan, math.nan)


def measure_y_offset(left: NDArray[np.float32], right: NDArray[np.float32],
                     left_valid: BoolArray, right_valid: BoolArray, n_disp: int,
                     cfg: MatchingConfig = MatchingConfig()) -> PointingCorrection:
    """Row offset between the rectified windows from a grid of patch matches (see above)."""
    h, w = left.shape
    p = cfg.pointing_patch_px
    half, m = p // 2, cfg.pointing_max_px
    u_lo, u_hi = n_disp + half, w - half - 1
    v_lo, v_hi = half + m + 1, h - half - m - 2
    vs, us = np.nonzero(left_valid)  # the grid spans the valid part of the left window
    if vs.size:
        u_lo, u_hi = max(u_lo, int(us.min()) + half), min(u_hi, int(us.max()) - half)
        v_lo, v_hi = max(v_lo, int(vs.min()) + half), min(v_hi, int(vs.max()) - half)
    dys: list[float] = []
    ds: list[float] = []
    if u_hi > u_lo and v_hi > v_lo:
        bad = np.ascontiguousarray(~right_valid, dtype=np.uint8)
        for v in np.linspace(v_lo, v_hi, cfg.pointing_grid).astype(int):
            for u in np.linspace(u_lo, u_hi, cfg.pointing_grid).astype(int):
                tpl_ok = left_valid[v - half:v + half + 1, u - half:u + half + 1]
                tpl = left[v - half:v + half + 1, u - half:u + half + 1]
                if not tpl_ok.all() or float(tpl.std()) < 1e-3:
                    continue
                rows = slice(v - half - m, v + half + m + 1)
                cols = slice(u - (n_disp - 1) - half, u + half + 1)
                # positions whose right patch touches an invalid pixel do not count
                score = ncc_surface(right[rows, cols], tpl, bad[rows, cols])
                i, j = np.unravel_index(int(np.argmax(score)), score.shape)
                best = float(score[i, j])
                if best < cfg.pointing_min_score or i in (0, score.shape[0] - 1):
                    continue
                a, b, c = score[i - 1, j], score[i, j], score[i + 1, j]
                den = a - 2.0 * b + c
                frac = 0.5 * (a - c) / den if den < 0 and min(a, c) > -1.0 else 0.0
                dys.append(float(i - m + frac))
                ds.append(float(u - (cols.start + j + half)))
    if len(dys) < cfg.pointing_min_matches:
        return PointingCorrection(0.0, len(dys), math.nan, False)
    arr = np.asarray(dys)
    med = float(np.median(arr))
    return PointingCorrection(med, len(dys), nmad(arr, med), True,
                              (float(min(ds)), float(max(ds))))


def fill_disparity(disparity: NDArray[np.float32], fallback: float) -> NDArray[np.float32]:
    """Invalid (NaN) disparities replaced by the mean of their valid neighbours, over growing
    boxes (31, 127, 511 px), else by the tile's median or ``fallback``."""
    valid = np.isfinite(disparity)
    out = np.where(valid, disparity, np.float32(0.0)).astype(np.float32)
    todo = ~valid
    wv = valid.astype(np.float32)
    for k in (31, 127, 511):
        if not todo.any():
            break
        num = cv2.boxFilter(out * wv, -1, (k, k), normalize=False,
                            borderType=cv2.BORDER_CONSTANT)
        den = cv2.boxFilter(wv, -1, (k, k), normalize=False, borderType=cv2.BORDER_CONSTANT)
        take = todo & (den > 0.5)
        out[take] = num[take] / den[take]
        todo &= ~take
    if todo.any():
        out[todo] = float(np.median(disparity[valid])) if valid.any() else fallback
    return out
