"""Ray intersection in ECEF: two-ray closest approach and multi-ray least squares.

Rays are given by an origin ``o`` and a direction ``d`` (any length) in ECEF metres,
as arrays of shape (n, 3). :func:`triangulate` builds the rays of any sensor model
(through ``localize`` at two heights) and returns geodetic points.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.errors import GeometryError, InputError
from core.geodesy import ecef_to_geodetic, geodetic_to_ecef
from core.sensors.base import SensorModel

FloatArray = NDArray[np.float64]
PARALLEL_TOL = 1e-12  # |d1 x d2|^2 below this (unit vectors): rays taken as parallel


def _unit(d: FloatArray) -> FloatArray:
    n = np.linalg.norm(d, axis=-1, keepdims=True)
    if np.any(n == 0):
        raise InputError("a ray direction has zero length; each ray needs two distinct points")
    return d / n


@dataclass(frozen=True)
class TwoRayResult:
    """Closest approach of two rays: midpoint (n,3) ECEF, miss distance (n,) m, ray parameters."""

    point_ecef: FloatArray
    miss_m: FloatArray
    s_m: FloatArray  # distance along ray 1 (unit direction) to its closest point
    t_m: FloatArray  # distance along ray 2


def intersect_two_rays(o1: ArrayLike, d1: ArrayLike, o2: ArrayLike, d2: ArrayLike) -> TwoRayResult:
    """Midpoint of the common perpendicular of two rays, and its length (the miss distance).

    Parallel rays give NaN for the point and the distance between the lines as miss.
    """
    o1, o2 = np.atleast_2d(np.asarray(o1, float)), np.atleast_2d(np.asarray(o2, float))
    u, v = _unit(np.atleast_2d(np.asarray(d1, float))), _unit(np.atleast_2d(np.asarray(d2, float)))
    w0 = o1 - o2
    b = np.einsum("ij,ij->i", u, v)
    d = np.einsum("ij,ij->i", u, w0)
    e = np.einsum("ij,ij->i", v, w0)
    denom = 1.0 - b * b
    parallel = denom < PARALLEL_TOL
    safe = np.where(parallel, 1.0, denom)
    s = np.where(parallel, np.nan, (b * e - d) / safe)
    t = np.where(parallel, np.nan, (e - b * d) / safe)
    p1 = o1 + s[:, None] * u
    p2 = o2 + t[:, None] * v
    miss = np.linalg.norm(p1 - p2, axis=1)
    # for parallel rays: distance between the lines
    perp = w0 - d[:, None] * u
    miss = np.where(parallel, np.linalg.norm(perp, axis=1), miss)
    return TwoRayResult(0.5 * (p1 + p2), miss, s, t)


@dataclass(frozen=True)
class MultiRayResult:
    """Least-squares point of k rays per point: (n,3) ECEF, RMS and max perpendicular residual."""

    point_ecef: FloatArray
    rms_m: FloatArray
    max_m: FloatArray
    n_rays: NDArray[np.int64]


def intersect_rays(origins: ArrayLike, directions: ArrayLike) -> MultiRayResult:
    """Point minimising the sum of squared perpendicular distances to k rays.

    ``origins`` and ``directions`` have shape (n, k, 3); rays with NaN are ignored,
    points seen by fewer than two rays (or by parallel ones) get NaN.
    Solves ``sum_i (I - u_i u_i^T) x = sum_i (I - u_i u_i^T) o_i`` per point.
    """
    o = np.asarray(origins, float)
    d = np.asarray(directions, float)
    if o.ndim != 3 or o.shape != d.shape or o.shape[-1] != 3:
        raise InputError(f"origins and directions must both be (n, k, 3), got {o.shape} and {d.shape}")
    valid = np.all(np.isfinite(o), axis=-1) & np.all(np.isfinite(d), axis=-1)
    dn = np.linalg.norm(np.where(valid[..., None], d, 1.0), axis=-1, keepdims=True)
    u = np.where(valid[..., None], d / dn, 0.0)
    o0 = np.where(valid[..., None], o, 0.0)
    eye = np.eye(3)
    proj = eye - u[..., :, None] * u[..., None, :]  # (n,k,3,3)
    proj = proj * valid[..., None, None]
    a = proj.sum(axis=1)
    rhs = np.einsum("nkij,nkj->ni", proj, o0)
    n_rays = valid.sum(axis=1)
    det = np.linalg.det(a)
    # scale-free conditioning test: a = sum of projectors; parallel rays make it rank 2
    ok = (n_rays >= 2) & (np.abs(det) > 1e-12 * np.maximum(n_rays, 1) ** 3)
    x = np.full((o.shape[0], 3), np.nan)
    if ok.any():
        x[ok] = np.linalg.solve(a[ok], rhs[ok][..., None])[..., 0]
    r = x[:, None, :] - o0
    perp = r - np.einsum("nkj,nkj->nk", r, u)[..., None] * u
    dist = np.where(valid, np.linalg.norm(perp, axis=-1), np.nan)
    with np.errstate(invalid="ignore"):
        rms = np.sqrt(np.nanmean(np.where(valid, dist**2, np.nan), axis=1)) if dist.size else dist
        mx = np.nanmax(np.where(valid, dist, -np.inf), axis=1)
    rms = np.where(ok, rms, np.nan)
    mx = np.where(ok, mx, np.nan)
    return MultiRayResult(x, rms, mx, n_rays.astype(np.int64))


def lines_of_sight(
    model: SensorModel, col: ArrayLike, row: ArrayLike, h_lo_m: ArrayLike, h_hi_m: ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """ECEF origin (on the high point) and direction (downward) of each image point's ray."""
    col, row = np.broadcast_arrays(np.asarray(col, float), np.asarray(row, float))
    lo = np.broadcast_to(np.asarray(h_lo_m, float), col.shape)
    hi = np.broadcast_to(np.asarray(h_hi_m, float), col.shape)
    lon_a, lat_a = model.localize(col, row, hi)
    lon_b, lat_b = model.localize(col, row, lo)
    a = np.stack(geodetic_to_ecef(lon_a, lat_a, hi), axis=-1)
    b = np.stack(geodetic_to_ecef(lon_b, lat_b, lo), axis=-1)
    return a, b - a


@dataclass(frozen=True)
class Triangulation:
    """Ground points of matched image points: lon/lat degrees, ellipsoidal h, miss distance m."""

    lon_deg: FloatArray
    lat_deg: FloatArray
    h_m: FloatArray
    miss_m: FloatArray


def triangulate(
    models: Sequence[SensorModel],
    cols: Sequence[ArrayLike],
    rows: Sequence[ArrayLike],
    h_range_m: tuple[float, float],
    *,
    refine_half_span_m: float = 50.0,
) -> Triangulation:
    """Intersect the rays of the same points seen in several images.

    Rays come from ``localize`` at two heights. Rigorous models have straight
    rays; RPC rays are slightly curved, so a second pass rebuilds every ray between
    h +- ``refine_half_span_m`` around the first solution. Two images give the
    closest-approach midpoint and its miss distance (the papers' rule); more give
    the least-squares point and the RMS perpendicular residual.
    """
    if len(models) < 2 or not (len(models) == len(cols) == len(rows)):
        raise InputError("triangulate needs at least two models with one (cols, rows) each")
    lo, hi = h_range_m
    if not hi > lo:
        raise InputError(f"height range {h_range_m} is empty; give (h_min, h_max) with h_min < h_max")
    cs = [np.atleast_1d(np.asarray(c, float)) for c in cols]
    rs = [np.atleast_1d(np.asarray(r, float)) for r in rows]
    n = cs[0].size
    if any(c.size != n or r.size != n for c, r in zip(cs, rs)):
        raise InputError("every image must give the same number of points, in the same order")

    def solve(h_lo, h_hi) -> tuple[FloatArray, FloatArray]:
        rays = [lines_of_sight(m, c, r, h_lo, h_hi) for m, c, r in zip(models, cs, rs)]
        if len(rays) == 2:
            res = intersect_two_rays(rays[0][0], rays[0][1], rays[1][0], rays[1][1])
            return res.point_ecef, res.miss_m
        o = np.stack([ray[0] for ray in rays], axis=1)
        d = np.stack([ray[1] for ray in rays], axis=1)
        mres = intersect_rays(o, d)
        return mres.point_ecef, mres.rms_m

    p, miss = solve(np.full(n, lo), np.full(n, hi))
    if not np.isfinite(p).any():
        raise GeometryError("no ray pair intersects: the images look along parallel directions")
    _, _, h0 = ecef_to_geodetic(p[:, 0], p[:, 1], p[:, 2])
    if refine_half_span_m > 0:
        h0f = np.where(np.isfinite(h0), h0, 0.5 * (lo + hi))
        p, miss = solve(h0f - refine_half_span_m, h0f + refine_half_span_m)
    lon, lat, h = ecef_to_geodetic(p[:, 0], p[:, 1], p[:, 2])
    return Triangulation(lon, lat, h, miss)
