"""Automatic tie points between the two images of a stereo pair (step 1 of the chain).

The delivered sensor models of both images are wrong by up to a few hundred metres on the
ground but consistent with each other to first order, so each interest point of the left image
is searched in the right image only around the position the models predict:

1. :func:`detect_points`: Shi-Tomasi corners (minimum eigenvalue of the structure tensor),
   spread over the window by keeping the strongest per small image cell, away from nodata.
2. :func:`predict_search`: the epipolar prior. The left pixel is localised at its height h
   (from a reference DEM) and projected into the right image; the 2x2 Jacobian of that
   left -> right mapping resamples the right image into left geometry; the search box covers
   the epipolar segment between h_lo and h_hi plus the metadata uncertainty on the ground.
3. :func:`core.matching.tiepoint_match.match_points`: normalised cross-correlation of the left
   template over the resampled search box, integer peak, then sub-pixel by re-centred 2-D
   quadratic fits of the correlation (the right image is resampled around the current estimate
   at shrinking steps, so the fit's pixel-locking bias vanishes), then a right -> left
   back-match over the same box that must return to the left point within a tolerance.
4. :func:`check_consistency`: the offsets of good matches from their predictions agree with
   their neighbours' (the models' error is smooth, the reference DEM gives the relief).
5. :func:`best_per_cell`: the best point per ground grid cell, so points cover the overlap.

Image coordinates are ``(col, row)``, 0-based, pixel centres at integers; arrays are indexed
``[row, col]``; windows of a larger image carry their ``(col0, row0)`` origin. Nodata is 0
(or NaN). Ground: WGS84 lon/lat degrees, ellipsoidal heights in metres.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage
from scipy.spatial import cKDTree

from core.dem import GeoDEM
from core.errors import GeometryError, InputError
from core.geodesy import geodetic_to_enu, metres_per_degree
from core.matching.peaks import MEASURES
from core.matching.tiepoint_results import Matches, TiePoints, TiePointStatus
from core.sensors.base import SensorModel, localize_on_dem

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]

_EPI_STEP_M = 10.0  # height step of the epipolar direction
#: the lowest correlation a match keeps, per measure (see TiePointConfig)
MIN_CORRELATION = {"ncc": 0.7, "orientation": 0.5}
#: suns further apart than this call for orientation correlation (see choose_measure)
SUN_CHANGE_DEG = 1.0
# cell ids: (iy + OFFSET) * STRIDE + (ix + OFFSET), valid for |ix|, |iy| < 2**20 cells
_CELL_OFFSET = 2**20
_CELL_STRIDE = 2**21


@dataclass(frozen=True)
class TiePointConfig:
    """Settings of the tie-point search (pixels of the left image, metres on the ground).

    Detection: ``candidates_per_cell`` interest points per ground cell, at most
    ``points_per_tile`` per ``tile_px``-square block, ``min_spacing_px`` apart, none weaker
    than ``quality_level`` times the block's strong corners. Search: ``search_radius_m`` is
    each image's stated geolocation uncertainty; the two errors can add up, so the search
    covers twice that (``pair_radius_m``) around the prediction, plus the epipolar segment over
    the reference DEM's range within ``search_radius_m`` widened by ``height_margin_m``.
    Matching: ``(2 template_half_px + 1)``-square templates, ``refine_iterations`` re-centred
    sub-pixel fits, back-match within ``back_match_tol_px``. ``measure``: ``ncc``, normalised
    cross-correlation, or ``orientation``, orientation correlation (:mod:`core.matching.peaks`)
    for pairs lit by two suns, whose shading moves NCC's matches (:func:`choose_measure`).
    ``min_correlation`` (None: the measure's own, :data:`MIN_CORRELATION`), 0.7 for NCC: two
    independent 15x15 noise patches correlate with a standard deviation of 1/15, so 0.7 is ten
    of them; correct matches score 0.85-0.99 (median 0.96 on the simulated pairs), but on
    scenes changed between dates 12-36 % of the matches at 0.7-0.9 that pass the back-match
    are still wrong. Those are caught by the neighbourhood check (``consistency_*``, see
    :func:`check_consistency`) rather than by a higher threshold, which costs coverage (0.8:
    63 -> 51 % of the cells of a changed tiny scene) and ``best_per_cell`` keeps the best
    correlation of each ``cell_m`` cell anyway. 0.5 for orientation correlation: unrelated
    15x15 patches score a standard deviation of 0.073 (white noise) to 0.12 (noise smoothed
    over 1.2 px, where NCC's is 0.18), so 0.5 is 4-7 of them as 0.7 is 4-11 of NCC's;
    correct matches of the two-sun tiny pair score a median 0.80 (p5 0.64), and the coverage
    stays that of NCC (97 % of the cells against 98; at 0.7, 85 %). An overlap holding fewer than
    ``min_cells_per_side`` squared cells of ``cell_m`` (a crop smaller than the cell) gets
    smaller cells, that many over it (:func:`core.matching.overlap.overlap_cell_m`; 0: never).
    """

    template_half_px: int = 7
    candidates_per_cell: int = 8
    points_per_tile: int = 4000
    tile_px: int = 1024
    min_spacing_px: int = 5
    quality_level: float = 0.01
    search_radius_m: float = 300.0
    min_correlation: float | None = None
    back_match_tol_px: float = 0.5
    cell_m: float = 2000.0
    min_cells_per_side: int = 8
    height_margin_m: float = 50.0
    refine_iterations: int = 4
    consistency_radius_m: float = 3000.0
    consistency_tol_px: float = 1.5
    consistency_height_m: float = 40.0
    measure: str = "ncc"

    def __post_init__(self) -> None:
        positive = ("candidates_per_cell", "points_per_tile", "min_spacing_px",
                    "back_match_tol_px", "cell_m", "consistency_radius_m", "consistency_tol_px")
        nonneg = ("search_radius_m", "height_margin_m", "refine_iterations",
                  "consistency_height_m", "min_cells_per_side")
        bad = [] if self.measure in MEASURES else [
            f"measure must be one of {', '.join(MEASURES)}, got {self.measure!r}"]
        bad += [f"{k} must be > 0, got {getattr(self, k)}" for k in positive
                if not getattr(self, k) > 0]
        bad += [f"{k} must be >= 0, got {getattr(self, k)}" for k in nonneg
                if not getattr(self, k) >= 0]
        if not 2 <= self.template_half_px <= 50:
            bad.append(f"template_half_px must be in 2..50, got {self.template_half_px}")
        if self.tile_px < 64:
            bad.append(f"tile_px must be >= 64, got {self.tile_px}")
        if not (0.0 <= self.quality_level < 1.0 and -1.0 < self.correlation_floor < 1.0):
            bad.append(f"quality_level ({self.quality_level}) must be in [0, 1) and "
                       f"min_correlation ({self.correlation_floor}) in (-1, 1)")
        if bad:
            raise InputError(f"tie points: {bad[0]}")

    @property
    def correlation_floor(self) -> float:
        """The lowest correlation kept: ``min_correlation``, or the measure's own."""
        if self.min_correlation is not None:
            return float(self.min_correlation)
        return MIN_CORRELATION.get(self.measure, math.nan)

    @property
    def pair_radius_m(self) -> float:
        """The relative uncertainty of the two images on the ground: twice each one's."""
        return 2.0 * self.search_radius_m

    def max_points(self, n_pixels: int, gsd_m: float) -> int:
        """Interest points wanted in a block of ``n_pixels`` of ``gsd_m`` ground sampling:
        ``candidates_per_cell`` per ground cell, at most the ``points_per_tile`` density."""
        per_cell = self.candidates_per_cell * n_pixels * gsd_m**2 / self.cell_m**2
        per_tile = self.points_per_tile * n_pixels / self.tile_px**2
        return max(1, round(min(per_cell, per_tile)))


def sun_separation_deg(left: tuple[float, float], right: tuple[float, float]) -> float:
    """The angle (deg) between two suns given as (azimuth, elevation) in degrees."""
    (a1, e1), (a2, e2) = (np.radians(np.asarray(v, dtype=np.float64)) for v in (left, right))
    cos = np.sin(e1) * np.sin(e2) + np.cos(e1) * np.cos(e2) * np.cos(a1 - a2)
    return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))


def choose_measure(left_sun: tuple[float, float] | None, right_sun: tuple[float, float] | None
                   ) -> tuple[str, str]:
    """The tie points' correlation measure for a pair, and why: orientation correlation when
    the two images' suns (azimuth, elevation in degrees, from their metadata) are more than
    :data:`SUN_CHANGE_DEG` apart, NCC when they are not or when either is unknown.

    Why: shading under two suns moves NCC's matches off the epipolar geometry by a common
    y-parallax that the adjustment, weighting hundreds of tie points, puts into the images'
    rows: -0.10 px on the simulated spot pair (suns 16.2 deg apart), 0.07 px of its check
    points' rows; orientation correlation brings it to -0.015 px. On one date NCC is the more
    precise: the y-parallax after the relative orientation of three real Pleiades pairs is
    0.071-0.133 px with NCC, 0.109-0.155 with orientation correlation, an extra 0.075 px per
    point, 0.003 px over 850 points. Spot's bias, 0.006 px per degree if it grows with the
    angle, passes that at about half a degree.
    """
    if left_sun is None or right_sun is None:
        return "ncc", "the suns are not in both images' metadata"
    d = sun_separation_deg(left_sun, right_sun)
    if d > SUN_CHANGE_DEG:
        return "orientation", f"the suns are {d:.1f} deg apart"
    return "ncc", f"the suns are {d:.1f} deg apart"


# ---------------------------------------------------------------------------- interest points


def valid_pixels(image: ArrayLike, nodata: float | None = 0,
                 saturation: float | None = None) -> NDArray[np.bool_]:
    """Pixels that can be matched: finite, not ``nodata`` and below ``saturation`` (when given;
    e.g. 255 for 8-bit or 4095 for 12-bit images)."""
    a = np.asarray(image)
    ok = np.isfinite(a) if a.dtype.kind == "f" else np.ones(a.shape, dtype=bool)
    if nodata is not None:
        ok &= a != nodata
    if saturation is not None:
        ok &= a < saturation
    return ok


def detect_points(
    image: ArrayLike,
    valid_mask: ArrayLike,
    *,
    max_points: int,
    min_spacing_px: int = 8,
    border_px: int = 7,
    quality_level: float = 0.01,
    region: tuple[int, int, int, int] | None = None,
) -> tuple[IntArray, IntArray]:
    """Interest points of an image window: (col, row) window indices, strongest first.

    Shi-Tomasi corners (``cv2.cornerMinEigenVal``, 5x5 blocks) that are local maxima within
    ``min_spacing_px``, whose ``(2 border_px + 1)``-square template is entirely valid
    (``valid_mask``: no nodata, no saturation), stronger than ``quality_level`` times the
    window's 99.5th-percentile corner (flat areas give none), and spread evenly: only the
    strongest per square image cell sized for ``max_points`` over the window (or over
    ``region`` = (col0, row0, col1, row1), end-exclusive, where points must lie).
    """
    img = np.asarray(image, dtype=np.float32)
    valid = np.asarray(valid_mask, dtype=bool) & np.isfinite(img)
    if img.ndim != 2 or valid.shape != img.shape:
        raise InputError(f"detect_points needs a 2-D image and a mask of its shape, got "
                         f"{img.shape} and {valid.shape}")
    if max_points < 1 or min_spacing_px < 1 or border_px < 0:
        raise InputError("detect_points: max_points and min_spacing_px must be >= 1 and "
                         "border_px >= 0")
    b = int(border_px)
    k = np.ones((2 * b + 1, 2 * b + 1), np.uint8)
    ok = cv2.erode(valid.astype(np.uint8), k, borderType=cv2.BORDER_CONSTANT, borderValue=0) > 0
    c0, r0, c1, r1 = region if region is not None else (0, 0, img.shape[1], img.shape[0])
    inside = np.zeros_like(ok)
    inside[max(r0, 0):max(r1, 0), max(c0, 0):max(c1, 0)] = True
    ok &= inside
    empty = (np.empty(0, np.intp), np.empty(0, np.intp))
    if not ok.any():
        return empty
    filled = np.where(valid, img, np.float32(np.mean(img[valid])))
    resp = cv2.cornerMinEigenVal(filled, blockSize=5, ksize=3)
    strong = float(np.percentile(resp[ok], 99.5))
    if not strong > 0:
        return empty
    s = int(min_spacing_px)
    peak = resp >= cv2.dilate(resp, np.ones((2 * s + 1, 2 * s + 1), np.uint8))
    rows, cols = np.nonzero(ok & peak & (resp > quality_level * strong))
    score = resp[rows, cols].astype(np.float64)
    area = float(max(r1 - r0, 1) * max(c1 - c0, 1))
    grid_px = max(float(s), math.sqrt(area / max_points))
    keep = best_per_cell(cols.astype(np.float64), rows.astype(np.float64), score, grid_px)
    keep = keep[np.argsort(-score[keep], kind="stable")][:max_points]
    return cols[keep].astype(np.intp), rows[keep].astype(np.intp)


# ---------------------------------------------------------------------------- heights


@dataclass(frozen=True, eq=False)
class HeightPrior:
    """Where the search heights come from: a reference DEM, or one range for the whole scene.

    With a DEM, a point's height is where its left line of sight meets the DEM, and its range
    the DEM's minimum and maximum within ``radius_m`` around that ground point (the model's own
    error puts it anywhere there) widened by ``margin_m``. Without, every point gets the middle
    of ``h_range_m`` and the range itself.
    """

    dem: GeoDEM | None = None
    dem_lo: GeoDEM | None = None
    dem_hi: GeoDEM | None = None
    h_range_m: tuple[float, float] | None = None
    margin_m: float = 0.0

    @classmethod
    def from_dem(cls, dem: GeoDEM, radius_m: float, margin_m: float) -> HeightPrior:
        """The DEM and its local envelope (min/max filters of ``radius_m``), ellipsoidal h."""
        m_lon, m_lat = metres_per_degree(dem.lat0_deg + 0.5 * (dem.shape[0] - 1) * dem.dlat_deg)
        ny = 2 * math.ceil(radius_m / (abs(dem.dlat_deg) * float(m_lat))) + 1
        nx = 2 * math.ceil(radius_m / (abs(dem.dlon_deg) * float(m_lon))) + 1
        h = dem.h_m
        lo = ndimage.minimum_filter(np.where(np.isnan(h), np.inf, h), size=(ny, nx))
        hi = ndimage.maximum_filter(np.where(np.isnan(h), -np.inf, h), size=(ny, nx))
        lo[~np.isfinite(lo)] = np.nan
        hi[~np.isfinite(hi)] = np.nan
        grid = (dem.lon0_deg, dem.lat0_deg, dem.dlon_deg, dem.dlat_deg)
        return cls(dem, GeoDEM(lo, *grid), GeoDEM(hi, *grid), None, float(margin_m))

    @property
    def typical_h_m(self) -> float:
        """The median DEM height, or the middle of the range."""
        if self.dem is not None:
            return float(np.nanmedian(self.dem.h_m))
        return 0.5 * sum(self.h_range_m) if self.h_range_m is not None else 0.0

    @classmethod
    def from_range(cls, h_min_m: float, h_max_m: float) -> HeightPrior:
        if not (np.isfinite(h_min_m) and np.isfinite(h_max_m) and h_max_m >= h_min_m):
            raise InputError(f"height range ({h_min_m}, {h_max_m}) is not a range; give "
                             "h_min <= h_max in metres (ellipsoidal)")
        return cls(h_range_m=(float(h_min_m), float(h_max_m)))

    def heights(self, model: SensorModel, col: ArrayLike, row: ArrayLike
                ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """(h, h_lo, h_hi) of image points of ``model``; NaN where the ray misses the DEM."""
        col = np.atleast_1d(np.asarray(col, dtype=np.float64)).ravel()
        row = np.atleast_1d(np.asarray(row, dtype=np.float64)).ravel()
        if self.dem is None or self.dem_lo is None or self.dem_hi is None:
            if self.h_range_m is None:
                raise InputError("a HeightPrior needs a DEM or a height range")
            lo, hi = self.h_range_m
            return (np.full(col.size, 0.5 * (lo + hi)), np.full(col.size, lo),
                    np.full(col.size, hi))
        try:
            lon, lat, h = localize_on_dem(model, col, row, self.dem)
        except GeometryError:
            nan = np.full(col.size, np.nan)
            return nan, nan.copy(), nan.copy()
        lo = self.dem_lo.height_m(lon, lat) - self.margin_m
        hi = self.dem_hi.height_m(lon, lat) + self.margin_m
        return h, np.fmin(lo, h - self.margin_m), np.fmax(hi, h + self.margin_m)

    def with_slopes(self, model: SensorModel, col: ArrayLike, row: ArrayLike, step_px: float
                    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
        """(h, h_lo, h_hi) as :meth:`heights`, and the terrain slope seen from the image,
        dh/dcol and dh/drow (metres per pixel; central differences of the DEM heights over
        +-``step_px``; zero without a DEM or off it), in one DEM intersection."""
        col = np.atleast_1d(np.asarray(col, dtype=np.float64)).ravel()
        row = np.atleast_1d(np.asarray(row, dtype=np.float64)).ravel()
        if self.dem is None:
            return (*self.heights(model, col, row), np.zeros(col.size), np.zeros(col.size))
        dc = np.array([0.0, step_px, -step_px, 0.0, 0.0])
        dr = np.array([0.0, 0.0, 0.0, step_px, -step_px])
        h, lo, hi = (a.reshape(5, -1) for a in self.heights(
            model, (col[None] + dc[:, None]).ravel(), (row[None] + dr[:, None]).ravel()))
        g_col = np.nan_to_num((h[1] - h[2]) / (2.0 * step_px))
        g_row = np.nan_to_num((h[3] - h[4]) / (2.0 * step_px))
        return h[0], lo[0], hi[0], g_col, g_row


# ---------------------------------------------------------------------------- epipolar prior


@dataclass(frozen=True, eq=False)
class SearchPrior:
    """Where to search each left point in the right image.

    ``right_col``/``right_row``: the prediction at height ``h_m``; ``jacobian`` (n, 2, 2):
    d(right col, row)/d(left col, row) there; ``half_col_px``/``half_row_px``: half-extent of
    the search box in left-geometry pixels (the right image resampled through the Jacobian);
    ``epipolar`` (n, 2): d(right col, row)/dh, pixels per metre of height (the epipolar
    direction and the parallax rate). ``valid`` is False where no prediction could be made.
    """

    right_col: FloatArray
    right_row: FloatArray
    jacobian: FloatArray
    half_col_px: FloatArray
    half_row_px: FloatArray
    h_m: FloatArray
    epipolar: FloatArray

    @property
    def valid(self) -> NDArray[np.bool_]:
        vals = [self.right_col, self.right_row, self.half_col_px, self.half_row_px]
        ok = np.logical_and.reduce([np.isfinite(v) for v in vals])
        return ok & np.all(np.isfinite(self.jacobian), axis=(1, 2))


def predict_search(
    left_model: SensorModel,
    right_model: SensorModel,
    col: ArrayLike,
    row: ArrayLike,
    h_m: ArrayLike,
    h_lo_m: ArrayLike,
    h_hi_m: ArrayLike,
    radius_m: float,
    *,
    dh_dcol: ArrayLike = 0.0,
    dh_drow: ArrayLike = 0.0,
) -> SearchPrior:
    """The epipolar prior of left points (col, row) with heights h in [h_lo, h_hi] (metres).

    The right position is ``right.project(left.localize(col, row, h), h)``; the Jacobian of
    that mapping comes from central differences of 1 px; the search half-extent, in left pixels,
    covers the right positions at h_lo and h_hi (the epipolar segment, mapped back to left
    geometry through the Jacobian) plus a ground circle of ``radius_m`` converted with the left
    image's local ground sampling, plus 1 px for the sub-pixel fit.
    """
    arrs = np.broadcast_arrays(*(np.atleast_1d(np.asarray(a, dtype=np.float64))
                                 for a in (col, row, h_m, h_lo_m, h_hi_m)))
    c, r, h, lo, hi = (a.ravel() for a in arrs)
    n = c.size
    if radius_m < 0:
        raise InputError(f"search radius must be >= 0 m, got {radius_m}")
    dc = np.array([0.0, 0.5, -0.5, 0.0, 0.0, 0.0, 0.0, 0.0])
    dr = np.array([0.0, 0.0, 0.0, 0.5, -0.5, 0.0, 0.0, 0.0])
    cc = (c[None, :] + dc[:, None]).ravel()
    rr = (r[None, :] + dr[:, None]).ravel()
    hh = np.concatenate([np.tile(h, 5), lo, hi, h + _EPI_STEP_M])
    lon, lat = left_model.localize(cc, rr, hh)
    pc, pr = right_model.project(lon, lat, hh)
    pc, pr = pc.reshape(8, n), pr.reshape(8, n)
    jac = np.empty((n, 2, 2))
    jac[:, 0, 0], jac[:, 1, 0] = pc[1] - pc[2], pr[1] - pr[2]
    jac[:, 0, 1], jac[:, 1, 1] = pc[3] - pc[4], pr[3] - pr[4]
    # ground metres per left pixel (east, north) x (col, row), then its inverse
    lon, lat = lon.reshape(8, n), lat.reshape(8, n)
    epi = np.stack([pc[7] - pc[0], pr[7] - pr[0]], axis=-1) / _EPI_STEP_M
    m_lon, m_lat = metres_per_degree(lat[0])
    g = np.empty((n, 2, 2))
    g[:, 0, 0], g[:, 1, 0] = (lon[1] - lon[2]) * m_lon, (lat[1] - lat[2]) * m_lat
    g[:, 0, 1], g[:, 1, 1] = (lon[3] - lon[4]) * m_lon, (lat[3] - lat[4]) * m_lat
    grad = np.stack(np.broadcast_arrays(np.ravel(dh_dcol) * np.ones(n),
                                        np.ravel(dh_drow) * np.ones(n)), axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        right_px_per_m = jac @ _inv2(g)  # a ground displacement seen in the right image
        # on sloping terrain the mapping follows the surface: J + (d right / dh) (grad h)^T
        jac = jac + epi[:, :, None] * grad[:, None, :]
        jinv = _inv2(jac)
        ends = np.stack([pc[5:7] - pc[0], pr[5:7] - pr[0]], axis=-1)  # (2 ends, n, 2)
        seg = np.einsum("nij,enj->eni", jinv, ends)
        radius_px = radius_m * np.linalg.norm(jinv @ right_px_per_m, axis=2)  # (n, 2)
        half_col = np.max(np.abs(seg[..., 0]), axis=0) + radius_px[:, 0] + 1.0
        half_row = np.max(np.abs(seg[..., 1]), axis=0) + radius_px[:, 1] + 1.0
    return SearchPrior(pc[0], pr[0], jac, half_col, half_row, h, epi)


def _inv2(a: FloatArray) -> FloatArray:
    """Inverses of 2x2 matrices (n, 2, 2); NaN for singular ones."""
    det = a[:, 0, 0] * a[:, 1, 1] - a[:, 0, 1] * a[:, 1, 0]
    det = np.where(np.abs(det) > 1e-12, det, np.nan)
    out = np.empty_like(a)
    out[:, 0, 0], out[:, 1, 1] = a[:, 1, 1] / det, a[:, 0, 0] / det
    out[:, 0, 1], out[:, 1, 0] = -a[:, 0, 1] / det, -a[:, 1, 0] / det
    return out


def search_windows(col: ArrayLike, row: ArrayLike, prior: SearchPrior, template_half_px: int
                   ) -> tuple[tuple[int, int, int, int], tuple[int, int, int, int]] | None:
    """The (col0, row0, col1, row1) windows, end-exclusive, that
    :func:`~core.matching.tiepoint_match.match_points` reads for
    these points: in the left image their templates and back-match boxes, in the right image
    their search boxes; None if no point has a prior."""
    ok = prior.valid
    if not ok.any():
        return None
    ex = np.ceil(prior.half_col_px[ok]) + template_half_px + 2
    ey = np.ceil(prior.half_row_px[ok]) + template_half_px + 2
    j = prior.jacobian[ok]
    boxes = [(np.asarray(col, np.float64)[ok], np.asarray(row, np.float64)[ok], ex, ey),
             (prior.right_col[ok], prior.right_row[ok], np.abs(j[:, 0, 0]) * ex
              + np.abs(j[:, 0, 1]) * ey, np.abs(j[:, 1, 0]) * ex + np.abs(j[:, 1, 1]) * ey)]
    left, right = ((int(np.floor(np.min(c - hc))), int(np.floor(np.min(r - hr))),
                    int(np.ceil(np.max(c + hc))) + 1, int(np.ceil(np.max(r + hr))) + 1)
                   for c, r, hc, hr in boxes)
    return left, right


# ---------------------------------------------------------------------------- ground cells


def ground_xy_m(model: SensorModel, col: ArrayLike, row: ArrayLike, h_m: ArrayLike,
                origin: tuple[float, float, float]) -> tuple[FloatArray, FloatArray]:
    """East, north metres, in the local frame at ``origin`` (lon, lat, h), of image points
    localised at heights ``h_m``."""
    lon, lat = model.localize(col, row, h_m)
    e, n, _ = geodetic_to_enu(lon, lat, h_m, origin)
    return np.asarray(e, np.float64), np.asarray(n, np.float64)


def default_search_radius_m(gsd_m: float) -> float:
    """The metadata's ground uncertainty when none is stated: 30 pixels, between 10 and 300 m
    (archive SPOT: 100-300 m at 10-20 m; Pleiades: about 10 m at 0.5 m)."""
    return float(np.clip(30.0 * gsd_m, 10.0, 300.0))


def ground_sampling_m(model: SensorModel, col: float, row: float, h_m: float) -> float:
    """Ground metres per pixel of ``model`` at (col, row) and height ``h_m``: the geometric
    mean of the ground steps of one column and one row."""
    h = np.full(3, h_m)
    lon, lat = model.localize([col, col + 1.0, col], [row, row, row + 1.0], h)
    e, n, _ = geodetic_to_enu(lon, lat, h, (lon[0], lat[0], h_m))
    gsd = math.sqrt(math.hypot(e[1], n[1]) * math.hypot(e[2], n[2]))
    if not gsd > 0:
        raise GeometryError(f"the sensor model gives no ground sampling at pixel ({col:.0f}, "
                            f"{row:.0f}); check the model")
    return gsd


def cell_ids(x_m: ArrayLike, y_m: ArrayLike, cell_m: float) -> NDArray[np.int64]:
    """The id of the ``cell_m`` square grid cell (origin 0, 0) holding each point; -1 for
    non-finite coordinates."""
    x = np.asarray(x_m, dtype=np.float64)
    y = np.asarray(y_m, dtype=np.float64)
    ok = np.isfinite(x) & np.isfinite(y)
    ix = np.floor(np.where(ok, x, 0.0) / cell_m).astype(np.int64)
    iy = np.floor(np.where(ok, y, 0.0) / cell_m).astype(np.int64)
    if np.any(np.abs(ix[ok]) >= _CELL_OFFSET) or np.any(np.abs(iy[ok]) >= _CELL_OFFSET):
        raise InputError(f"cell size {cell_m} m is too small for points {np.nanmax(np.abs(x))} "
                         "m from the origin; use a larger cell")
    return np.where(ok, (iy + _CELL_OFFSET) * _CELL_STRIDE + ix + _CELL_OFFSET, -1)


def best_per_cell(x_m: ArrayLike, y_m: ArrayLike, score: ArrayLike, cell_m: float) -> IntArray:
    """Indices (ascending) of the highest-``score`` point in each ``cell_m`` square cell of the
    (x, y) plane; points with a non-finite coordinate or score are never kept. Ties go to the
    first point."""
    if not cell_m > 0:
        raise InputError(f"cell size must be > 0, got {cell_m}")
    s = np.asarray(score, dtype=np.float64).ravel()
    ids = cell_ids(np.ravel(x_m), np.ravel(y_m), cell_m)
    cand = np.flatnonzero((ids >= 0) & np.isfinite(s))
    if cand.size == 0:
        return np.empty(0, np.intp)
    order = cand[np.lexsort((cand, -s[cand], ids[cand]))]
    first = np.ones(order.size, bool)
    first[1:] = ids[order[1:]] != ids[order[:-1]]
    return np.sort(order[first]).astype(np.intp)


def check_consistency(matches: Matches, x_m: ArrayLike, y_m: ArrayLike, cfg: TiePointConfig,
                      *, heights_known: bool = True, min_neighbours: int = 3) -> Matches:
    """Flag matches whose offset from their prediction disagrees with their neighbours'.

    The delivered models' error moves the matches of an area together, and heights move them
    along the epipolar line by the parallax of the terrain above the reference DEM. So the
    offset (match - prediction, right pixels) of a good match differs from the median offset
    of the other matches within ``cfg.consistency_radius_m`` (ground x, y in metres) by at most
    ``cfg.consistency_tol_px`` across the epipolar line, and by that plus the parallax of
    ``cfg.consistency_height_m`` along it (canopy, buildings, reference errors). Without a
    reference DEM (``heights_known`` False) heights are unknown and only the across-epipolar
    part is checked. Matches with fewer than ``min_neighbours`` neighbours are kept. Returns
    the matches with ``INCONSISTENT`` statuses.
    """
    idx = np.flatnonzero(matches.ok & np.isfinite(np.asarray(x_m)) & np.isfinite(np.asarray(y_m)))
    if idx.size <= min_neighbours:
        return matches
    xy = np.stack([np.asarray(x_m, np.float64)[idx], np.asarray(y_m, np.float64)[idx]], axis=1)
    off = np.stack([matches.right_col - matches.pred_col,
                    matches.right_row - matches.pred_row], axis=1)[idx]
    epi = np.stack([matches.epipolar_col, matches.epipolar_row], axis=1)[idx]
    rate = np.linalg.norm(epi, axis=1)
    unit = epi / np.where(rate > 0, rate, 1.0)[:, None]
    bad = np.zeros(idx.size, bool)
    for k, nb in enumerate(cKDTree(xy).query_ball_point(xy, cfg.consistency_radius_m)):
        nb = [j for j in nb if j != k]
        if len(nb) < min_neighbours:
            continue
        d = off[k] - np.median(off[nb], axis=0)
        along = d @ unit[k]
        across = d[1] * unit[k, 0] - d[0] * unit[k, 1]
        bad[k] = abs(across) > cfg.consistency_tol_px or (heights_known and abs(along) > (
            cfg.consistency_tol_px + cfg.consistency_height_m * rate[k]))
    return matches.with_status(idx[bad], TiePointStatus.INCONSISTENT)


def select_tie_points(matches: Matches, x_m: ArrayLike, y_m: ArrayLike, cell_m: float
                      ) -> TiePoints:
    """The best matched point (highest correlation) of each ``cell_m`` ground cell, with its
    cell id and prior height; ``x_m``, ``y_m`` are the ground positions of all matches
    (:func:`ground_xy_m`)."""
    ok = np.flatnonzero(matches.ok)
    ids = cell_ids(x_m, y_m, cell_m)
    keep = ok[best_per_cell(np.asarray(x_m)[ok], np.asarray(y_m)[ok],
                            matches.correlation[ok], cell_m)]
    return TiePoints(matches.left_col[keep], matches.left_row[keep], matches.right_col[keep],
                     matches.right_row[keep], matches.correlation[keep], matches.status[keep],
                     ids[keep], matches.h_m[keep])
