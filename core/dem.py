"""Gridded surfaces: the one bilinear grid sampler, a lon/lat DEM value, and the one
march-then-bisect search for where lines of sight first meet a surface.

Used by the sensor models to intersect lines of sight with the terrain and by the scene
simulator to ray-cast its truth surface. Heights are WGS84 ellipsoidal metres (convert SRTM
with the geoid first). No I/O here.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.ndimage import map_coordinates

from core.errors import InputError
from core.geodesy import metres_per_degree

FloatArray = NDArray[np.float64]
HeightAbove = Callable[[FloatArray, NDArray[np.intp]], FloatArray]


def sample_bilinear(z: NDArray[np.floating], fi: ArrayLike, fj: ArrayLike) -> NDArray[np.float64]:
    """Bilinear value of grid ``z`` at fractional (row, col) indices; NaN outside the grid.

    The one bilinear sampler of the project (DEMs, geoid grids, rasters in the simulator).
    Indices must lie in ``[0, n - 1]`` (inclusive) to get a value; cells next to a NaN node
    give NaN (voids are not invented).
    """
    fi = np.asarray(fi, dtype=np.float64)
    fj = np.asarray(fj, dtype=np.float64)
    fi, fj = np.broadcast_arrays(fi, fj)
    nr, nc = np.shape(z)
    inside = (fi >= 0) & (fi <= nr - 1) & (fj >= 0) & (fj <= nc - 1)
    out = np.full(fi.shape, np.nan)
    if inside.any():
        out[inside] = map_coordinates(np.asarray(z, dtype=np.float64), [fi[inside], fj[inside]],
                                      order=1, mode="nearest", prefilter=False)
    return out


@dataclass(frozen=True, eq=False)
class GeoDEM:
    """Heights on a regular lon/lat grid; grid nodes are pixel centres.

    ``h_m[i, j]`` is the height at lon ``lon0_deg + j * dlon_deg`` and lat
    ``lat0_deg + i * dlat_deg``. For a north-up raster ``dlat_deg`` is negative
    and (lon0, lat0) is the centre of the top-left pixel. NaN marks voids.
    """

    h_m: NDArray[np.float64]
    lon0_deg: float
    lat0_deg: float
    dlon_deg: float
    dlat_deg: float

    def __post_init__(self) -> None:
        h = np.asarray(self.h_m, dtype=np.float64)
        if h.ndim != 2 or min(h.shape) < 2:
            raise InputError(f"a DEM must be a 2-D array of at least 2x2 cells, got {h.shape}")
        if self.dlon_deg == 0 or self.dlat_deg == 0:
            raise InputError("DEM spacing must be non-zero in both directions")
        h.setflags(write=False)
        object.__setattr__(self, "h_m", h)

    @classmethod
    def from_transform(cls, h_m: NDArray, transform: tuple[float, ...]) -> GeoDEM:
        """From a GDAL/affine geotransform (a, b, c, d, e, f) whose origin is the pixel corner.

        Accepts ``affine.Affine`` order (a, b, c, d, e, f) = (dlon, 0, lon_corner, 0, dlat, lat_corner).
        """
        a, b, c, d, e, f = (float(v) for v in tuple(transform)[:6])
        if b != 0 or d != 0:
            raise InputError("rotated DEM geotransforms are not supported; warp the DEM north-up")
        return cls(np.asarray(h_m), c + 0.5 * a, f + 0.5 * e, a, e)

    @property
    def shape(self) -> tuple[int, int]:
        return self.h_m.shape  # type: ignore[return-value]

    def bounds_deg(self) -> tuple[float, float, float, float]:
        """(lon_min, lat_min, lon_max, lat_max) of the node grid."""
        lons = (self.lon0_deg, self.lon0_deg + (self.shape[1] - 1) * self.dlon_deg)
        lats = (self.lat0_deg, self.lat0_deg + (self.shape[0] - 1) * self.dlat_deg)
        return min(lons), min(lats), max(lons), max(lats)

    def height_range_m(self) -> tuple[float, float]:
        return float(np.nanmin(self.h_m)), float(np.nanmax(self.h_m))

    def height_m(self, lon_deg: ArrayLike, lat_deg: ArrayLike) -> NDArray[np.float64]:
        """Bilinear height at (lon, lat); NaN outside the grid or next to a void."""
        fi = (np.asarray(lat_deg, dtype=np.float64) - self.lat0_deg) / self.dlat_deg
        fj = (np.asarray(lon_deg, dtype=np.float64) - self.lon0_deg) / self.dlon_deg
        return sample_bilinear(self.h_m, fi, fj)

    def cell_size_m(self) -> float:
        """Approximate smaller ground cell size in metres at the DEM centre."""
        lat_c = self.lat0_deg + 0.5 * (self.shape[0] - 1) * self.dlat_deg
        m_lon, m_lat = metres_per_degree(lat_c)
        return float(min(abs(self.dlon_deg) * m_lon, abs(self.dlat_deg) * m_lat))


@dataclass(frozen=True, eq=False)
class SurfaceGrid:
    """A north-up height grid in a projected frame (x east, y north, metres).

    ``z_m[i, j]`` is the height at ``x0_m + j * dx_m``, ``y0_m - i * dy_m``: (x0, y0) is the
    centre of the top-left cell. NaN marks voids.
    """

    z_m: NDArray[np.floating]
    x0_m: float
    y0_m: float
    dx_m: float
    dy_m: float

    def __post_init__(self) -> None:
        if np.ndim(self.z_m) != 2 or min(np.shape(self.z_m)) < 2:
            raise InputError(f"a surface grid needs at least 2x2 cells, got {np.shape(self.z_m)}")
        if self.dx_m <= 0 or self.dy_m <= 0:
            raise InputError("surface grid spacings must be positive")

    def sample(self, x_m: FloatArray, y_m: FloatArray) -> FloatArray:
        """Bilinear height; NaN outside the grid (or next to NaN cells)."""
        fj = (np.asarray(x_m) - self.x0_m) / self.dx_m
        fi = (self.y0_m - np.asarray(y_m)) / self.dy_m
        return sample_bilinear(self.z_m, fi, fj)


def march_levels(h_top_m: float, h_bottom_m: float, ground_move_per_m: float, cell_m: float,
                 min_step_m: float) -> FloatArray:
    """Decreasing heights from ``h_top_m`` to ``h_bottom_m`` for :func:`first_crossing`.

    The step keeps the ground point of a line of sight (moving ``ground_move_per_m`` metres
    horizontally per metre of height) within half a surface cell of ``cell_m``, but is never
    below ``min_step_m``; a vertical line of sight takes one step.
    """
    span = h_top_m - h_bottom_m
    if not span > 0:
        raise InputError(f"h_top {h_top_m} must be above h_bottom {h_bottom_m}")
    step = span if ground_move_per_m < 1e-9 else max(0.5 * cell_m / ground_move_per_m, min_step_m)
    return np.linspace(h_top_m, h_bottom_m, int(np.ceil(span / step)) + 1)


def first_crossing(height_above: HeightAbove, n: int, levels_m: FloatArray, *, tol_m: float,
                   max_bisections: int) -> FloatArray:
    """Height (m) where each of ``n`` lines of sight first meets a surface, coming down.

    ``height_above(h, idx)`` gives the heights above the surface (NaN off it) of the lines
    ``idx`` at heights ``h`` (arrays of ``idx``'s size). The lines are marched down the
    decreasing ``levels_m`` (:func:`march_levels`); the first step from above (> 0) to below
    (<= 0) brackets the crossing, which is bisected to ``tol_m`` (at most ``max_bisections``
    times). Keeping the first crossing keeps the visible surface: occlusions and cliffs are
    right. Lines that never cross give NaN.
    """
    hi = np.full(n, np.nan)  # last level above the surface
    lo = np.full(n, np.nan)  # first level below
    active = np.arange(n)
    prev = height_above(np.full(n, levels_m[0]), active)
    prev_h = levels_m[0]
    for lev in levels_m[1:]:
        if active.size == 0:
            break
        d = height_above(np.full(active.size, lev), active)
        hit = (prev > 0) & (d <= 0)
        hi[active[hit]] = prev_h
        lo[active[hit]] = lev
        keep = ~hit
        active, prev = active[keep], d[keep]
        prev_h = lev
    found = np.flatnonzero(np.isfinite(lo))
    a, b = lo[found], hi[found]
    for _ in range(max_bisections):
        if a.size == 0 or np.max(b - a) <= tol_m:
            break
        m = 0.5 * (a + b)
        up = height_above(m, found) > 0
        b = np.where(up, m, b)
        a = np.where(up, a, m)
    h = np.full(n, np.nan)
    h[found] = 0.5 * (a + b)
    return h
