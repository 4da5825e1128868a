"""A stereo pair's epipolar geometry, the pieces its relative orientation is made of: each tie
point on its epipolar curve (height, y-parallax), what a point's neighbours say there, and how
a correction moves an image's projections.

The left pixel's line of sight projects into the right image as an epipolar curve
``E(h) = right.project(left.localize(col_l, row_l, h), h)``; the point's height is the one that
brings ``E`` closest to the matched right pixel, and what is left, across the curve, is the
y-parallax (the rays' miss distance expressed in right-image pixels). No I/O here.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.errors import InputError
from core.orientation.tracks import TrackGroup, fit_group
from core.robust import nmad
from core.sensors.base import SensorModel

FloatArray = NDArray[np.float64]
#: tie points whose y-parallaxes tell what a point's neighbourhood shares (the tie-point
#: search keeps about one per 2 km cell: 12 span about 7 km)
NEIGHBOURS = 12
#: the smallest robust sigma of a y-parallax (px): below it, the matching's own precision
SIGMA_FLOOR_PX = 0.05


@dataclass(frozen=True, eq=False)
class EpipolarFit:
    """Each tie point on its epipolar curve in the right image (arrays of the points).

    ``h_m`` the height whose projection comes closest to the right pixel, ``lon_deg``/``lat_deg``
    the left ray's ground point there, ``parallax_px`` the signed distance across the curve,
    ``along_px`` the distance along it (about 0 once ``h_m`` is solved), ``tangent`` and
    ``normal`` unit vectors (col, row) along and across the curve, ``px_per_m`` how fast the
    curve moves with height.
    """

    h_m: FloatArray
    lon_deg: FloatArray
    lat_deg: FloatArray
    parallax_px: FloatArray
    along_px: FloatArray
    tangent: FloatArray
    normal: FloatArray
    px_per_m: FloatArray


def epipolar_fit(left: SensorModel, right: SensorModel, left_col: ArrayLike,
                 left_row: ArrayLike, right_col: ArrayLike, right_row: ArrayLike,
                 h0_m: ArrayLike, *, dh_m: float = 10.0, max_iter: int = 10,
                 tol_m: float = 1e-3) -> EpipolarFit:
    """Each point's height along its left ray and its y-parallax in the right image: the
    track of two images of :func:`core.orientation.tracks.fit_group`."""
    lc, lr, rc, rr = (np.atleast_1d(np.asarray(a, dtype=np.float64))
                      for a in (left_col, left_row, right_col, right_row))
    fit = fit_group((left, right), TrackGroup(np.arange(lc.size), 0, (1,)),
                    np.stack([lc, rc], axis=1), np.stack([lr, rr], axis=1), h0_m, dh_m=dh_m,
                    max_iter=max_iter, tol_m=tol_m)
    return EpipolarFit(fit.h_m, fit.lon_deg, fit.lat_deg, fit.y[:, 0],
                       np.einsum("ni,ni->n", fit.tangent[:, 0], fit.residual[:, 0]),
                       fit.tangent[:, 0], fit.normal[:, 0], fit.speed[:, 0])


def local_value(col: ArrayLike, row: ArrayLike, y: ArrayLike, use: ArrayLike,
                k: int = NEIGHBOURS, floor: float = SIGMA_FLOOR_PX
                ) -> FloatArray:
    """Per point, what ``y`` is there by its ``k`` nearest other points among ``use`` (image
    position ``col``, ``row``): a plane fitted to their values, less those beyond 3 robust
    sigmas (at least ``floor``) of their median, taken at the point, so a point at the image's
    edge, whose neighbours all lie inward, is compared with the trend they show and not with
    their median (on a cubic of 2 px at the ends that differs by 0.4 px); the median where the
    plane is undetermined. 0 everywhere with no more than ``k`` such points."""
    from scipy.spatial import cKDTree

    y = np.asarray(y, dtype=np.float64)
    idx = np.flatnonzero(np.asarray(use, dtype=bool))
    if idx.size <= k:
        return np.zeros_like(y)
    pos = np.column_stack([np.asarray(col, np.float64), np.asarray(row, np.float64)])
    _, nn = cKDTree(pos[idx]).query(pos, k=k + 1)
    nb = idx[nn]  # (n, k + 1): the point itself first when it is among ``use``
    own = nb == np.arange(y.size)[:, None]
    keep = np.where(own.any(axis=1, keepdims=True), ~own, np.arange(k + 1) < k)
    nb = nb[keep].reshape(y.size, k)
    yn = y[nb]
    med = np.median(yn, axis=1)
    w = (np.abs(yn - med[:, None]) <= 3.0 * max(nmad(yn - med[:, None]), floor)).astype(float)
    d = pos[nb] - pos[:, None, :]  # (n, k, 2)
    scale = np.maximum(np.sqrt(np.mean(np.sum(d**2, axis=2), axis=1)), 1e-9)[:, None, None]
    a = np.concatenate([np.ones(yn.shape + (1,)), d / scale], axis=2)  # (n, k, 3)
    n_mat = np.einsum("nk,nki,nkj->nij", w, a, a)
    rhs = np.einsum("nk,nki,nk->ni", w, a, yn)
    ok = np.linalg.cond(n_mat) < 1e6
    out = med.copy()
    out[ok] = np.linalg.solve(n_mat[ok], rhs[ok][..., None])[:, 0, 0]
    return out


@dataclass(frozen=True)
class ImageCorrection:
    """How the adjustment moved the right image's projections (pixels, right image).

    ``col_shift_px``, ``row_shift_px``: at the image centre; ``epipolar_direction``: the unit
    (col, row) vector of the epipolar line there; the shift split along and across it;
    ``affine``: the 2x3 matrix ``[[a, b, c], [d, e, f]]`` with ``d_col = a col + b row + c``
    (same for rows) that best fits the shift over the image, and the RMS misfit of that affine.
    """

    col_shift_px: float
    row_shift_px: float
    epipolar_direction: tuple[float, float]
    along_epipolar_px: float
    across_epipolar_px: float
    affine: tuple[tuple[float, float, float], tuple[float, float, float]]
    affine_rms_px: float


def image_correction(left: SensorModel, right_before: SensorModel, right_after: SensorModel,
                     n_cols: int, n_rows: int, h_m: float) -> ImageCorrection:
    """The shift ``right_after`` adds to ``right_before``'s projections at height ``h_m``
    (its parts along and across the epipolar line of ``left`` NaN where the two images have
    no base)."""
    c, r = np.meshgrid(np.linspace(0, n_cols - 1, 11), np.linspace(0, n_rows - 1, 11))
    c, r = c.ravel(), r.ravel()
    lon, lat = right_before.localize(c, r, np.full(c.size, h_m))
    c2, r2 = right_after.project(lon, lat, np.full(c.size, h_m))
    design = np.stack([c, r, np.ones_like(c)], axis=1)
    coef, *_ = np.linalg.lstsq(design, np.stack([c2 - c, r2 - r], axis=1), rcond=None)
    misfit = design @ coef - np.stack([c2 - c, r2 - r], axis=1)
    cc, rc = 0.5 * (n_cols - 1), 0.5 * (n_rows - 1)
    lon0, lat0 = right_before.localize(cc, rc, h_m)
    c0, r0 = right_after.project(lon0, lat0, h_m)
    lc, lr = left.project(lon0, lat0, h_m)
    try:
        fit = epipolar_fit(left, right_before, lc, lr, cc, rc, h_m)
        t, nrm = fit.tangent[0], fit.normal[0]
    except InputError:  # along the same lines of sight (one pass's scenes): no epipolar line
        t = nrm = np.full(2, np.nan)
    shift = np.array([float(c0) - cc, float(r0) - rc])
    return ImageCorrection(
        col_shift_px=float(shift[0]), row_shift_px=float(shift[1]),
        epipolar_direction=(float(t[0]), float(t[1])),
        along_epipolar_px=float(t @ shift), across_epipolar_px=float(nrm @ shift),
        affine=(tuple(float(v) for v in coef[:, 0]), tuple(float(v) for v in coef[:, 1])),
        affine_rms_px=float(np.sqrt(np.mean(np.sum(misfit**2, axis=1)))),
    )
