"""Rectified matches back to the ground: every disparity of a tile triangulated with the models.

A tile's match ``(u, v, d)`` (rectified left pixel and disparity ``d = u_left - u_right``) goes
back to both sensor images through the inverse affine maps of :mod:`core.matching.rectify`,
and the two lines of sight are intersected (:func:`core.intersection.triangulate`: closest
approach, its midpoint and miss distance).

Why polynomials. Exact triangulation through the models costs about 20 us per point here
(pushbroom ``localize`` at two heights for both images, twice), so a SPOT scene of 36 M
points would take ten minutes. Within a tile the map ``(u, v, d) -> (x, y, h, miss)`` is very
smooth, so it is triangulated exactly on a small lattice (``n_uv`` x ``n_uv`` x ``n_d`` nodes
over the rectified window and the disparity range), fitted with polynomials of total degree
``degree`` in the normalised ``(u, v, d)``, and checked on distinct nodes (offset half a step).
Measured on a 1000 px SPOT tile with 1500 m of relief: cubic polynomials are exact to 0.2 mm
(quadratic: 5 cm). :attr:`DisparityToGround.fit_max_m` reports the check on every tile, and the
degree goes up until the check is within ``tol_m``.

``x``, ``y`` come from a projection the caller gives (``to_xy(lon, lat)``, e.g. the local UTM
zone); heights are WGS84 ellipsoidal, or orthometric (EGM96: ``H = h - N``) when a geoid is
given. No I/O here.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.errors import GeometryError, InputError
from core.geoid import GeoidGrid
from core.intersection import triangulate
from core.matching.rectify import TileRectification
from core.parallel import run_split
from core.sensors.base import SensorModel

FloatArray = NDArray[np.float64]
ToXY = Callable[[FloatArray, FloatArray], tuple[FloatArray, FloatArray]]
MAX_DEGREE = 5


def _exponents(degree: int) -> NDArray[np.int64]:
    return np.array([(i, j, k) for i in range(degree + 1) for j in range(degree + 1 - i)
                     for k in range(degree + 1 - i - j)], dtype=np.int64)


@dataclass(frozen=True)
class GroundPoints:
    """Projected ``x_m``, ``y_m``, height ``h_m`` and the rays' miss distance ``miss_m``."""

    x_m: FloatArray
    y_m: FloatArray
    h_m: FloatArray
    miss_m: FloatArray


@dataclass(frozen=True, eq=False)
class DisparityToGround:
    """Polynomials ``(u, v, d) -> (x, y, h, miss)`` of one tile.

    Inputs are normalised as ``(q - centre) / scale``; ``coef[:, k]`` are the coefficients of
    output ``k`` for the monomials ``u^i v^j d^l`` listed in ``exponents``. ``fit_max_m`` is the
    largest difference in x, y or h between the polynomials and exact triangulation on the
    check nodes.
    """

    centre: FloatArray
    scale: FloatArray
    exponents: NDArray[np.int64]
    coef: FloatArray
    fit_max_m: float

    @property
    def degree(self) -> int:
        return int(self.exponents.sum(axis=1).max())

    def __call__(self, u: ArrayLike, v: ArrayLike, d: ArrayLike) -> GroundPoints:
        u, v, d = (np.ravel(np.asarray(a, dtype=np.float64)) for a in np.broadcast_arrays(u, v, d))
        out = np.zeros((u.size, 4))
        run_split(_evaluate, u.size, u, v, d, np.asarray(self.centre, np.float64),
                  np.asarray(self.scale, np.float64), np.ascontiguousarray(self.exponents),
                  np.ascontiguousarray(self.coef, dtype=np.float64), self.degree, out)
        return GroundPoints(out[:, 0], out[:, 1], out[:, 2], out[:, 3])

    def to_dict(self) -> dict[str, Any]:
        return {"degree": self.degree, "fit_max_m": self.fit_max_m}


def triangulate_matches(
    rect: TileRectification, left: SensorModel, right: SensorModel, u: ArrayLike, v: ArrayLike,
    d: ArrayLike, to_xy: ToXY, h_range_m: tuple[float, float], geoid: GeoidGrid | None = None,
) -> GroundPoints:
    """Exact triangulation of rectified matches ``(u, v, d)`` through the models."""
    u, v, d = (np.ravel(np.asarray(a, dtype=np.float64)) for a in np.broadcast_arrays(u, v, d))
    lc, lr = rect.rect_to_left(u, v)
    rc, rr = rect.rect_to_right(u - d, v)
    t = triangulate([left, right], [lc, rc], [lr, rr], h_range_m)
    x, y = to_xy(t.lon_deg, t.lat_deg)
    h = t.h_m if geoid is None else geoid.ellipsoidal_to_orthometric(t.lon_deg, t.lat_deg, t.h_m)
    return GroundPoints(np.asarray(x, float), np.asarray(y, float), np.asarray(h, float),
                        np.asarray(t.miss_m, float))


def _lattice(window: tuple[int, int, int, int], d_range: tuple[float, float], n_uv: int,
             n_d: int, offset: float) -> tuple[FloatArray, FloatArray, FloatArray]:
    u0, v0, w, h = window

    def axis(a: float, b: float, n: int) -> FloatArray:
        if not offset:
            return np.linspace(a, b, n)
        step = (b - a) / (n - 1)
        return a + (np.arange(n - 1) + offset) * step

    uu, vv, dd = np.meshgrid(axis(u0, u0 + w - 1, n_uv), axis(v0, v0 + h - 1, n_uv),
                             axis(d_range[0], d_range[1], n_d), indexing="ij")
    return uu.ravel(), vv.ravel(), dd.ravel()


def fit_disparity_to_ground(
    rect: TileRectification, left: SensorModel, right: SensorModel,
    window: tuple[int, int, int, int], d_range_px: tuple[float, float], to_xy: ToXY, *,
    geoid: GeoidGrid | None = None, n_uv: int = 9, n_d: int = 6, degree: int = 3,
    tol_m: float = 0.01, h_margin_m: float = 200.0,
) -> DisparityToGround:
    """Fit the tile's ``(u, v, d) -> (x, y, h, miss)`` polynomials (see the module docstring).

    ``window`` is the rectified window ``(u0, v0, width, height)``, ``d_range_px`` the
    disparities to cover. The degree starts at ``degree`` and grows (up to 5) until the check
    nodes agree within ``tol_m``.

    Raises:
        GeometryError: the lattice does not triangulate (the models do not see the same ground).
    """
    d_lo, d_hi = map(float, d_range_px)
    if not d_hi > d_lo:
        d_lo, d_hi = d_lo - 0.5, d_lo + 0.5
    if not 1 <= degree <= MAX_DEGREE:
        raise InputError(f"degree must be in 1..{MAX_DEGREE}, got {degree}")
    h_range = (rect.h_range_m[0] - h_margin_m, rect.h_range_m[1] + h_margin_m)
    nodes = _lattice(window, (d_lo, d_hi), n_uv, n_d, 0.0)
    checks = _lattice(window, (d_lo, d_hi), n_uv, n_d, 0.5)
    exact = triangulate_matches(rect, left, right, *nodes, to_xy, h_range, geoid)
    check = triangulate_matches(rect, left, right, *checks, to_xy, h_range, geoid)
    y_fit = np.stack([exact.x_m, exact.y_m, exact.h_m, exact.miss_m], axis=1)
    y_chk = np.stack([check.x_m, check.y_m, check.h_m], axis=1)
    ok = np.isfinite(y_fit).all(axis=1)
    if ok.sum() < 0.9 * ok.size or not np.isfinite(y_chk).all():
        raise GeometryError("the rays of the tile's matches do not intersect; check that the two "
                            "models belong to one stereo pair")
    q = np.stack(nodes, axis=1)[ok]
    centre = 0.5 * (q.max(axis=0) + q.min(axis=0))
    scale = np.maximum(0.5 * (q.max(axis=0) - q.min(axis=0)), 1e-9)
    offset = y_fit[ok].mean(axis=0)
    for deg in range(degree, MAX_DEGREE + 1):
        exps = _exponents(deg)
        if exps.shape[0] > ok.sum():
            break
        qn = (q - centre) / scale
        design = np.prod(qn[:, None, :] ** exps[None, :, :], axis=2)
        coef, *_ = np.linalg.lstsq(design, y_fit[ok] - offset, rcond=None)
        coef[0] += offset
        model = DisparityToGround(centre, scale, exps, coef, 0.0)
        pred = model(*checks)
        err = float(np.max(np.abs(np.stack([pred.x_m, pred.y_m, pred.h_m], axis=1) - y_chk)))
        model = DisparityToGround(centre, scale, exps, coef, err)
        if err <= tol_m:
            break
    return model


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _evaluate(u: FloatArray, v: FloatArray, d: FloatArray, centre: FloatArray,
              scale: FloatArray, exponents: NDArray[np.int64], coef: FloatArray, degree: int,
              out: FloatArray, start: int, stop: int) -> None:
    """:class:`DisparityToGround`'s polynomials at the points ``start:stop`` into ``out``
    (zeros): per point the powers of the normalised ``(u, v, d)``, then the monomials' terms
    added in the order of ``exponents``, as NumPy added them over arrays (same products, same
    order: the same floats). A compiled loop: a degree-5 tile (56 monomials) of 1 M points
    took 0.49 CPU-s over arrays, most of it temporaries."""
    pw = np.empty((3, degree + 1))
    for n in range(start, stop):
        q0 = (u[n] - centre[0]) / scale[0]
        q1 = (v[n] - centre[1]) / scale[1]
        q2 = (d[n] - centre[2]) / scale[2]
        pw[0, 0] = pw[1, 0] = pw[2, 0] = 1.0
        for e in range(degree):
            pw[0, e + 1] = pw[0, e] * q0
            pw[1, e + 1] = pw[1, e] * q1
            pw[2, e + 1] = pw[2, e] * q2
        for t in range(exponents.shape[0]):
            m = pw[0, exponents[t, 0]] * pw[1, exponents[t, 1]] * pw[2, exponents[t, 2]]
            for o in range(4):
                out[n, o] += m * coef[t, o]
