"""Terrain-independent RPC fitting from any sensor model (Tao & Hu 2001).

A 3-D grid of image points x heights is localised through the model; the 3rd-order
rational functions col(L, P, H) and row(L, P, H) (RPC00B, 39 unknowns each, 78 in
all, denominators' constant term fixed to 1) are fitted by the linearised, iteratively
re-weighted least squares of Tao & Hu with Tikhonov regularisation. The inverse
polynomials lon(C, R, H), lat(C, R, H) are fitted the same way so ``localize`` starts
close. Accuracy is measured on an independent grid (cells' centres, other heights).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from core.errors import ConvergenceError, InputError
from core.geodesy import metres_per_degree
from core.sensors.base import SensorModel
from core.sensors.rpc import RPCModel
from core.sensors.rpc00b import rational_functions

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class RPCFitConfig:
    """Grid and solver settings of :func:`fit_rpc`."""

    n_cols: int = 21  # grid nodes across the image
    n_rows: int = 21  # grid nodes along the image
    n_heights: int = 9  # height layers
    regularization: float = 1e-9  # Tikhonov weight, relative to the normal matrix trace
    n_iterations: int = 4  # Tao & Hu re-weighting passes

    def __post_init__(self) -> None:
        if min(self.n_cols, self.n_rows) < 6 or self.n_heights < 4:
            raise InputError(
                "an RPC fit needs at least 6x6 image nodes and 4 height layers (78 unknowns); "
                f"got {self.n_cols}x{self.n_rows}x{self.n_heights}"
            )
        if self.regularization < 0 or self.n_iterations < 1:
            raise InputError("regularization must be >= 0 and n_iterations >= 1")


@dataclass(frozen=True)
class RPCFitReport:
    """Errors of a fitted RPC on the independent check grid, in pixels."""

    max_px: float
    rms_px: float
    n_check: int
    max_inverse_m: float  # error of the inverse polynomial (lon/lat), metres on the ground


def monomials(x: FloatArray, y: FloatArray, z: FloatArray) -> FloatArray:
    """The 20 RPC00B monomials of normalised coordinates, shape (n, 20)."""
    return rational_functions(np.eye(20), np.ravel(x), np.ravel(y), np.ravel(z), divide=False).T


def _fit_rational(m: FloatArray, target: FloatArray, cfg: RPCFitConfig) -> tuple[FloatArray, FloatArray]:
    """Numerator (20) and denominator (20, den[0] = 1) with target ~= num(m)/den(m)."""
    a = np.hstack([m, -target[:, None] * m[:, 1:]])  # target*den = num, den0 = 1
    w = np.ones(target.size)
    x = np.zeros(39)
    for _ in range(cfg.n_iterations):
        aw = a * w[:, None]
        bw = target * w
        n = aw.T @ aw
        lam = cfg.regularization * np.trace(n) / n.shape[0]
        x_new = np.linalg.solve(n + lam * np.eye(39), aw.T @ bw)
        den = 1.0 + m[:, 1:] @ x_new[20:]
        if np.any(np.abs(den) < 1e-6):
            raise ConvergenceError(
                "the fitted RPC denominator vanishes inside the fitting grid; fit over a "
                "smaller height range or raise the regularization"
            )
        w = 1.0 / np.abs(den)
        x = x_new
    return x[:20], np.concatenate([[1.0], x[20:]])


def _grid(model: SensorModel, cols: FloatArray, rows: FloatArray, heights: FloatArray):
    c, r, h = np.meshgrid(cols, rows, heights, indexing="ij")
    c, r, h = c.ravel(), r.ravel(), h.ravel()
    lon, lat = model.localize(c, r, h)
    ok = np.isfinite(lon) & np.isfinite(lat)
    return c[ok], r[ok], h[ok], lon[ok], lat[ok]


def fit_rpc(
    model: SensorModel,
    width: int,
    height: int,
    h_range_m: tuple[float, float],
    config: RPCFitConfig = RPCFitConfig(),
) -> tuple[RPCModel, RPCFitReport]:
    """Fit an RPC00B model (with inverse) to ``model`` over an image and a height range.

    ``width``/``height`` are the image size in pixels, ``h_range_m`` the ellipsoidal
    heights the RPC must serve (scene relief plus margin). Returns the RPC and its errors
    on an independent grid (half-cell offsets, heights between the fitting layers).
    """
    h_lo, h_hi = map(float, h_range_m)
    if not (width > 1 and height > 1 and h_hi > h_lo):
        raise InputError(
            f"RPC fit needs an image of at least 2x2 px and h_max > h_min; got {width}x{height}, "
            f"heights {h_range_m}"
        )
    cols = np.linspace(-0.5, width - 0.5, config.n_cols)
    rows = np.linspace(-0.5, height - 0.5, config.n_rows)
    hs = np.linspace(h_lo, h_hi, config.n_heights)
    c, r, h, lon, lat = _grid(model, cols, rows, hs)
    if c.size < 100:
        raise InputError("fewer than 100 grid points could be localised; check the model")

    def off_scale(v: FloatArray) -> tuple[float, float]:
        lo, hi = float(np.min(v)), float(np.max(v))
        return 0.5 * (lo + hi), max(0.5 * (hi - lo), 1e-12)

    col_off, col_scale = (width - 1) / 2.0, width / 2.0
    row_off, row_scale = (height - 1) / 2.0, height / 2.0
    lon_off, lon_scale = off_scale(lon)
    lat_off, lat_scale = off_scale(lat)
    alt_off, alt_scale = 0.5 * (h_lo + h_hi), 0.5 * (h_hi - h_lo)
    L, P, H = (lon - lon_off) / lon_scale, (lat - lat_off) / lat_scale, (h - alt_off) / alt_scale
    C, R = (c - col_off) / col_scale, (r - row_off) / row_scale
    m_ground = monomials(L, P, H)
    m_image = monomials(C, R, H)
    col_num, col_den = _fit_rational(m_ground, C, config)
    row_num, row_den = _fit_rational(m_ground, R, config)
    lon_num, lon_den = _fit_rational(m_image, L, config)
    lat_num, lat_den = _fit_rational(m_image, P, config)
    rpc = RPCModel(
        col_off=col_off, col_scale=col_scale, row_off=row_off, row_scale=row_scale,
        lon_off=lon_off, lon_scale=lon_scale, lat_off=lat_off, lat_scale=lat_scale,
        alt_off=alt_off, alt_scale=alt_scale,
        col_num=col_num, col_den=col_den, row_num=row_num, row_den=row_den,
        lon_num=lon_num, lon_den=lon_den, lat_num=lat_num, lat_den=lat_den,
    )
    return rpc, check_rpc(model, rpc, width, height, h_range_m, config)


def check_rpc(
    model: SensorModel,
    rpc: RPCModel,
    width: int,
    height: int,
    h_range_m: tuple[float, float],
    config: RPCFitConfig = RPCFitConfig(),
) -> RPCFitReport:
    """Errors of ``rpc`` against ``model`` on a grid independent of the fitting grid."""
    h_lo, h_hi = h_range_m
    dc = width / (config.n_cols - 1)
    dr = height / (config.n_rows - 1)
    cols = np.linspace(-0.5, width - 0.5, config.n_cols)[:-1] + dc / 2
    rows = np.linspace(-0.5, height - 0.5, config.n_rows)[:-1] + dr / 2
    dh = (h_hi - h_lo) / (config.n_heights - 1)
    hs = np.linspace(h_lo, h_hi, config.n_heights)[:-1] + dh / 2
    c, r, h, lon, lat = _grid(model, cols, rows, hs)
    pc, pr = rpc.project(lon, lat, h)
    err = np.hypot(pc - c, pr - r)
    # inverse polynomial alone (no Newton): how good a start it gives
    C = (c - rpc.col_off) / rpc.col_scale
    R = (r - rpc.row_off) / rpc.row_scale
    H = (h - rpc.alt_off) / rpc.alt_scale
    coeffs = np.stack([rpc.lon_num, rpc.lon_den, rpc.lat_num, rpc.lat_den])
    ln, lt = rational_functions(coeffs, C, R, H)
    ilon = ln * rpc.lon_scale + rpc.lon_off
    ilat = lt * rpc.lat_scale + rpc.lat_off
    m_lon, m_lat = metres_per_degree(lat)
    d_m = np.hypot((ilon - lon) * m_lon, (ilat - lat) * m_lat)
    return RPCFitReport(float(err.max()), float(np.sqrt(np.mean(err**2))), int(err.size),
                        float(d_m.max()))
