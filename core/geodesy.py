"""WGS84 geodesy: geodetic <-> ECEF and local East-North-Up frames.

Angles in degrees at the interface, heights in metres above the WGS84 ellipsoid.
All functions are vectorised over NumPy arrays (scalars work too) and broadcast.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

WGS84_A_M = 6378137.0
WGS84_F = 1.0 / 298.257223563
WGS84_B_M = WGS84_A_M * (1.0 - WGS84_F)
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)  # first eccentricity squared
WGS84_EP2 = WGS84_E2 / (1.0 - WGS84_E2)  # second eccentricity squared

FloatArray = NDArray[np.float64]


def geodetic_to_ecef(
    lon_deg: ArrayLike, lat_deg: ArrayLike, h_m: ArrayLike
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """WGS84 geodetic (lon, lat in degrees, ellipsoidal h in metres) to ECEF (x, y, z) metres."""
    lon = np.radians(np.asarray(lon_deg, dtype=np.float64))
    lat = np.radians(np.asarray(lat_deg, dtype=np.float64))
    h = np.asarray(h_m, dtype=np.float64)
    sin_lat, cos_lat = np.sin(lat), np.cos(lat)
    n = WGS84_A_M / np.sqrt(1.0 - WGS84_E2 * sin_lat**2)
    x = (n + h) * cos_lat * np.cos(lon)
    y = (n + h) * cos_lat * np.sin(lon)
    z = (n * (1.0 - WGS84_E2) + h) * sin_lat
    return x, y, z


def ecef_to_geodetic(
    x: ArrayLike, y: ArrayLike, z: ArrayLike, *, tol_rad: float = 1e-15, max_iter: int = 10
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """ECEF (x, y, z) metres to WGS84 geodetic (lon_deg, lat_deg, h_m).

    Bowring's parametric-latitude iteration, run to convergence (it converges
    cubically: two iterations reach 1e-15 rad for heights up to thousands of km).
    The height uses ``p cos(lat) + z sin(lat) - a sqrt(1 - e2 sin^2 lat)``, which
    is well conditioned everywhere, the poles included.
    """
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    z = np.asarray(z, dtype=np.float64)
    p = np.hypot(x, y)
    beta = np.arctan2(z, (1.0 - WGS84_F) * p)
    lat = beta
    for _ in range(max_iter):
        sb, cb = np.sin(beta), np.cos(beta)
        lat = np.arctan2(z + WGS84_EP2 * WGS84_B_M * sb**3, p - WGS84_E2 * WGS84_A_M * cb**3)
        beta_new = np.arctan2((1.0 - WGS84_F) * np.sin(lat), np.cos(lat))
        done = np.all(np.abs(beta_new - beta) <= tol_rad)
        beta = beta_new
        if done:
            break
    sin_lat, cos_lat = np.sin(lat), np.cos(lat)
    h = p * cos_lat + z * sin_lat - WGS84_A_M * np.sqrt(1.0 - WGS84_E2 * sin_lat**2)
    lon = np.arctan2(y, x)
    return np.degrees(lon), np.degrees(lat), h


def enu_rotation(lon_deg: float, lat_deg: float) -> FloatArray:
    """3x3 matrix R whose rows are the East, North, Up unit vectors in ECEF at (lon, lat).

    ``enu = R @ (ecef - origin)`` and ``ecef = origin + R.T @ enu``.
    """
    lon, lat = np.radians(lon_deg), np.radians(lat_deg)
    sl, cl = np.sin(lon), np.cos(lon)
    sp, cp = np.sin(lat), np.cos(lat)
    return np.array(
        [
            [-sl, cl, 0.0],
            [-sp * cl, -sp * sl, cp],
            [cp * cl, cp * sl, sp],
        ]
    )


def geodetic_to_enu(
    lon_deg: ArrayLike,
    lat_deg: ArrayLike,
    h_m: ArrayLike,
    origin: tuple[float, float, float],
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Geodetic points to East, North, Up metres in the local frame at ``origin`` (lon, lat, h)."""
    x, y, z = geodetic_to_ecef(lon_deg, lat_deg, h_m)
    x0, y0, z0 = geodetic_to_ecef(*origin)
    r = enu_rotation(origin[0], origin[1])
    d = np.stack([x - x0, y - y0, z - z0])
    e, n, u = np.tensordot(r, d, axes=1)
    return e, n, u


def enu_to_geodetic(
    e_m: ArrayLike,
    n_m: ArrayLike,
    u_m: ArrayLike,
    origin: tuple[float, float, float],
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """East, North, Up metres in the local frame at ``origin`` (lon, lat, h) to geodetic."""
    x0, y0, z0 = geodetic_to_ecef(*origin)
    r = enu_rotation(origin[0], origin[1])
    enu = np.stack(np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in (e_m, n_m, u_m))))
    dx, dy, dz = np.tensordot(r.T, enu, axes=1)
    return ecef_to_geodetic(x0 + dx, y0 + dy, z0 + dz)
