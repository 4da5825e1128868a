"""Points on a raster grid: where they fall, which windows hold them, the cell they are in.

A raster's GDAL/affine transform ``(a, b, c, d, e, f)`` (pixel-corner origin, rotation terms
allowed) gives each point fractional node indices ``(fi, fj)`` (row, col; pixel centres at
integers), which :func:`core.dem.sample_bilinear` interpolates and :func:`sample_nearest` reads
as classes. :func:`window_groups` splits scattered points into groups whose windows stay small,
so a task reads a raster window by window in bounded memory. No I/O here.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.errors import InputError

FloatArray = NDArray[np.float64]


def affine_nodes(transform: Sequence[float], x: ArrayLike,
                 y: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Fractional grid-node indices ``(fi, fj)`` (row, col; pixel centres at integers) of
    points ``(x, y)`` in a raster with the GDAL/affine transform ``(a, b, c, d, e, f)``
    (pixel corner origin; rotation terms allowed)."""
    a, b, c, d, e, f = (float(v) for v in tuple(transform)[:6])
    det = a * e - b * d
    if det == 0:
        raise InputError("raster transform is singular (zero pixel size); fix its "
                         "georeferencing")
    dx = np.asarray(x, dtype=np.float64) - c
    dy = np.asarray(y, dtype=np.float64) - f
    col = (e * dx - b * dy) / det
    row = (-d * dx + a * dy) / det
    return row - 0.5, col - 0.5


@dataclass(frozen=True, eq=False)
class WindowGroup:
    """Points ``index`` (into the chunk) whose bilinear neighbours lie in rows
    ``[row0, row1)`` and columns ``[col0, col1)`` of the grid."""

    index: NDArray[np.intp]
    row0: int
    row1: int
    col0: int
    col1: int


def inside_grid(fi: FloatArray, fj: FloatArray, shape: tuple[int, int],
                nearest: bool = False) -> NDArray[np.bool_]:
    """Points with a value on the grid: node indices within ``[0, n - 1]`` (bilinear), or
    within the cells, ``[-0.5, n - 0.5)`` (``nearest``)."""
    nr, nc = shape
    if nearest:
        return (fi >= -0.5) & (fi < nr - 0.5) & (fj >= -0.5) & (fj < nc - 0.5)
    return (fi >= 0) & (fi <= nr - 1) & (fj >= 0) & (fj <= nc - 1)


def window_groups(fi: FloatArray, fj: FloatArray, shape: tuple[int, int],
                  tile_cells: int = 2048, nearest: bool = False) -> list[WindowGroup]:
    """Split the points on a grid (:func:`inside_grid`) into groups whose windows span at
    most about ``tile_cells`` x ``tile_cells`` cells, so that reading a window keeps memory
    bounded whatever the spread of the points. A window holds every node bilinear
    interpolation needs, or with ``nearest`` the cell of each point. Points off the grid are
    left out."""
    if tile_cells < 2:
        raise InputError(f"tile_cells must be >= 2, got {tile_cells}")
    nr, nc = shape
    idx = np.flatnonzero(inside_grid(fi, fj, shape, nearest))
    if idx.size == 0:
        return []
    shift, extra = (0.5, 1) if nearest else (0.0, 2)
    r = np.floor(fi[idx] + shift).astype(np.int64)
    c = np.floor(fj[idx] + shift).astype(np.int64)

    def group(sel: NDArray[np.intp], rr: NDArray[np.int64], cc: NDArray[np.int64]) -> WindowGroup:
        return WindowGroup(sel, int(rr.min()), int(min(rr.max() + extra, nr)), int(cc.min()),
                           int(min(cc.max() + extra, nc)))

    if r.max() - r.min() < tile_cells and c.max() - c.min() < tile_cells:
        return [group(idx, r, c)]
    ntc = nc // tile_cells + 1
    tile = (r // tile_cells) * ntc + c // tile_cells
    order = np.argsort(tile, kind="stable")
    _, start = np.unique(tile[order], return_index=True)
    return [group(idx[part], r[part], c[part]) for part in np.split(order, start[1:])]


def sample_nearest(grid: NDArray, fi: ArrayLike, fj: ArrayLike, fill: int) -> NDArray:
    """Value of the cell containing each point (node indices, pixel centres at integers);
    ``fill`` outside the grid. For class rasters (land cover)."""
    fi = np.asarray(fi, dtype=np.float64)
    fj = np.asarray(fj, dtype=np.float64)
    nr, nc = np.shape(grid)
    i = np.floor(fi + 0.5)
    j = np.floor(fj + 0.5)
    ok = (i >= 0) & (i < nr) & (j >= 0) & (j < nc)
    out = np.full(fi.shape, fill, dtype=np.asarray(grid).dtype)
    out[ok] = np.asarray(grid)[i[ok].astype(np.intp), j[ok].astype(np.intp)]
    return out
