"""Gridded surfaces: the one bilinear grid sampler, the two height grids (lon/lat
:class:`GeoDEM`, projected :class:`SurfaceGrid`) with one convention (:class:`RegularGrid`),
and the one march-then-bisect search for where lines of sight first meet a surface.

Used by the sensor models to intersect lines of sight with the terrain and by the scene
simulator to ray-cast its truth surface. Heights are WGS84 ellipsoidal metres (convert SRTM
with the geoid first). No I/O here.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, fields, replace
from typing import ClassVar, Self

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


class RegularGrid:
    """What the project's two height grids share, with ONE convention (GDAL's, the one
    rasterio's transforms give): ``values[i, j]`` is the value at the node
    ``(x0 + j dx, y0 + i dy)``; nodes are cell centres, ``(x0, y0)`` the centre of the top-left
    cell, ``dx``/``dy`` signed steps: a north-up raster has ``dx > 0`` and ``dy < 0`` (its
    transform's ``a`` and ``e``). NaN marks voids.

    :class:`GeoDEM` holds lon/lat degrees (``geographic``), :class:`SurfaceGrid` projected
    metres, each under its own field names: the values first, then x0, y0, dx, dy (read as
    :attr:`values` and :attr:`axes`). Both are made from a raster's affine by
    :meth:`from_transform`.
    """

    geographic: ClassVar[bool] = False
    what: ClassVar[str] = "surface grid"  # for messages

    def __post_init__(self) -> None:
        _, _, dx, dy = self.axes
        if np.ndim(self.values) != 2 or min(np.shape(self.values)) < 2:
            raise InputError(f"a {self.what} must be a 2-D array of at least 2x2 cells, got "
                             f"{np.shape(self.values)}")
        if dx == 0 or dy == 0:
            raise InputError(f"{self.what} spacing must be non-zero in both directions")

    @property
    def values(self) -> NDArray[np.floating]:
        return getattr(self, fields(self)[0].name)  # type: ignore[arg-type]

    @property
    def axes(self) -> tuple[float, float, float, float]:
        """``(x0, y0, dx, dy)``: the top-left node and the signed steps."""
        return tuple(getattr(self, f.name) for f in fields(self)[1:5])  # type: ignore

    def with_values(self, values: NDArray) -> Self:
        """The same grid holding other values (same shape)."""
        if np.shape(values) != self.shape:
            raise InputError(f"values of shape {np.shape(values)} for a grid of {self.shape}")
        return replace(self, **{fields(self)[0].name: values})  # type: ignore[type-var]

    @classmethod
    def from_transform(cls, values: NDArray, transform: Sequence[float]) -> Self:
        """From a GDAL/affine geotransform in ``affine.Affine`` order ``(a, b, c, d, e, f)`` =
        ``(dx, 0, x_corner, 0, dy, y_corner)``, whose origin is the top-left pixel's corner."""
        a, b, c, d, e, f = (float(v) for v in tuple(transform)[:6])
        if b != 0 or d != 0:
            raise InputError("rotated DEM geotransforms are not supported; warp the DEM north-up")
        return cls(np.asarray(values), c + 0.5 * a, f + 0.5 * e, a, e)  # type: ignore[call-arg]

    @property
    def shape(self) -> tuple[int, int]:
        return np.shape(self.values)  # type: ignore[return-value]

    def indices(self, x: ArrayLike, y: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Fractional (row, col) indices of points (x, y in the grid's units)."""
        x0, y0, dx, dy = self.axes
        return ((np.asarray(y, dtype=np.float64) - y0) / dy,
                (np.asarray(x, dtype=np.float64) - x0) / dx)

    def sample(self, x: ArrayLike, y: ArrayLike) -> FloatArray:
        """Bilinear value at (x, y); NaN outside the grid or next to a void."""
        fi, fj = self.indices(x, y)
        return sample_bilinear(self.values, fi, fj)

    def nodes(self) -> tuple[FloatArray, FloatArray]:
        """(x, y) of every node, arrays of the grid's shape."""
        x0, y0, dx, dy = self.axes
        i, j = np.mgrid[0:self.shape[0], 0:self.shape[1]]
        return x0 + j * dx, y0 + i * dy

    def bounds(self) -> tuple[float, float, float, float]:
        """(x_min, y_min, x_max, y_max) of the nodes."""
        x0, y0, dx, dy = self.axes
        xs = (x0, x0 + (self.shape[1] - 1) * dx)
        ys = (y0, y0 + (self.shape[0] - 1) * dy)
        return min(xs), min(ys), max(xs), max(ys)


@dataclass(frozen=True, eq=False)
class GeoDEM(RegularGrid):
    """Heights on a regular lon/lat grid (:class:`RegularGrid`'s convention): ``h_m[i, j]`` at
    lon ``lon0_deg + j * dlon_deg``, lat ``lat0_deg + i * dlat_deg``; north-up: ``dlat_deg``
    negative and (lon0, lat0) the centre of the top-left pixel. NaN marks voids.
    """

    h_m: NDArray[np.float64]
    lon0_deg: float
    lat0_deg: float
    dlon_deg: float
    dlat_deg: float

    geographic: ClassVar[bool] = True
    what: ClassVar[str] = "DEM"

    def __post_init__(self) -> None:
        h = np.asarray(self.h_m, dtype=np.float64)
        object.__setattr__(self, "h_m", h)
        super().__post_init__()
        h.setflags(write=False)

    def bounds_deg(self) -> tuple[float, float, float, float]:
        """(lon_min, lat_min, lon_max, lat_max) of the node grid."""
        return self.bounds()

    def height_range_m(self) -> tuple[float, float]:
        return float(np.nanmin(self.h_m)), float(np.nanmax(self.h_m))

    def height_m(self, lon_deg: ArrayLike, lat_deg: ArrayLike) -> NDArray[np.float64]:
        """Bilinear height at (lon, lat); NaN outside the grid or next to a void."""
        return self.sample(lon_deg, lat_deg)

    def cell_size_m(self) -> float:
        """The smaller ground cell size in metres at the DEM centre."""
        lat_c = self.lat0_deg + 0.5 * (self.shape[0] - 1) * self.dlat_deg
        m_lon, m_lat = metres_per_degree(lat_c)
        return float(min(abs(self.dlon_deg) * m_lon, abs(self.dlat_deg) * m_lat))


@dataclass(frozen=True, eq=False)
class SurfaceGrid(RegularGrid):
    """Heights on a grid in a projected frame (x east, y north, metres), with
    :class:`RegularGrid`'s convention: ``z_m[i, j]`` at ``(x0_m + j * dx_m, y0_m + i * dy_m)``,
    (x0, y0) the centre of the top-left cell; north-up: ``dy_m`` negative. NaN marks voids.
    """

    z_m: NDArray[np.floating]
    x0_m: float
    y0_m: float
    dx_m: float
    dy_m: float


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
