"""Compiled (Numba) kernels of the simulator's ray casting: the grid's bilinear sample and the
march-then-bisect search of where each line of sight first meets the surface.

The arithmetic is that of the NumPy code it replaces, value for value and in the same order, so
the rendered bytes stay: the line of sight's quadratic (Lagrange) interpolation in height
(:meth:`core.simulation.raycast.Rays.at`), and the bilinear sample of
:func:`core.dem.sample_bilinear` as SciPy's ``map_coordinates(order=1, mode="nearest")``
computes it (weights ``1 - t`` and ``1 - (1 - t)``, the four taps added from 0.0 row by row,
the upper edge's second tap mirrored back inside, NaN outside ``[0, n - 1]``). The march keeps
:func:`core.dem.first_crossing`'s rule: the first level below the surface after one above it,
then every ray bisected the same number of times, until the widest bracket is within the
tolerance; it only skips the samples of the levels where the line is above every node around its track.

This module imports Numba: :mod:`core.simulation.raycast` imports it inside the functions that
call it. Kernels compile on their first call, are cached on disk, serial, and release the GIL
(the simulator's Dask threads run them side by side).
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]


@numba.njit(inline="always")
def _bilinear(z: F64, fi: float, fj: float) -> float:
    nr, nc = z.shape
    if not (fi >= 0.0 and fi <= nr - 1 and fj >= 0.0 and fj <= nc - 1):
        return np.nan
    i0 = np.int64(np.floor(fi))
    j0 = np.int64(np.floor(fj))
    ti = fi - np.floor(fi)
    tj = fj - np.floor(fj)
    wi0 = 1.0 - ti
    wi1 = 1.0 - wi0
    wj0 = 1.0 - tj
    wj1 = 1.0 - wj0
    i1 = i0 + 1 if i0 + 1 < nr else nr - 2  # SciPy's mirror of the tap beyond the edge
    j1 = j0 + 1 if j0 + 1 < nc else nc - 2
    t = 0.0
    t += z[i0, j0] * wi0 * wj0
    t += z[i0, j1] * wi0 * wj1
    t += z[i1, j0] * wi1 * wj0
    t += z[i1, j1] * wi1 * wj1
    return t


@numba.njit(cache=True, nogil=True, error_model="numpy")
def sample_grid(z: F64, x0: float, y0: float, dx: float, dy: float, x: F64, y: F64) -> F64:
    """Bilinear values of the grid ``z`` (node ``[i, j]`` at ``(x0 + j dx, y0 + i dy)``) at the
    points (x, y); NaN off the grid or next to a NaN node."""
    out = np.empty(x.size)
    for p in range(x.size):
        out[p] = _bilinear(z, (y[p] - y0) / dy, (x[p] - x0) / dx)
    return out


@numba.njit(inline="always")
def _ray_xy(rx: F64, ry: F64, p: int, h: float, hl: F64, den: F64) -> tuple[float, float]:
    l0 = (h - hl[1]) * (h - hl[2]) / den[0]
    l1 = (h - hl[0]) * (h - hl[2]) / den[1]
    l2 = (h - hl[0]) * (h - hl[1]) / den[2]
    return (l0 * rx[0, p] + l1 * rx[1, p] + l2 * rx[2, p],
            l0 * ry[0, p] + l1 * ry[1, p] + l2 * ry[2, p])


@numba.njit(inline="always")
def _above(rx: F64, ry: F64, p: int, h: float, hl: F64, den: F64, z: F64, x0: float, y0: float,
           dx: float, dy: float) -> float:
    x, y = _ray_xy(rx, ry, p, h, hl, den)
    return h - _bilinear(z, (y - y0) / dy, (x - x0) / dx)


TILE = 16  # cells per side of the tiles whose highest node lets the march skip a level
_SKIP_MARGIN_M = 1e-3  # far above the rounding of a bilinear sample (1e-12 m at 4000 m)


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _tile_tops(z: F64) -> F64:
    """Per tile of TILE x TILE nodes the highest node of the tile and of the tiles around it
    (every tap a sample inside the tile reads, the mirrored edge tap included, and a margin of
    a tile for a position computed approximately); NaN when that region holds a NaN node."""
    nr, nc = z.shape
    tr, tc = (nr + TILE - 1) // TILE, (nc + TILE - 1) // TILE
    own = np.empty((tr, tc))
    for a in range(tr):
        for b in range(tc):
            m = -np.inf
            for i in range(a * TILE, min((a + 1) * TILE, nr)):
                for j in range(b * TILE, min((b + 1) * TILE, nc)):
                    v = z[i, j]
                    m = np.nan if not np.isfinite(v) else max(m, v)
            own[a, b] = m
    top = np.empty((tr, tc))
    for a in range(tr):
        for b in range(tc):
            m = -np.inf
            for i in range(max(a - 1, 0), min(a + 2, tr)):
                for j in range(max(b - 1, 0), min(b + 2, tc)):
                    m = np.nan if np.isnan(own[i, j]) or np.isnan(m) else max(m, own[i, j])
            top[a, b] = m
    return top


@numba.njit(inline="always")
def _tile_of(rx: F64, ry: F64, p: int, h: float, hl: F64, inv: F64, nr: int, nc: int,
             x0: float, y0: float, inv_dx: float, inv_dy: float) -> tuple[int, int]:
    """The tile under the line of sight at height h, (-1, -1) within a cell of the grid's edge
    or off it. The position is computed with reciprocals: a few ulps off, well inside the tile
    of margin :func:`_tile_tops` keeps."""
    l0 = (h - hl[1]) * (h - hl[2]) * inv[0]
    l1 = (h - hl[0]) * (h - hl[2]) * inv[1]
    l2 = (h - hl[0]) * (h - hl[1]) * inv[2]
    fi = (l0 * ry[0, p] + l1 * ry[1, p] + l2 * ry[2, p] - y0) * inv_dy
    fj = (l0 * rx[0, p] + l1 * rx[1, p] + l2 * rx[2, p] - x0) * inv_dx
    if not (fi >= 1.0 and fi <= nr - 2 and fj >= 1.0 and fj <= nc - 2):
        return -1, -1
    return np.int64(fi) // TILE, np.int64(fj) // TILE


@numba.njit(inline="always")
def _first_level_to_sample(rx: F64, ry: F64, p: int, levels: F64, hl: F64, inv: F64, top: F64,
                           nr: int, nc: int, x0: float, y0: float, inv_dx: float,
                           inv_dy: float) -> int:
    """The first level the march must sample: every level above it is above the highest node
    of the tiles the line of sight crosses from the top level to the bottom one (its ground
    track is a straight segment to well under a tile), so there it is surely above the surface;
    0 when that cannot be known (a NaN node, the grid's edge)."""
    a0, b0 = _tile_of(rx, ry, p, levels[0], hl, inv, nr, nc, x0, y0, inv_dx, inv_dy)
    a1, b1 = _tile_of(rx, ry, p, levels[-1], hl, inv, nr, nc, x0, y0, inv_dx, inv_dy)
    if a0 < 0 or a1 < 0:
        return 0
    t = -np.inf
    for a in range(min(a0, a1), max(a0, a1) + 1):
        for b in range(min(b0, b1), max(b0, b1) + 1):
            t = max(t, top[a, b])
    if not np.isfinite(t):
        return 0
    thr = t + _SKIP_MARGIN_M
    k = 0
    while k < levels.size and levels[k] > thr:
        k += 1
    return k


@numba.njit(cache=True, nogil=True, error_model="numpy")
def ray_first_heights(rx: F64, ry: F64, hl: F64, z: F64, x0: float, y0: float, dx: float,
                      dy: float, levels: F64, tol_m: float, max_bisections: int) -> F64:
    """Height where each line of sight (ground positions ``rx``, ``ry`` (3, n) at the heights
    ``hl``) first meets the surface grid coming down the decreasing ``levels``; NaN where it
    never does. The levels where the line is above the highest node around its ground track
    are known to be above the surface without sampling them (a bilinear sample never exceeds
    its taps): the march samples from the first level below that."""
    n = rx.shape[1]
    nr, nc = z.shape
    top = _tile_tops(z)
    den = np.empty(3)
    den[0] = (hl[0] - hl[1]) * (hl[0] - hl[2])
    den[1] = (hl[1] - hl[0]) * (hl[1] - hl[2])
    den[2] = (hl[2] - hl[0]) * (hl[2] - hl[1])
    inv = 1.0 / den
    inv_dx, inv_dy = 1.0 / dx, 1.0 / dy
    lo = np.full(n, np.nan)
    hi = np.full(n, np.nan)
    for p in range(n):
        k0 = _first_level_to_sample(rx, ry, p, levels, hl, inv, top, nr, nc, x0, y0, inv_dx,
                                    inv_dy)
        prev = 1.0 if k0 > 0 else np.nan  # level k0 - 1 is surely above the surface
        for k in range(k0, levels.size):
            d = _above(rx, ry, p, levels[k], hl, den, z, x0, y0, dx, dy)
            if k > 0 and prev > 0 and d <= 0:
                hi[p] = levels[k - 1]
                lo[p] = levels[k]
                break
            prev = d
    found = np.flatnonzero(np.isfinite(lo))
    a = lo[found]
    b = hi[found]
    for _ in range(max_bisections):
        if a.size == 0:
            break
        widest = b[0] - a[0]
        for q in range(1, a.size):
            widest = max(widest, b[q] - a[q])
        if widest <= tol_m:
            break
        for q in range(a.size):
            m = 0.5 * (a[q] + b[q])
            if _above(rx, ry, found[q], m, hl, den, z, x0, y0, dx, dy) > 0:
                b[q] = m
            else:
                a[q] = m
    h = np.full(n, np.nan)
    for q in range(found.size):
        h[found[q]] = 0.5 * (a[q] + b[q])
    return h


@numba.njit(cache=True, nogil=True, error_model="numpy")
def ray_xy(rx: F64, ry: F64, hl: F64, h: F64) -> tuple[F64, F64]:
    """Ground (x, y) of each line of sight at its height ``h``."""
    den = np.empty(3)
    den[0] = (hl[0] - hl[1]) * (hl[0] - hl[2])
    den[1] = (hl[1] - hl[0]) * (hl[1] - hl[2])
    den[2] = (hl[2] - hl[0]) * (hl[2] - hl[1])
    x = np.empty(h.size)
    y = np.empty(h.size)
    for p in range(h.size):
        x[p], y[p] = _ray_xy(rx, ry, p, h[p], hl, den)
    return x, y
