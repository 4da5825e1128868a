"""Stereo rectification of one tile of a pair: an affine map per image (s2p's local approach).

Step 2 of the chain starts here. Dense matchers search along image rows, so each image of a
tile is resampled so that its epipolar lines become rows of the same index.

Why a per-tile affine and not resampling grids (CARS). Pushbroom pairs have no global epipolar
geometry, but over a tile the map ``left (col, row, h) -> right (col, row)`` is very nearly
affine. Measured on the simulator's SPOT pair (10 m, +25.5 / -20 deg across track) with the
true models, the largest y-parallax an affine leaves over the tile's height range is 0.05 px
for 1000 px tiles and 1000 m of relief (0.08 px for 2000 m), 0.2 px for 2000 px tiles and
1.1-1.4 px over the whole 6000 px scene. So tiles of about 1000 px meet the 0.1 px target with
two 2x3 matrices: resampling is one ``cv2.warpAffine`` per image, going back to sensor
pixels is exact (the inverse affine), and there is no grid to interpolate. Every tile reports
its own residual (:attr:`TileRectification.y_residual_max_px`), measured on check points
distinct from the fit points.

The fit. Virtual correspondences: the left tile's pixels on an ``n_grid`` lattice localised at
``n_heights`` heights over the tile's height range and projected into the right image. The left
map is a rotation by ``theta`` (scale kept: one rectified pixel per left pixel); the right
map's second row is the affine ``v' = a col' + b row' + e`` that best equals the left ``v``
(linear least squares for a given ``theta``; ``theta`` by a 1-D search), so the y-parallax is
minimised in left pixels. The right map's first row makes ``u' = u`` at the reference height
``h_ref_m``: the right image is resampled to look like the left one on that plane, and the
disparity ``d = u - u'`` is proportional to ``h - h_ref`` (``disparity_per_m``). A constant
``u`` shift then puts the smallest expected disparity at 0, as OpenCV's matcher wants.

Coordinates: sensor ``(col, row)`` 0-based with pixel centres at integers; rectified ``(u, v)``
likewise; a window's array ``[i, j]`` is rectified ``(u0 + j, v0 + i)``. No I/O here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage
from scipy.optimize import minimize_scalar

from core.dem import GeoDEM
from core.errors import GeometryError, InputError
from core.sensors.base import SensorModel, localize_on_dem
from core.sensors.footprint import PixelBox, edge_pixels

FloatArray = NDArray[np.float64]


def _box_check(box: PixelBox, what: str) -> None:
    c0, r0, c1, r1 = box
    if not (c1 > c0 and r1 > r0):
        raise InputError(f"{what} {box} is empty; give (col0, row0, col1, row1) with col1 > "
                         "col0 and row1 > row0")


@dataclass(frozen=True)
class RectifyConfig:
    """Virtual correspondences of a tile: an ``n_grid`` x ``n_grid`` lattice of left pixels at
    ``n_heights`` heights to fit, a ``n_check`` lattice at ``n_heights + 2`` heights (offset
    half a step, so distinct from the fit points) to measure the residual y-parallax."""

    n_grid: int = 9
    n_heights: int = 5
    n_check: int = 12
    min_height_span_m: float = 50.0

    def __post_init__(self) -> None:
        if self.n_grid < 3 or self.n_check < 2 or self.n_heights < 2:
            raise InputError("RectifyConfig needs n_grid >= 3, n_check >= 2 and n_heights >= 2")
        if not self.min_height_span_m > 0:
            raise InputError("min_height_span_m must be > 0 m")


@dataclass(frozen=True, eq=False)
class TileRectification:
    """Two affine maps from sensor to rectified pixels: ``(u, v) = A @ (col, row, 1)``.

    ``disparity_per_m`` is the mean change of the disparity ``d = u_left - u_right`` per metre
    of height (its sign depends on the viewing geometry); ``h_ref_m`` the height where
    ``d = d_ref_px``. The residual y-parallax is measured over ``h_range_m``.
    """

    left_affine: FloatArray
    right_affine: FloatArray
    h_ref_m: float
    h_range_m: tuple[float, float]
    disparity_per_m: float
    d_ref_px: float
    y_residual_max_px: float
    y_residual_rms_px: float

    def __post_init__(self) -> None:
        for name in ("left_affine", "right_affine"):
            a = np.array(getattr(self, name), dtype=np.float64)
            if a.shape != (2, 3) or not np.isfinite(a).all():
                raise InputError(f"{name} must be a finite 2x3 matrix, got shape {a.shape}")
            a.setflags(write=False)
            object.__setattr__(self, name, a)

    @staticmethod
    def _apply(a: FloatArray, x: ArrayLike, y: ArrayLike) -> tuple[FloatArray, FloatArray]:
        x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
        return a[0, 0] * x + a[0, 1] * y + a[0, 2], a[1, 0] * x + a[1, 1] * y + a[1, 2]

    @staticmethod
    def _inverse(a: FloatArray) -> FloatArray:
        return cv2.invertAffineTransform(a.astype(np.float64))

    def left_to_rect(self, col: ArrayLike, row: ArrayLike) -> tuple[FloatArray, FloatArray]:
        return self._apply(self.left_affine, col, row)

    def right_to_rect(self, col: ArrayLike, row: ArrayLike) -> tuple[FloatArray, FloatArray]:
        return self._apply(self.right_affine, col, row)

    def rect_to_left(self, u: ArrayLike, v: ArrayLike) -> tuple[FloatArray, FloatArray]:
        return self._apply(self._inverse(self.left_affine), u, v)

    def rect_to_right(self, u: ArrayLike, v: ArrayLike) -> tuple[FloatArray, FloatArray]:
        return self._apply(self._inverse(self.right_affine), u, v)

    def shifted(self, du_px: float = 0.0, dv_px: float = 0.0) -> TileRectification:
        """The same rectification with the right image moved by ``(du, dv)`` rectified pixels:
        a right point's ``u'`` grows by ``du`` (so disparities drop by ``du``), its ``v'`` by
        ``dv`` (a pointing correction)."""
        a = np.array(self.right_affine)
        a[0, 2] += du_px
        a[1, 2] += dv_px
        return replace(self, right_affine=a, d_ref_px=self.d_ref_px - du_px)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> TileRectification:
        try:
            return cls(np.asarray(d["left_affine"], float), np.asarray(d["right_affine"], float),
                       float(d["h_ref_m"]), tuple(d["h_range_m"]), float(d["disparity_per_m"]),
                       float(d["d_ref_px"]), float(d["y_residual_max_px"]),
                       float(d["y_residual_rms_px"]))
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f"tile rectification record lacks or mistypes {exc}") from None

    def to_dict(self) -> dict[str, Any]:
        return {
            "left_affine": self.left_affine.tolist(), "right_affine": self.right_affine.tolist(),
            "h_ref_m": self.h_ref_m, "h_range_m": list(self.h_range_m),
            "disparity_per_m": self.disparity_per_m, "d_ref_px": self.d_ref_px,
            "y_residual_max_px": self.y_residual_max_px,
            "y_residual_rms_px": self.y_residual_rms_px,
        }


def virtual_correspondences(
    left: SensorModel, right: SensorModel, box: PixelBox, heights_m: ArrayLike, n_side: int,
    offset: float = 0.0,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """Left pixels of an ``n_side`` lattice over ``box`` (shifted by ``offset`` steps) at each
    height, and their right pixels: ``(col, row, h, col_right, row_right)``, finite only."""
    c0, r0, c1, r1 = box
    step_c, step_r = (c1 - 1 - c0) / (n_side - 1), (r1 - 1 - r0) / (n_side - 1)
    n = n_side - 1 if offset else n_side
    cs = c0 + (np.arange(n) + offset) * step_c
    rs = r0 + (np.arange(n) + offset) * step_r
    cc, rr, hh = np.meshgrid(cs, rs, np.asarray(heights_m, dtype=np.float64), indexing="ij")
    cc, rr, hh = cc.ravel(), rr.ravel(), hh.ravel()
    lon, lat = left.localize(cc, rr, hh)
    cr, rr_r = right.project(lon, lat, hh)
    ok = np.isfinite(cr) & np.isfinite(rr_r)
    return cc[ok], rr[ok], hh[ok], cr[ok], rr_r[ok]


def _v_fit(theta: float, x: FloatArray, y: FloatArray, design: FloatArray
           ) -> tuple[FloatArray, FloatArray]:
    """Residual ``v_left - v_right`` and the right v-row for a left rotation ``theta``."""
    v = -math.sin(theta) * x + math.cos(theta) * y
    coef, *_ = np.linalg.lstsq(design, v, rcond=None)
    return v - design @ coef, coef


def rectify_tile(
    left: SensorModel, right: SensorModel, box: PixelBox, h_range_m: tuple[float, float],
    h_ref_m: float | None = None, config: RectifyConfig = RectifyConfig(),
) -> TileRectification:
    """The affine rectification of the left pixels ``box`` over the heights ``h_range_m``.

    ``h_ref_m`` (default: the middle of the range) is where the disparity is zero before the
    shift of :func:`plan_tile`. See the module docstring for the method.

    Raises:
        GeometryError: the left tile does not project into the right model, or the two
            views are parallel (no disparity with height).
    """
    _box_check(box, "tile")
    lo, hi = map(float, h_range_m)
    if not hi >= lo:
        raise InputError(f"height range {h_range_m} is reversed; give (h_min, h_max)")
    if hi - lo < config.min_height_span_m:  # the fit needs the epipolar direction
        mid = 0.5 * (lo + hi)
        lo, hi = mid - 0.5 * config.min_height_span_m, mid + 0.5 * config.min_height_span_m
    h_ref = 0.5 * (lo + hi) if h_ref_m is None else float(h_ref_m)
    heights = np.linspace(lo, hi, config.n_heights)
    c, r, h, cr, rr = virtual_correspondences(left, right, box, heights, config.n_grid)
    if c.size < 4 * config.n_heights:
        raise GeometryError(f"the left tile {box} does not project into the right image model; "
                            "check that the two models belong to one stereo pair")
    cm, rm, crm, rrm = c.mean(), r.mean(), cr.mean(), rr.mean()
    x, y = c - cm, r - rm
    design = np.stack([cr - crm, rr - rrm, np.ones_like(cr)], axis=1)

    def cost(theta: float) -> float:
        return float(np.sum(_v_fit(theta, x, y, design)[0] ** 2))

    grid = np.radians(np.arange(-90.0, 90.0, 1.0))
    t0 = float(grid[np.argmin([cost(t) for t in grid])])
    step = math.radians(1.0)
    theta = float(minimize_scalar(cost, bounds=(t0 - step, t0 + step), method="bounded",
                                  options={"xatol": 1e-12}).x)
    _, vrow = _v_fit(theta, x, y, design)
    ct, st = math.cos(theta), math.sin(theta)
    # left: rotation about the lattice centre, u along the epipolar lines
    a_left = np.array([[ct, st, -(ct * cm + st * rm)], [-st, ct, -(-st * cm + ct * rm)]])
    # right v-row: v' = a (col' - crm) + b (row' - rrm) + e
    a_right = np.zeros((2, 3))
    a_right[1] = [vrow[0], vrow[1], vrow[2] - vrow[0] * crm - vrow[1] * rrm]
    # right u-row: u' = u on the reference height
    cc, rc, _, crc, rrc = virtual_correspondences(left, right, box, [h_ref], config.n_grid)
    u_ref = a_left[0, 0] * cc + a_left[0, 1] * rc + a_left[0, 2]
    urow, *_ = np.linalg.lstsq(np.stack([crc, rrc, np.ones_like(crc)], axis=1), u_ref,
                               rcond=None)
    a_right[0] = urow
    if abs(np.linalg.det(a_right[:, :2])) < 1e-9:
        raise GeometryError("the right image cannot be rectified on this tile: its epipolar "
                            "lines are parallel to its disparity direction (degenerate pair)")
    rect = TileRectification(a_left, a_right, h_ref, (lo, hi), 0.0, 0.0, 0.0, 0.0)
    # disparity per metre and residual y-parallax on the check lattice
    ch = np.linspace(lo, hi, config.n_heights + 2)
    c, r, h, cr, rr = virtual_correspondences(left, right, box, ch, config.n_check, offset=0.5)
    ul, vl = rect.left_to_rect(c, r)
    ur, vr = rect.right_to_rect(cr, rr)
    dy = vl - vr
    d = ul - ur
    slope = float(np.polyfit(h - h_ref, d, 1)[0])
    if abs(slope) < 1e-9:
        raise GeometryError("the two views are parallel on this tile: the disparity does not "
                            "change with height (no stereo base)")
    return replace(rect, disparity_per_m=slope,
                   y_residual_max_px=float(np.max(np.abs(dy))),
                   y_residual_rms_px=float(np.sqrt(np.mean(dy**2))))


def predicted_disparity(rect: TileRectification, left: SensorModel, right: SensorModel,
                        col: ArrayLike, row: ArrayLike, h_m: ArrayLike) -> FloatArray:
    """Disparity ``u_left - u_right`` (px) of left pixels whose ground is at height ``h_m``."""
    col, row, h = (np.asarray(a, dtype=np.float64) for a in np.broadcast_arrays(col, row, h_m))
    lon, lat = left.localize(col, row, h)
    cr, rr = right.project(lon, lat, h)
    u, _ = rect.left_to_rect(col, row)
    ur, _ = rect.right_to_rect(cr, rr)
    return u - ur


@dataclass(frozen=True)
class TerrainSample:
    """Reference heights (ellipsoidal m) under left pixels; NaN where the reference has none."""

    col: FloatArray
    row: FloatArray
    h_m: FloatArray

    def finite(self) -> TerrainSample:
        ok = np.isfinite(self.h_m)
        return TerrainSample(self.col[ok], self.row[ok], self.h_m[ok])


def sample_terrain(left: SensorModel, box: PixelBox, dem: GeoDEM | None,
                   h_range_m: tuple[float, float], step_px: float = 25.0) -> TerrainSample:
    """Reference heights under a lattice of the left pixels of ``box`` (spacing about
    ``step_px``): the lines of sight intersected with ``dem``, or without a DEM the two ends
    of ``h_range_m`` at every point."""
    _box_check(box, "tile")
    c0, r0, c1, r1 = box
    cs = np.linspace(c0, c1 - 1, max(2, math.ceil((c1 - c0) / step_px) + 1))
    rs = np.linspace(r0, r1 - 1, max(2, math.ceil((r1 - r0) / step_px) + 1))
    cc, rr = (a.ravel() for a in np.meshgrid(cs, rs))
    if dem is None:
        lo, hi = h_range_m
        return TerrainSample(np.concatenate([cc, cc]), np.concatenate([rr, rr]),
                             np.concatenate([np.full(cc.size, lo), np.full(cc.size, hi)]))
    lo, hi = dem.height_range_m()
    _, _, h = localize_on_dem(left, cc, rr, dem, h_range_m=(lo - 10.0, hi + 10.0), tol_m=0.5)
    return TerrainSample(cc, rr, h)


@dataclass(frozen=True, eq=False)
class TilePlan:
    """Everything a tile needs before its pixels are read.

    ``core`` is the left tile (sensor pixels, half-open) whose points this tile produces;
    ``window`` the rectified window ``(u0, v0, width, height)`` matched, which adds
    ``n_disp + margin`` columns on each side and ``margin`` rows so that every core pixel has
    its full search range and context; disparities lie in ``[0, n_disp)``.
    ``left_read``/``right_read`` are the sensor windows holding the rectified window (boxes,
    possibly beyond the image: read them boundless).
    """

    index: int
    core: PixelBox
    rect: TileRectification
    window: tuple[int, int, int, int]
    n_disp: int
    left_read: PixelBox
    right_read: PixelBox
    d_pred_px: tuple[float, float]
    h_terrain_m: tuple[float, float]

    def narrowed(self, d_lo_px: float, d_hi_px: float) -> TilePlan:
        """The plan searching only disparities ``d_lo_px .. d_hi_px`` (clipped to the current
        range): the right map shifted so they start at 0, the window cut by the disparities
        dropped on each side (the sensor windows to read still hold it)."""
        lo = max(0.0, float(d_lo_px))
        hi = min(float(self.n_disp - 1), float(d_hi_px))
        if not hi >= lo:
            return self
        shift = math.floor(lo)
        n_disp = min(self.n_disp, int(16 * math.ceil((hi - shift + 1.0) / 16.0)))
        k = self.n_disp - n_disp
        u0, v0, w, h = self.window
        return replace(self, rect=self.rect.shifted(du_px=float(shift)), n_disp=n_disp,
                       window=(u0 + k, v0, w - 2 * k, h),
                       d_pred_px=(self.d_pred_px[0] - shift, self.d_pred_px[1] - shift))

    def to_dict(self) -> dict[str, Any]:
        return {"index": self.index, "core": list(self.core), "window": list(self.window),
                "n_disp": self.n_disp, "left_read": list(self.left_read),
                "right_read": list(self.right_read), "d_pred_px": list(self.d_pred_px),
                "h_terrain_m": list(self.h_terrain_m), "rectification": self.rect.to_dict()}


def _read_box(inverse: FloatArray, window: tuple[int, int, int, int], pad: int) -> PixelBox:
    u0, v0, w, h = window
    u = np.array([u0, u0 + w - 1, u0 + w - 1, u0], dtype=np.float64)
    v = np.array([v0, v0, v0 + h - 1, v0 + h - 1], dtype=np.float64)
    c, r = TileRectification._apply(inverse, u, v)
    return (math.floor(c.min()) - pad, math.floor(r.min()) - pad,
            math.ceil(c.max()) + pad + 1, math.ceil(r.max()) + pad + 1)


def plan_tile(
    index: int, left: SensorModel, right: SensorModel, core: PixelBox, terrain: TerrainSample,
    margin_m: float, margin_px: int = 32, config: RectifyConfig = RectifyConfig(),
    max_disp: int = 4096, right_pad_px: int = 3,
) -> TilePlan:
    """Rectify a tile and size its disparity search from the reference heights.

    The search covers the disparities predicted from ``terrain`` (reference heights under the
    tile) widened by ``margin_m`` of height either side (reference error, trees, buildings)
    and one pixel, rounded up to a multiple of 16 disparities. The right sensor window is
    padded by ``right_pad_px`` (at least the bicubic kernel's 3 px; more when the right map
    may still move, e.g. by a pointing correction).

    Raises:
        InputError: the search range would exceed ``max_disp`` (the reference is far too
            uncertain: give a better one or a smaller margin).
    """
    t = terrain.finite()
    if t.h_m.size == 0:
        raise GeometryError(f"no reference height under the left tile {core}; give a reference "
                            "DEM that covers the image")
    lo, hi = float(np.min(t.h_m)), float(np.max(t.h_m))
    rect = rectify_tile(left, right, core, (lo - margin_m, hi + margin_m),
                        h_ref_m=float(np.median(t.h_m)), config=config)
    d = predicted_disparity(rect, left, right, t.col, t.row, t.h_m)
    d = d[np.isfinite(d)]
    if d.size == 0:
        raise GeometryError(f"the left tile {core} does not reach the right image model")
    extra = abs(rect.disparity_per_m) * margin_m + 1.0
    d_lo, d_hi = float(d.min()) - extra, float(d.max()) + extra
    shift = math.floor(d_lo)
    rect = rect.shifted(du_px=float(shift))  # disparities now start at 0
    n_disp = int(16 * math.ceil((d_hi - shift + 1.0) / 16.0))
    if n_disp > max_disp:
        raise InputError(
            f"tile {core} needs {n_disp} disparities (> {max_disp}): the heights under it span "
            f"{lo:.0f}..{hi:.0f} m with a margin of {margin_m:.0f} m; give a reference DEM "
            "closer to the terrain or a smaller margin")
    c0, r0, c1, r1 = core
    cu, cv = rect.left_to_rect(np.array([c0, c1 - 1, c1 - 1, c0], float),
                               np.array([r0, r0, r1 - 1, r1 - 1], float))
    pad_u = n_disp + margin_px
    u0 = math.floor(cu.min()) - pad_u
    v0 = math.floor(cv.min()) - margin_px
    window = (u0, v0, math.ceil(cu.max()) + pad_u + 1 - u0,
              math.ceil(cv.max()) + margin_px + 1 - v0)
    inv_l = TileRectification._inverse(rect.left_affine)
    inv_r = TileRectification._inverse(rect.right_affine)
    return TilePlan(index, core, rect, window, n_disp, _read_box(inv_l, window, 3),
                    _read_box(inv_r, window, max(3, right_pad_px)), (d_lo - shift, d_hi - shift),
                    (lo, hi))


def warp_to_window(image: NDArray, origin: tuple[int, int], affine: FloatArray,
                   window: tuple[int, int, int, int], image_size: tuple[int, int],
                   nodata: float | None = None, order: int = 3
                   ) -> tuple[NDArray[np.float32], NDArray[np.bool_]]:
    """Resample a sensor window into the rectified ``window``: cubic B-spline interpolation
    (``order=3``), or bilinear (``order=1``, OpenCV: four times faster and free of Python's
    lock, for previews such as the pointing correction's patches).

    ``image`` holds sensor pixels from ``origin`` ``(col0, row0)``; ``image_size`` is the whole
    image's ``(cols, rows)``. Returns the float32 window and its validity: the sensor position
    lies inside the image and 3 px inside the window given, and no nodata pixel (nor the
    image's edge) within 3 px of it.

    Why not ``cv2.warpAffine(INTER_CUBIC)``: OpenCV's cubic kernel (a = -0.75) does not
    reproduce a linear ramp; it moves the content by up to 0.05 px as a function of the
    sub-pixel position, a periodic disparity bias. The B-spline reproduces cubics exactly.
    """
    u0, v0, w, h = window
    c0, r0 = origin
    a = np.asarray(affine, dtype=np.float64)
    inv = TileRectification._inverse(a)
    src = np.asarray(image, dtype=np.float32)
    bad = ~np.isfinite(src)
    if nodata is not None and not (isinstance(nodata, float) and math.isnan(nodata)):
        bad |= src == nodata
    # pixels beyond the image (a window read past its edge) are no data either
    rr, cc = np.ogrid[r0:r0 + src.shape[0], c0:c0 + src.shape[1]]
    bad |= (rr < 0) | (rr >= image_size[1]) | (cc < 0) | (cc >= image_size[0])
    if bad.any():
        src = np.where(bad, np.float32(np.median(src[~bad]) if (~bad).any() else 0.0), src)
    # window array [i, j] -> source array [row - r0, col - c0]
    (ia, ib, ic), (id_, ie, if_) = inv
    matrix = np.array([[ie, id_], [ib, ia]])
    offset = np.array([id_ * u0 + ie * v0 + if_ - r0, ia * u0 + ib * v0 + ic - c0])
    if order == 1:
        m1 = a.copy()  # array -> window: [j, i] = A (col0 + x, row0 + y, 1) - (u0, v0)
        m1[:, 2] = a[:, 2] + a[:, 0] * c0 + a[:, 1] * r0 - np.array([u0, v0])
        out = cv2.warpAffine(src, m1, (w, h), flags=cv2.INTER_LINEAR,
                             borderMode=cv2.BORDER_REPLICATE)
    elif order == 3:
        out = ndimage.affine_transform(src, matrix, offset=offset, output_shape=(h, w),
                                       order=3, mode="nearest", prefilter=True,
                                       output=np.float32)
    else:
        raise InputError(f"interpolation order must be 1 or 3, got {order}")
    jj, ii = np.meshgrid(np.arange(w, dtype=np.float64) + u0, np.arange(h, dtype=np.float64) + v0)
    col, row = TileRectification._apply(inv, jj, ii)
    valid = (col >= 0) & (col <= image_size[0] - 1) & (row >= 0) & (row <= image_size[1] - 1)
    # and 3 px inside the window given: the spline's edge effects fade within that
    valid &= (col >= c0 + 3) & (col <= c0 + src.shape[1] - 4)
    valid &= (row >= r0 + 3) & (row <= r0 + src.shape[0] - 4)
    if bad.any():
        m = a.copy()  # array -> window: [j, i] = A (col0 + x, row0 + y, 1) - (u0, v0)
        m[:, 2] = a[:, 2] + a[:, 0] * c0 + a[:, 1] * r0 - np.array([u0, v0])
        grown = cv2.dilate(bad.astype(np.uint8), np.ones((7, 7), np.uint8))
        hit = cv2.warpAffine(grown, m, (w, h), flags=cv2.INTER_NEAREST,
                             borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        valid &= hit == 0
    out[~valid] = 0.0
    return out, valid


def plan_tile_on_dem(
    index: int, left: SensorModel, right: SensorModel, core: PixelBox, right_size: tuple[int, int],
    dem: GeoDEM | None, h_range_m: tuple[float, float], margin_m: float, *,
    step_px: float = 25.0, margin_px: int = 32, right_pad_px: int = 3,
    config: RectifyConfig = RectifyConfig(), max_disp: int = 4096,
) -> TilePlan | None:
    """:func:`plan_tile` from a reference DEM (or, without one or where it has no height, the
    scene's ``h_range_m``); None when no ground of the tile is seen by the right image
    (``right_size`` its ``(cols, rows)``)."""
    terrain = sample_terrain(left, core, dem, h_range_m, step_px).finite()
    if terrain.h_m.size == 0:
        terrain = sample_terrain(left, core, None, h_range_m, step_px)
    lon, lat = left.localize(terrain.col, terrain.row, terrain.h_m)
    rc, rr = right.project(lon, lat, terrain.h_m)
    seen = (rc >= 0) & (rc <= right_size[0] - 1) & (rr >= 0) & (rr <= right_size[1] - 1)
    if not seen.any():
        return None
    return plan_tile(index, left, right, core, terrain, margin_m, margin_px, config, max_disp,
                     right_pad_px)


def box_in_image(source: SensorModel, box: PixelBox, target: SensorModel,
                 target_size: tuple[int, int], h_range_m: tuple[float, float]
                 ) -> PixelBox | None:
    """The pixels of ``target`` that see the ground of the ``source`` pixels ``box`` at any
    height of ``h_range_m``: its edges localised at both heights and projected into
    ``target``, their bounding box (whole pixels, end-exclusive) clipped to the image;
    None when it misses the image (a multi-view DSM's region of interest, given in its
    first image, in another pair's left image)."""
    col, row = edge_pixels(box)
    cs, rs = [], []
    for h in map(float, h_range_m):
        lon, lat = source.localize(col, row, np.full(col.size, h))
        c, r = target.project(lon, lat, np.full(col.size, h))
        cs.append(np.asarray(c, np.float64))
        rs.append(np.asarray(r, np.float64))
    c, r = np.concatenate(cs), np.concatenate(rs)
    if not (np.isfinite(c).all() and np.isfinite(r).all()):
        raise GeometryError("the region of interest does not project into every image; "
                            "check the images' models")
    cols, rows = target_size
    out = (max(int(np.floor(c.min())), 0), max(int(np.floor(r.min())), 0),
           min(int(np.ceil(c.max())) + 1, cols), min(int(np.ceil(r.max())) + 1, rows))
    return out if out[2] > out[0] and out[3] > out[1] else None
