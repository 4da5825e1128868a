"""WGS84 geodesy: geodetic <-> ECEF, local East-North-Up frames, metres per degree, where a
line of sight meets a height above the ellipsoid, viewing angles, lon/lat boxes.

Angles in degrees at the interface (:data:`ARCSEC` converts arcseconds), heights in metres
above the WGS84 ellipsoid. All functions are vectorised over NumPy arrays (scalars work too)
and broadcast.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.errors import ConvergenceError, GeometryError, InputError

WGS84_A_M = 6378137.0
WGS84_F = 1.0 / 298.257223563
WGS84_B_M = WGS84_A_M * (1.0 - WGS84_F)
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)  # first eccentricity squared
WGS84_EP2 = WGS84_E2 / (1.0 - WGS84_E2)  # second eccentricity squared
#: one arcsecond in degrees: ``shift_deg = shift_arcsec * ARCSEC``
ARCSEC = 1.0 / 3600.0

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


def enu_rotation(lon_deg: ArrayLike, lat_deg: ArrayLike) -> FloatArray:
    """Matrices R whose rows are the East, North, Up unit vectors in ECEF at (lon, lat).

    Shape ``(..., 3, 3)`` for inputs of shape ``(...)`` (a single 3x3 for scalars);
    ``R[..., 2, :]`` is the ellipsoid normal. ``enu = R @ (ecef - origin)`` and
    ``ecef = origin + R.T @ enu``.
    """
    lon, lat = np.radians(lon_deg), np.radians(lat_deg)
    sl, cl = np.sin(lon), np.cos(lon)
    sp, cp = np.sin(lat), np.cos(lat)
    sl, cl, sp, cp = np.broadcast_arrays(sl, cl, sp, cp)
    r = np.empty(sl.shape + (3, 3))
    r[..., 0, 0], r[..., 0, 1], r[..., 0, 2] = -sl, cl, 0.0
    r[..., 1, 0], r[..., 1, 1], r[..., 1, 2] = -sp * cl, -sp * sl, cp
    r[..., 2, 0], r[..., 2, 1], r[..., 2, 2] = cp * cl, cp * sl, sp
    return r


def metres_per_degree(lat_deg: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Ground metres per degree of longitude and of latitude at ``lat_deg`` on the WGS84
    ellipsoid, exactly: the radii of curvature in the prime vertical (``N cos(lat)``) and in
    the meridian (``M``) times one degree in radians.

    The one conversion of the project between degree steps and metres (windows, margins, cell
    sizes, shifts in metres). It is the local scale at the ellipsoid (a point ``h`` above it
    moves ``(1 + h / R)`` times more): measure distances between points in ECEF or with
    :func:`geodetic_to_enu`. (The scene simulator sizes its world with it, so changing it
    changes every simulated scene.)
    """
    phi = np.radians(np.asarray(lat_deg, dtype=np.float64))
    w = np.sqrt(1.0 - WGS84_E2 * np.sin(phi) ** 2)
    n = WGS84_A_M / w
    m = WGS84_A_M * (1.0 - WGS84_E2) / w**3
    return np.radians(1.0) * n * np.cos(phi), np.radians(1.0) * m


def intersect_ellipsoid(
    pos_m: FloatArray, u: FloatArray, h_m: FloatArray, *, tol_m: float = 1e-6, max_iter: int = 10
) -> tuple[FloatArray, FloatArray]:
    """First point of rays ``pos + s u`` (s > 0) at ellipsoidal height h: (lon, lat) degrees.

    Starts from the ellipsoid inflated by h (a + h, b + h) and corrects along the ray by Newton
    on the geodetic height (its gradient is the ellipsoid normal), so the result is exact at h.
    """
    scale = np.stack([WGS84_A_M + h_m, WGS84_A_M + h_m, WGS84_B_M + h_m], axis=1)
    ps, us = pos_m / scale, u / scale
    qa = np.sum(us * us, axis=1)
    qb = 2.0 * np.sum(ps * us, axis=1)
    qc = np.sum(ps * ps, axis=1) - 1.0
    disc = qb * qb - 4.0 * qa * qc
    if np.any(disc < 0) or np.any(qc <= 0):
        bad = int(np.sum((disc < 0) | (qc <= 0)))
        raise GeometryError(
            f"{bad} lines of sight miss the Earth at the requested height (or start below it); "
            "check the image coordinates, the heights and the attitude"
        )
    s = (-qb - np.sqrt(disc)) / (2.0 * qa)
    for _ in range(max_iter):
        x = pos_m + s[:, None] * u
        lon, lat, h = ecef_to_geodetic(x[:, 0], x[:, 1], x[:, 2])
        err = h - h_m
        if not np.any(np.abs(err) > tol_m):  # NaN inputs give NaN outputs
            return lon, lat
        up = enu_rotation(lon, lat)[:, 2, :]  # ellipsoid normals
        s = s - err / np.sum(up * u, axis=1)
    raise ConvergenceError(
        f"ray-height intersection did not reach {tol_m} m in {max_iter} iterations; "
        "the line of sight is probably grazing the Earth"
    )


def utm_epsg(lon_deg: float, lat_deg: float) -> int:
    """EPSG code of the WGS84 UTM zone holding (lon, lat): 326zz north, 327zz south."""
    zone = int((lon_deg + 180.0) // 6.0) % 60 + 1
    return (32600 if lat_deg >= 0 else 32700) + zone


def incidence_angles(
    sat_pos_m: FloatArray, sat_vel_m_s: FloatArray, ground_m: FloatArray, lon_deg: FloatArray,
    lat_deg: FloatArray,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Viewing angles of ground points (n, 3 ECEF, at ``lon_deg``, ``lat_deg``) from a satellite.

    Returns ``(incidence_rad, across_track_rad, slant_range_m)``: the incidence is the angle at
    the ground between the ellipsoid normal and the direction to the satellite (position
    ``sat_pos_m`` (n, 3), ECEF velocity ``sat_vel_m_s`` (n, 3)); the across-track incidence is
    the same angle in the vertical plane across the ground track, positive when the satellite
    is west of the point (the view looks east).
    """
    r = enu_rotation(lon_deg, lat_deg)
    e, n, u = r[..., 0, :], r[..., 1, :], r[..., 2, :]
    s = sat_pos_m - ground_m
    rng = np.linalg.norm(s, axis=1)
    se, sn, su = (np.sum(s * a, axis=1) for a in (e, n, u))
    ae, an = np.sum(sat_vel_m_s * e, axis=1), np.sum(sat_vel_m_s * n, axis=1)
    norm = np.hypot(ae, an)
    ce, cn = an / norm, -ae / norm  # horizontal, perpendicular to the track
    flip = np.where(ce < 0, -1.0, 1.0)  # make it point east
    across = np.arctan2(-(se * ce + sn * cn) * flip, su)
    inc = np.arccos(np.clip(su / rng, -1.0, 1.0))
    return inc, across, rng


@dataclass(frozen=True)
class BBox:
    """A lon/lat box in degrees (WGS84)."""

    lon_min: float
    lat_min: float
    lon_max: float
    lat_max: float

    def __post_init__(self) -> None:
        if not (-180 <= self.lon_min < self.lon_max <= 180):
            raise InputError(
                f"bad bbox longitudes {self.lon_min}..{self.lon_max}: need "
                "-180 <= LON_MIN < LON_MAX <= 180 (order: LON_MIN LAT_MIN LON_MAX LAT_MAX)"
            )
        if not (-90 <= self.lat_min < self.lat_max <= 90):
            raise InputError(
                f"bad bbox latitudes {self.lat_min}..{self.lat_max}: need "
                "-90 <= LAT_MIN < LAT_MAX <= 90 (order: LON_MIN LAT_MIN LON_MAX LAT_MAX)"
            )

    def expanded(self, margin_deg: float) -> BBox:
        """The box widened by ``margin_deg`` on every side (clipped to the globe)."""
        if margin_deg < 0:
            raise InputError(f"margin must be >= 0 degrees, got {margin_deg}")
        return BBox(
            max(self.lon_min - margin_deg, -180.0),
            max(self.lat_min - margin_deg, -90.0),
            min(self.lon_max + margin_deg, 180.0),
            min(self.lat_max + margin_deg, 90.0),
        )

    def contains(self, other: BBox, tol_deg: float = 1e-9) -> bool:
        """Whether ``other`` lies inside this box (within ``tol_deg``)."""
        return (other.lon_min >= self.lon_min - tol_deg and other.lat_min >= self.lat_min - tol_deg
                and other.lon_max <= self.lon_max + tol_deg
                and other.lat_max <= self.lat_max + tol_deg)

    def as_tuple(self) -> tuple[float, float, float, float]:
        return (self.lon_min, self.lat_min, self.lon_max, self.lat_max)


#: a point (lon, lat degrees, ellipsoidal h metres): the origin of a local ENU frame
Origin = tuple[float, float, float]


def _local_frame(origin: Origin) -> tuple[FloatArray, FloatArray]:
    """ECEF position (3,) of ``origin`` (lon, lat, h) and the ENU rotation there."""
    return np.array(geodetic_to_ecef(*origin)), enu_rotation(origin[0], origin[1])


def geodetic_to_enu(lon_deg: ArrayLike, lat_deg: ArrayLike, h_m: ArrayLike,
                    origin: Origin) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Geodetic points to East, North, Up metres in the local frame at ``origin`` (lon, lat, h)."""
    x, y, z = geodetic_to_ecef(lon_deg, lat_deg, h_m)
    o, r = _local_frame(origin)
    d = np.stack([x - o[0], y - o[1], z - o[2]])
    e, n, u = np.tensordot(r, d, axes=1)
    return e, n, u


def enu_to_geodetic(e_m: ArrayLike, n_m: ArrayLike, u_m: ArrayLike,
                    origin: Origin) -> tuple[FloatArray, FloatArray, FloatArray]:
    """East, North, Up metres in the local frame at ``origin`` (lon, lat, h) to geodetic."""
    o, r = _local_frame(origin)
    enu = np.stack(np.broadcast_arrays(*(np.asarray(v, dtype=np.float64)
                                         for v in (e_m, n_m, u_m))))
    dx, dy, dz = np.tensordot(r.T, enu, axes=1)
    return ecef_to_geodetic(o[0] + dx, o[1] + dy, o[2] + dz)
