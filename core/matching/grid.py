"""Ground points into a DEM grid: median per cell, small holes filled, the edge cells left out, a
mask of what is not.

The grid is north-up in a projected frame (the local UTM zone): cell ``[i, j]`` covers
``x0 + j res .. x0 + (j + 1) res`` and ``y0 - (i + 1) res .. y0 - i res`` (``x0``, ``y0`` its
north-west corner). Each cell's height is the median of the matched points falling in it.
Unmatched pixels also land on the ground (at a disparity filled from their neighbours), with
their :class:`~core.matching.dense.PixelStatus`, so a cell without height says why:

- ``MASK_VALID`` (0) a height (measured, or a hole smaller than ``max_hole_cells`` cells
  filled with the mean of the heights around it);
- ``MASK_MISMATCH`` (1) the pixels there were seen by both images but not matched, or the
  cell was one of a tiny isolated group of heights (a blunder);
- ``MASK_OCCLUDED`` (2) occluded in one image, outside the pair, or no pixel at all, or on the
  DEM's edge (next to a cell outside the pair: :func:`without_rim`).

No I/O here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

from core.errors import InputError
from core.matching.dense import PixelStatus
from core.robust import nmad

FloatArray = NDArray[np.float64]
MASK_VALID, MASK_MISMATCH, MASK_OCCLUDED = 0, 1, 2


@dataclass(frozen=True)
class GridSpec:
    """A north-up grid: north-west corner ``(x0_m, y0_m)``, square cells of ``res_m``."""

    x0_m: float
    y0_m: float
    res_m: float
    n_cols: int
    n_rows: int

    def __post_init__(self) -> None:
        if not self.res_m > 0 or self.n_cols < 1 or self.n_rows < 1:
            raise InputError(f"a grid needs res_m > 0 and at least one cell, got {self}")

    @classmethod
    def covering(cls, bounds_m: tuple[float, float, float, float], res_m: float) -> GridSpec:
        """The grid of cells aligned on multiples of ``res_m`` covering (x_min, y_min, x_max,
        y_max)."""
        if not res_m > 0:
            raise InputError(f"the resolution must be > 0 m, got {res_m}")
        xmin, ymin, xmax, ymax = bounds_m
        x0 = math.floor(xmin / res_m) * res_m
        y0 = math.ceil(ymax / res_m) * res_m
        n_cols = max(1, math.ceil((xmax - x0) / res_m))
        n_rows = max(1, math.ceil((y0 - ymin) / res_m))
        return cls(float(x0), float(y0), float(res_m), n_cols, n_rows)

    @property
    def shape(self) -> tuple[int, int]:
        return self.n_rows, self.n_cols

    def geotransform(self) -> tuple[float, float, float, float, float, float]:
        """GDAL/affine ``(a, b, c, d, e, f)`` of the grid (corner-based)."""
        return (self.res_m, 0.0, self.x0_m, 0.0, -self.res_m, self.y0_m)

    def bounds_of(self, row0: int, row1: int, col0: int, col1: int
                  ) -> tuple[float, float, float, float]:
        """(x_min, y_min, x_max, y_max) of the cells ``[row0:row1, col0:col1]``."""
        return (self.x0_m + col0 * self.res_m, self.y0_m - row1 * self.res_m,
                self.x0_m + col1 * self.res_m, self.y0_m - row0 * self.res_m)


def median_per_cell(x_m: ArrayLike, y_m: ArrayLike, h_m: ArrayLike, x0_m: float, y0_m: float,
                    res_m: float, shape: tuple[int, int]) -> NDArray[np.float32]:
    """Median height of the finite points in each cell of the grid (NaN where none)."""
    return _median(*_cells(x_m, y_m, x0_m, y0_m, res_m, shape), h_m, shape)


def _median(ix: NDArray[np.int64], iy: NDArray[np.int64], inside: NDArray[np.bool_],
            h_m: ArrayLike, shape: tuple[int, int]) -> NDArray[np.float32]:
    """:func:`median_per_cell` of points already in cells (:func:`_cells`)."""
    h = np.asarray(h_m).ravel()
    if h.dtype != np.float32:
        h = h.astype(np.float64)
    keep = inside & np.isfinite(h)
    cell = iy[keep] * shape[1] + ix[keep]
    out = np.full(shape[0] * shape[1], np.nan, dtype=np.float32)
    if cell.size:
        cs, hs = _sorted_by_cell(cell, h[keep])
        start = np.flatnonzero(np.r_[True, cs[1:] != cs[:-1]])
        count = np.diff(np.r_[start, cs.size])
        out[cs[start]] = 0.5 * (hs[start + (count - 1) // 2] + hs[start + count // 2])
    return out.reshape(shape)


def _sorted_by_cell(cell: NDArray[np.int64], h: NDArray) -> tuple[NDArray[np.int64], FloatArray]:
    """The points ordered by cell, then height: (cells, heights as float64). float32 heights
    (the point files') are sorted as one 64-bit key, the cell above the height's bits made
    monotonic (a quarter of the time of ``np.lexsort``); others by ``np.lexsort``."""
    if h.dtype != np.float32:
        order = np.lexsort((h, cell))
        return cell[order], h[order]
    bits = h.view(np.uint32)
    neg = bits >> np.uint32(31) == 1
    ordered = np.where(neg, ~bits, bits | np.uint32(0x80000000))
    key = (cell.astype(np.uint64) << np.uint64(32)) | ordered.astype(np.uint64)
    key.sort()
    low = (key & np.uint64(0xFFFFFFFF)).astype(np.uint32)
    back = np.where(low >> np.uint32(31) == 1, low & np.uint32(0x7FFFFFFF), ~low)
    return (key >> np.uint64(32)).astype(np.int64), back.view(np.float32).astype(np.float64)


def _cells(x_m: ArrayLike, y_m: ArrayLike, x0_m: float, y0_m: float, res_m: float,
           shape: tuple[int, int]) -> tuple[NDArray[np.int64], NDArray[np.int64], NDArray]:
    x = np.asarray(x_m, dtype=np.float64).ravel()
    y = np.asarray(y_m, dtype=np.float64).ravel()
    with np.errstate(invalid="ignore"):
        fx = np.floor((x - x0_m) / res_m)
        fy = np.floor((y0_m - y) / res_m)
    inside = (fx >= 0) & (fx < shape[1]) & (fy >= 0) & (fy < shape[0])
    return (np.where(inside, fx, 0).astype(np.int64), np.where(inside, fy, 0).astype(np.int64),
            inside)


def fill_small_holes(z: NDArray[np.float32], max_cells: int
                     ) -> tuple[NDArray[np.float32], NDArray[np.bool_]]:
    """Fill NaN regions (4-connected) of fewer than ``max_cells`` cells that do not touch the
    array's border with the mean of the valid cells around them; returns the new grid and the
    cells filled. (Callers pad the grid by ``max_cells`` so that border holes are judged on
    the padded array.)"""
    holes = ~np.isfinite(z)
    out = z.copy()
    if max_cells <= 1 or not holes.any() or holes.all():
        return out, np.zeros(z.shape, dtype=bool)
    labels, n = ndimage.label(holes)
    sizes = np.bincount(labels.ravel(), minlength=n + 1)
    border = np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]]))
    small = sizes < max_cells
    small[0] = False
    small[border] = False
    if not small.any():
        return out, np.zeros(z.shape, dtype=bool)
    small_labels = np.where(small[labels], labels, 0)
    near = ndimage.maximum_filter(small_labels, size=3)
    ring = (near > 0) & ~holes
    total = np.bincount(near[ring], weights=z[ring].astype(np.float64), minlength=n + 1)
    count = np.bincount(near[ring], minlength=n + 1)
    filled = small_labels > 0
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = total / count
    out[filled] = mean[small_labels[filled]].astype(np.float32)
    filled &= np.isfinite(out)
    return out, filled


@dataclass(frozen=True, eq=False)
class DemCells:
    """A gridded block: heights ``z_m`` (float32, NaN = no data), ``mask`` (uint8, see the
    module docstring) and ``overlap`` (cells that received a pixel seen by both images, or a
    height: the cells the pair could have measured)."""

    z_m: NDArray[np.float32]
    mask: NDArray[np.uint8]
    overlap: NDArray[np.bool_]


def remove_small_islands(z: NDArray[np.float32], min_cells: int
                         ) -> tuple[NDArray[np.float32], NDArray[np.bool_]]:
    """Blank the groups of valid cells (8-connected) smaller than ``min_cells`` that do not
    touch the array's border: isolated blunders, whose far-off heights also put them far
    from where they belong. Returns the grid and the cells blanked."""
    valid = np.isfinite(z)
    out = z.copy()
    if min_cells <= 1 or not valid.any():
        return out, np.zeros(z.shape, dtype=bool)
    labels, n = ndimage.label(valid, structure=np.ones((3, 3), dtype=bool))
    sizes = np.bincount(labels.ravel(), minlength=n + 1)
    border = np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]]))
    small = sizes < min_cells
    small[0] = False
    small[border] = False
    gone = small[labels]
    out[gone] = np.nan
    return out, gone


def grid_dem(x_m: ArrayLike, y_m: ArrayLike, h_m: ArrayLike, status: ArrayLike, x0_m: float,
             y0_m: float, res_m: float, shape: tuple[int, int], max_hole_cells: int = 5,
             min_island_cells: int = 5, z_m: NDArray[np.float32] | None = None) -> DemCells:
    """Grid ground points: ``h_m`` finite where matched, ``status`` a
    :class:`~core.matching.dense.PixelStatus` per point; ``(x0_m, y0_m)`` the north-west
    corner of the block. Each cell's height is the median of its matched points, or ``z_m``
    when given (the cells' heights made otherwise: a fusion of several pairs,
    :mod:`core.matching.fusion`). Groups of fewer than ``min_island_cells`` valid cells are
    blanked (mismatch) before holes of fewer than ``max_hole_cells`` are filled, and the cells
    next to those outside the pair are blanked (:func:`without_rim`)."""
    if not res_m > 0 or min(shape) < 1:
        raise InputError(f"grid_dem needs res_m > 0 and a non-empty shape, got {res_m}, {shape}")
    ix, iy, inside = _cells(x_m, y_m, x0_m, y0_m, res_m, shape)
    z = (_median(ix, iy, inside, h_m, shape) if z_m is None
         else np.asarray(z_m, dtype=np.float32).reshape(shape))
    st = np.asarray(status).ravel()
    cell = iy * shape[1] + ix
    n_cells = shape[0] * shape[1]
    mis = np.bincount(cell[inside & (st == PixelStatus.MISMATCH)], minlength=n_cells)
    occ = np.bincount(cell[inside & ((st == PixelStatus.OCCLUDED) | (st == PixelStatus.OUTSIDE))],
                      minlength=n_cells)
    seen = np.bincount(cell[inside & (st != PixelStatus.OUTSIDE)], minlength=n_cells) > 0
    mask = np.where(mis > occ, MASK_MISMATCH, MASK_OCCLUDED).astype(np.uint8).reshape(shape)
    z, blanked = remove_small_islands(z, min_island_cells)
    mask[blanked] = MASK_MISMATCH
    z, _ = fill_small_holes(z, max_hole_cells)
    seen = seen.reshape(shape)
    z, rim = without_rim(z, ~(seen | np.isfinite(z)))
    mask[rim] = MASK_OCCLUDED
    has_z = np.isfinite(z)
    mask[has_z] = MASK_VALID
    return DemCells(z, mask, seen | has_z | rim)


def without_rim(z: NDArray[np.float32], outside: NDArray[np.bool_]
                ) -> tuple[NDArray[np.float32], NDArray[np.bool_]]:
    """Blank the heights next to (8-connected) the cells ``outside`` the pair (no pixel seen by
    both images fell there): the DEM's edge. Such a cell holds matched points on its inner
    side only, so its median is the height of a place off its centre: the surface moved
    outwards by up to half a cell. On simulated ``tiny`` (80 m cells, 4 points each) the
    relative DEM's outermost cells were 31-40 m out and the next two 6-10 m (regressed on the
    slopes against the truth carried into the relative frame); the surface-matching windows
    that the edge cuts then put their GCPs 6 m inwards on average (10 m where the cut moved
    their cells' centroid 1.5 km or more; 0.1 m in the uncut ones): a shrinking of the GCPs
    all round the scene, which the lens and rate terms took up. Without the outermost cells
    the windows' bias fell to 2.6 and 5.0 m (one ring more: 2.1 and 2.2, not kept). The rims
    of the voids inside the DEM are not blanked: their offsets point every way, and at a cell
    of one pixel (Pleiades at 0.5 m) the rims of the mismatched patches were 6 % of the DSM.
    The array's border is not outside: callers pad the grid (the halo of
    :func:`tasks.dense.blocks.grid_block` reaches past the DEM's own border). Returns the grid
    and the cells blanked."""
    rim = np.isfinite(z) & ndimage.binary_dilation(outside, structure=np.ones((3, 3), dtype=bool))
    if not rim.any():
        return z, rim
    out = z.copy()
    out[rim] = np.nan
    return out, rim


@dataclass(frozen=True)
class OffsetTilt:
    """The best-fit difference between two surfaces, ``dz = a + b x + c y - (dx gx + dy gy)``:
    a vertical offset ``dz_m`` at the centroid, a tilt (``tilt_x``, ``tilt_y``, metres per
    metre) and a horizontal shift (``dx_m``, ``dy_m``) seen through the slopes ``gx``, ``gy``
    of the reference; ``residual_m`` what is left, ``n_used`` the points kept."""

    dz_m: float
    tilt_x: float
    tilt_y: float
    dx_m: float
    dy_m: float
    residual_m: FloatArray
    n_used: int


def remove_offset_and_tilt(dz_m: ArrayLike, x_m: ArrayLike, y_m: ArrayLike,
                           slope_x: ArrayLike, slope_y: ArrayLike, k_nmad: float = 4.0,
                           iterations: int = 5) -> OffsetTilt:
    """Fit and remove a 3-D offset (vertical, and horizontal through the slopes) and a tilt
    from height differences ``dz_m`` (e.g. a relative DEM minus a reference at the same
    points), by least squares iterated with the points beyond ``k_nmad`` NMADs left out.
    How a relatively oriented DEM is compared with a truth: its remaining errors are the
    orientation's datum (shift, tilt), not the matching's."""
    dz, x, y, gx, gy = (np.ravel(np.asarray(a, dtype=np.float64))
                        for a in (dz_m, x_m, y_m, slope_x, slope_y))
    ok = np.isfinite(dz) & np.isfinite(gx) & np.isfinite(gy) & np.isfinite(x) & np.isfinite(y)
    if ok.sum() < 10:
        raise InputError(f"only {int(ok.sum())} valid height differences; at least 10 are "
                         "needed to fit an offset and a tilt")
    xc, yc = x - x[ok].mean(), y - y[ok].mean()
    design = np.stack([np.ones_like(dz), xc, yc, -gx, -gy], axis=1)
    use = ok.copy()
    coef = np.zeros(5)
    for _ in range(iterations):
        coef, *_ = np.linalg.lstsq(design[use], dz[use], rcond=None)
        res = dz - design @ np.where(np.isfinite(coef), coef, 0.0)
        med = np.median(res[ok])
        spread = nmad(res[ok], med)
        new = ok & (np.abs(res - med) <= k_nmad * max(spread, 1e-6))
        if (new == use).all():
            break
        use = new
    res = dz - design @ coef
    res[~ok] = np.nan
    return OffsetTilt(float(coef[0]), float(coef[1]), float(coef[2]), float(coef[3]),
                      float(coef[4]), res, int(use.sum()))
