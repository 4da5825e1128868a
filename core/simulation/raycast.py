"""Lines of sight against a gridded surface: the first (visible) intersection per pixel.

The surface is a north-up grid in a local projected frame (x east, y north, metres),
``z[i, j]`` at ``x0 + j*dx``, ``y0 - i*dy``. Each line of sight is given by its ground
position at three heights (low, middle, high) and interpolated quadratically in h, which
represents a straight ECEF ray in a projected frame to well under a millimetre over a
few kilometres of height. Marching from the top keeps the first crossing, so
occlusions (buildings, steep slopes away from the sensor) are right.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from core.dem import sample_bilinear
from core.errors import InputError

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class SurfaceGrid:
    """A north-up height grid; (x0, y0) is the centre of the top-left cell."""

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


@dataclass(frozen=True, eq=False)
class Rays:
    """Lines of sight: ground (x, y) at heights ``h_levels_m`` (3,), arrays (3, n)."""

    x_m: FloatArray
    y_m: FloatArray
    h_levels_m: tuple[float, float, float]

    def at(self, h: FloatArray, idx: NDArray[np.intp] | slice = slice(None)) -> tuple[FloatArray, FloatArray]:
        """Quadratic (Lagrange) interpolation of the ray's ground position at height ``h``."""
        h0, h1, h2 = self.h_levels_m
        l0 = (h - h1) * (h - h2) / ((h0 - h1) * (h0 - h2))
        l1 = (h - h0) * (h - h2) / ((h1 - h0) * (h1 - h2))
        l2 = (h - h0) * (h - h1) / ((h2 - h0) * (h2 - h1))
        x = l0 * self.x_m[0, idx] + l1 * self.x_m[1, idx] + l2 * self.x_m[2, idx]
        y = l0 * self.y_m[0, idx] + l1 * self.y_m[1, idx] + l2 * self.y_m[2, idx]
        return x, y


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
    then refined by bisection to ``tol_m``. Rays that never meet it give NaN.
    """
    if not h_top_m > h_bottom_m:
        raise InputError(f"h_top {h_top_m} must be above h_bottom {h_bottom_m}")
    n = rays.x_m.shape[1]
    xa, ya = rays.at(np.full(n, h_top_m))
    xb, yb = rays.at(np.full(n, h_bottom_m))
    horiz = np.nanmax(np.hypot(xa - xb, ya - yb)) / (h_top_m - h_bottom_m) if n else 0.0
    cell = min(surface.dx_m, surface.dy_m)
    step = (h_top_m - h_bottom_m) if horiz < 1e-9 else max(0.5 * cell / horiz, 1e-3)
    n_levels = int(np.ceil((h_top_m - h_bottom_m) / step)) + 1
    levels = np.linspace(h_top_m, h_bottom_m, n_levels)

    hi = np.full(n, np.nan)  # above the surface
    lo = np.full(n, np.nan)  # below
    active = np.arange(n)
    prev = levels[0] - surface.sample(xa, ya)
    prev_h = levels[0]
    for lev in levels[1:]:
        if active.size == 0:
            break
        x, y = rays.at(np.full(active.size, lev), active)
        d = lev - surface.sample(x, y)
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
        x, y = rays.at(m, found)
        above = m - surface.sample(x, y) > 0
        b = np.where(above, m, b)
        a = np.where(above, a, m)
    h = np.full(n, np.nan)
    h[found] = 0.5 * (a + b)
    x, y = rays.at(h)
    return x, y, h
