"""One tile of the dense matching (step 2 of the chain), from its sensor windows to ground
points: :func:`dense_tile`, and :func:`retriangulate` for its matches intersected again with
other models.

:func:`dense_tile` rectifies both windows (:mod:`core.matching.rectify`), measures the
pointing correction and narrows the search (:func:`core.matching.dense.measure_y_offset`),
matches (:func:`core.matching.dense.match_disparity`, twice with the half-pixel and upside-down
second matching), then takes every core pixel to the ground through the tile's polynomials
(:mod:`core.matching.triangulate`). Unmatched pixels are placed on the ground with a disparity
filled from their neighbours, so the gridding can tell mismatched cells from occluded ones.
No I/O here; OpenCV runs on the caller's thread pool (set ``cv2.setNumThreads(1)`` in
parallel workers).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from core.geoid import GeoidGrid
from core.matching.dense import (
    MatchingConfig,
    PixelStatus,
    PointingCorrection,
    average_half_pixel,
    inner_valid,
    match_disparity,
    measure_y_offset,
    normalize_local,
    outside_prior,
    quantize,
    sgbm_disparity,
    to_uint8,
)
from core.matching.rectify import TilePlan, TileRectification, warp_to_window
from core.matching.triangulate import GroundPoints, ToXY, fit_disparity_to_ground
from core.sensors.base import SensorModel
from core.sensors.footprint import PixelBox

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
DEFAULT_MATCHING = MatchingConfig()


@dataclass(frozen=True, eq=False)
class SensorWindow:
    """One image's part of a tile: the pixels ``image`` read from the full-image pixel
    ``origin`` (col0, row0), the image's ``nodata`` value (None: none), its ``model`` and the
    whole image's ``size`` (cols, rows), beyond which nothing is valid."""

    image: NDArray
    origin: tuple[int, int]
    model: SensorModel
    size: tuple[int, int]
    nodata: float | None = None

    def warp(self, affine: FloatArray, window: tuple[int, int, int, int], order: int = 3
             ) -> tuple[NDArray[np.float32], BoolArray]:
        """The window resampled into rectified geometry (:func:`warp_to_window`)."""
        return warp_to_window(self.image, self.origin, affine, window, self.size, self.nodata,
                              order)


@dataclass(frozen=True)
class TileStats:
    """Figures of one tile (pixels of its core, in the left image)."""

    index: int
    core: tuple[int, int, int, int]
    n_pixels: int
    n_valid: int
    n_mismatch: int
    n_occluded: int
    n_outside: int
    n_disp: int
    d_pred_px: tuple[float, float]
    h_terrain_m: tuple[float, float]
    y_residual_max_px: float
    y_residual_rms_px: float
    pointing_dy_px: float
    pointing_matches: int
    pointing_applied: bool
    fit_degree: int
    fit_max_m: float
    miss_median_m: float
    bounds_m: tuple[float, float, float, float] | None

    @property
    def n_overlap(self) -> int:
        """Pixels seen by both images (matched, mismatched or occluded)."""
        return self.n_valid + self.n_mismatch + self.n_occluded

    @property
    def match_rate(self) -> float:
        return self.n_valid / self.n_overlap if self.n_overlap else 0.0

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["match_rate"] = self.match_rate
        return d


@dataclass(frozen=True, eq=False)
class TileMatches:
    """What a tile's matching found, enough to triangulate it again with other models: the
    (filled) disparity of each core pixel in the order of :func:`core_pixels`, the final
    rectification (pointing correction included), the rectified window and the disparities
    the ground fit must span."""

    d_px: NDArray[np.float32]
    rect: TileRectification
    window: tuple[int, int, int, int]
    core: PixelBox
    d_range_px: tuple[float, float]


@dataclass(frozen=True, eq=False)
class TileResult:
    """Ground points of a tile's core pixels: projected ``x_m``, ``y_m``, height ``h_m``
    (NaN unless matched) and the :class:`PixelStatus` of each, with the tile's figures and
    its matches."""

    x_m: FloatArray
    y_m: FloatArray
    h_m: NDArray[np.float32]
    status: NDArray[np.uint8]
    stats: TileStats
    matches: TileMatches | None = None


def core_pixels(rect: TileRectification, window: tuple[int, int, int, int],
                core: PixelBox) -> tuple[FloatArray, FloatArray, BoolArray]:
    """Rectified coordinates ``(u, v)`` of the window's pixels and which of them fall in the
    left tile's core (rounded to the nearest sensor pixel)."""
    u0, v0, w, h = window
    uu, vv = np.meshgrid(np.arange(w, dtype=np.float64) + u0, np.arange(h, dtype=np.float64) + v0)
    col, row = rect.rect_to_left(uu, vv)
    c0, r0, c1, r1 = core
    ci, ri = np.floor(col + 0.5), np.floor(row + 0.5)
    return uu, vv, (ci >= c0) & (ci < c1) & (ri >= r0) & (ri < r1)


def retriangulate(matches: TileMatches, left: SensorModel, right: SensorModel, to_xy: ToXY,
                  geoid: GeoidGrid | None = None) -> GroundPoints:
    """The tile's matches intersected again with (e.g. absolutely oriented) models: the same
    image correspondences, new rays. Points in the order of the tile's core pixels."""
    uu, vv, core = core_pixels(matches.rect, matches.window, matches.core)
    g2g = fit_disparity_to_ground(matches.rect, left, right, matches.window, matches.d_range_px,
                                  to_xy, geoid=geoid)
    return g2g(uu[core], vv[core], matches.d_px.astype(np.float64))


def dense_tile(plan: TilePlan, left: SensorWindow, right: SensorWindow, to_xy: ToXY, *,
               geoid: GeoidGrid | None = None, cfg: MatchingConfig = DEFAULT_MATCHING,
               ) -> TileResult:
    """One tile from its sensor windows to ground points (see the module docstring).

    ``left``/``right`` hold the sensor windows ``plan.left_read``/``right_read`` with their
    models (the right one oriented to the left). Heights are ellipsoidal, or EGM96
    orthometric with ``geoid``.
    """
    def warp(p: TilePlan, order: int = 3) -> tuple[NDArray[np.float32], BoolArray,
                                                   NDArray[np.float32], BoolArray]:
        return (*left.warp(p.rect.left_affine, p.window, order),
                *right.warp(p.rect.right_affine, p.window, order))

    pc = PointingCorrection(0.0, 0, math.nan, False)
    if cfg.pointing_correction or cfg.narrow_search:
        lw, lv, rw, rv = warp(plan, order=1)  # patches only: bilinear is enough
        pc = measure_y_offset(lw, rw, lv, rv, plan.n_disp, cfg)
        tuned = plan
        if pc.applied and cfg.pointing_correction and abs(pc.dy_px) >= cfg.pointing_min_px:
            tuned = replace(tuned, rect=tuned.rect.shifted(dv_px=-pc.dy_px))
        else:
            pc = replace(pc, applied=False)
        if pc.n_matches >= cfg.pointing_min_matches and cfg.narrow_search:
            lo, hi = pc.d_range_px
            extra = max(cfg.narrow_margin_px, cfg.narrow_margin_frac * (hi - lo))
            tuned = tuned.narrowed(lo - extra, hi + extra)
        plan = tuned
    lw, lv, rw, rv = warp(plan)
    rect = plan.rect

    def prepared(image: NDArray[np.float32], valid: BoolArray
                 ) -> tuple[NDArray[np.uint8], NDArray[np.float32]]:
        if cfg.normalize_px:
            z = normalize_local(image, valid, cfg.normalize_px)
            return quantize(z, valid), z
        i8 = to_uint8(image, valid, cfg.stretch_pct)
        return i8, i8.astype(np.float32)

    (l8, lz), (r8, rz) = prepared(lw, lv), prepared(rw, rv)
    disp = match_disparity(l8, r8, lv, rv, plan.n_disp, cfg, lz, rz)
    if cfg.half_pixel:  # again with the right image half a pixel on (disparities - 0.5),
        half = replace(plan, rect=rect.shifted(du_px=0.5))  # and upside down
        rw2, rv2 = warp(half)[2:]
        second = sgbm_disparity(l8, prepared(rw2, rv2)[0], plan.n_disp, cfg,
                                upside_down=cfg.second_upside_down)
        disp = average_half_pixel(disp, second)
    disp = outside_prior(disp, plan.d_pred_px)
    u0, v0, w, _ = plan.window
    uu, vv, core = core_pixels(rect, plan.window, plan.core)
    status = disp.status[core]
    d = disp.filled_px[core].astype(np.float64)
    u, v = uu[core], vv[core]
    # an unmatched pixel whose (filled) match leaves the right image is outside the pair
    qu = np.rint(u - d - u0).astype(np.int64)
    qv = (v - v0).astype(np.int64)
    right_in = (qu >= 0) & (qu < w) & inner_valid(rv, cfg)[qv, np.clip(qu, 0, w - 1)]
    status = np.where((status != PixelStatus.VALID) & ~right_in, np.uint8(PixelStatus.OUTSIDE),
                      status).astype(np.uint8)
    d_lo = float(min(np.min(d), 0.0)) if d.size else 0.0
    d_hi = float(max(np.max(d), plan.n_disp - 1)) if d.size else float(plan.n_disp - 1)
    g2g = fit_disparity_to_ground(rect, left.model, right.model, plan.window, (d_lo, d_hi),
                                  to_xy, geoid=geoid)
    pts = g2g(u, v, d)
    valid = status == PixelStatus.VALID
    h_m = np.where(valid, pts.h_m, np.nan).astype(np.float32)
    counts = np.bincount(status, minlength=4)
    bounds = None
    if pts.x_m.size:
        bounds = (float(pts.x_m.min()), float(pts.y_m.min()), float(pts.x_m.max()),
                  float(pts.y_m.max()))
    stats = TileStats(
        index=plan.index, core=plan.core, n_pixels=int(status.size),
        n_valid=int(counts[PixelStatus.VALID]), n_mismatch=int(counts[PixelStatus.MISMATCH]),
        n_occluded=int(counts[PixelStatus.OCCLUDED]), n_outside=int(counts[PixelStatus.OUTSIDE]),
        n_disp=plan.n_disp, d_pred_px=plan.d_pred_px, h_terrain_m=plan.h_terrain_m,
        y_residual_max_px=rect.y_residual_max_px, y_residual_rms_px=rect.y_residual_rms_px,
        pointing_dy_px=pc.dy_px, pointing_matches=pc.n_matches, pointing_applied=pc.applied,
        fit_degree=g2g.degree, fit_max_m=g2g.fit_max_m,
        miss_median_m=float(np.median(pts.miss_m[valid])) if valid.any() else math.nan,
        bounds_m=bounds)
    return TileResult(pts.x_m, pts.y_m, h_m, status, stats,
                      TileMatches(d.astype(np.float32), rect, plan.window, plan.core,
                                  (d_lo, d_hi)))
