"""Lines of sight against a gridded surface: the first (visible) intersection per pixel.

The surface is a north-up grid in a local projected frame (x east, y north, metres),
``z[i, j]`` at ``x0 + j*dx``, ``y0 - i*dy``. Each line of sight is given by its ground
position at three heights (low, middle, high) and interpolated quadratically in h, which
represents a straight ECEF ray in a projected frame to well under a millimetre over a
few kilometres of height. Marching from the top keeps the first crossing
(:func:`core.dem.first_crossing`), so occlusions (buildings, steep slopes away from the sensor)
are right.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from core.dem import SurfaceGrid, march_levels
from core.errors import InputError
from core.geodesy import intersect_ellipsoid
from core.sensors.base import SensorModel

FloatArray = NDArray[np.float64]
ToXY = Callable[[FloatArray, FloatArray], tuple[FloatArray, FloatArray]]
Bounds = tuple[float, float, float, float]  # x_min, y_min, x_max, y_max (metres)
SurfaceReader = Callable[[Bounds], SurfaceGrid | None]

COL_STEP = 8  # lines of sight are localised every COL_STEP columns and interpolated


@dataclass(frozen=True, eq=False)
class Rays:
    """Lines of sight: ground (x, y) at heights ``h_levels_m`` (3,), arrays (3, n)."""

    x_m: FloatArray
    y_m: FloatArray
    h_levels_m: tuple[float, float, float]

    def at(self, h: FloatArray,
           idx: NDArray[np.intp] | slice = slice(None)) -> tuple[FloatArray, FloatArray]:
        """Quadratic (Lagrange) interpolation of the ray's ground position at height ``h``."""
        h0, h1, h2 = self.h_levels_m
        l0 = (h - h1) * (h - h2) / ((h0 - h1) * (h0 - h2))
        l1 = (h - h0) * (h - h2) / ((h1 - h0) * (h1 - h2))
        l2 = (h - h0) * (h - h1) / ((h2 - h0) * (h2 - h1))
        x = l0 * self.x_m[0, idx] + l1 * self.x_m[1, idx] + l2 * self.x_m[2, idx]
        y = l0 * self.y_m[0, idx] + l1 * self.y_m[1, idx] + l2 * self.y_m[2, idx]
        return x, y

    def ground_bounds(self) -> Bounds:
        """(x_min, y_min, x_max, y_max) of the rays' ground positions at the three heights."""
        return (float(np.nanmin(self.x_m)), float(np.nanmin(self.y_m)),
                float(np.nanmax(self.x_m)), float(np.nanmax(self.y_m)))


def ray_levels(surface_range_m: tuple[float, float]) -> tuple[float, float, float]:
    """Heights at which lines of sight are localised: just below, across and above a surface."""
    lo, hi = surface_range_m
    return lo - 5.0, 0.5 * (lo + hi), hi + 5.0


def image_rays(model: SensorModel, rows: NDArray, cols: NDArray, levels: tuple[float, float, float],
               to_xy: ToXY, col_step: int = COL_STEP) -> Rays:
    """Lines of sight of the pixels ``rows x cols`` (a block, row-major) in the frame of ``to_xy``.

    The model localises every ``col_step``-th column (and the last) at the three ``levels``;
    the columns between are interpolated linearly along each row (a pushbroom line is
    straight to well under a millimetre over 8 pixels).
    """
    sub = np.unique(np.concatenate([cols[::col_step], cols[-1:]])).astype(np.float64)
    rr, cc = np.meshgrid(rows.astype(np.float64), sub, indexing="ij")
    xs, ys = [], []
    sight = getattr(model, "lines_of_sight", None)  # a pushbroom's: the platform once per line
    if sight is not None:
        t_line, line = np.unique(model.line_time_s(rr.ravel()), return_inverse=True)
        pos, u = sight(cc.ravel(), t_line, line)
        ground = [intersect_ellipsoid(pos, u, np.full(cc.size, float(h))) for h in levels]
    else:
        ground = [model.localize(cc.ravel(), rr.ravel(), np.full(cc.size, h)) for h in levels]
    for lon, lat in ground:
        x, y = to_xy(lon, lat)
        x = x.reshape(rr.shape)
        y = y.reshape(rr.shape)
        fx = np.stack([np.interp(cols, sub, xr) for xr in x])
        fy = np.stack([np.interp(cols, sub, yr) for yr in y])
        xs.append(fx.ravel())
        ys.append(fy.ravel())
    return Rays(np.stack(xs), np.stack(ys), levels)


def first_hit(
    rays: Rays,
    surface: SurfaceGrid,
    h_top_m: float,
    h_bottom_m: float,
    *,
    tol_m: float = 1e-3,
    max_bisections: int = 40,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(x, y, h) where each ray first meets the surface coming down from ``h_top_m``.

    The march step keeps the horizontal move under half a grid cell; the crossing is
    then refined by bisection to ``tol_m`` (:func:`core.dem.first_crossing`'s rule, compiled in
    :func:`core.simulation.raycast_kernels.ray_first_heights`). Rays that never meet it give
    NaN.
    """
    from core.simulation import raycast_kernels as K

    if not h_top_m > h_bottom_m:
        raise InputError(f"h_top {h_top_m} must be above h_bottom {h_bottom_m}")
    n = rays.x_m.shape[1]
    xa, ya = rays.at(np.full(n, h_top_m))
    xb, yb = rays.at(np.full(n, h_bottom_m))
    move = np.nanmax(np.hypot(xa - xb, ya - yb)) / (h_top_m - h_bottom_m) if n else 0.0
    levels = march_levels(h_top_m, h_bottom_m, move, min(abs(surface.dx_m), abs(surface.dy_m)),
                          min_step_m=1e-3)
    x0, y0, dx, dy = surface.axes
    hl = np.array(rays.h_levels_m, dtype=np.float64)
    rx, ry = np.ascontiguousarray(rays.x_m), np.ascontiguousarray(rays.y_m)
    h = K.ray_first_heights(rx, ry, hl, np.asarray(surface.values, dtype=np.float64),
                            float(x0), float(y0), float(dx), float(dy), levels, float(tol_m),
                            int(max_bisections))
    x, y = K.ray_xy(rx, ry, hl, h)
    return x, y, h


def cast_on_surface(rays: Rays, read_surface: SurfaceReader,
                    tol_m: float) -> tuple[FloatArray, FloatArray] | None:
    """First hit (x, y) of each ray on the surface that ``read_surface`` gives for the rays'
    ground bounds, searched from just above its highest cell to just below its lowest; None
    when it holds no height there."""
    surface = read_surface(rays.ground_bounds())
    if surface is None or not np.isfinite(surface.z_m).any():
        return None
    top = float(np.nanmax(surface.z_m)) + 0.5
    bottom = float(np.nanmin(surface.z_m)) - 0.5
    x, y, _ = first_hit(rays, surface, top, bottom, tol_m=tol_m)
    return x, y
