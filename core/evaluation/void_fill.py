"""SRTM void filling by the delta surface (Grohman, Kroenung and Strebeck 2006): the paper's
second application of the oriented DSM.

A void of the reference (SRTM) is filled with the DSM's heights corrected by the difference
``delta = SRTM - DSM`` measured on the valid cells around it and interpolated across it:

1. the *ring*: valid reference cells within ``border_cells`` of a void where the DSM has a
   height; there ``delta`` is measured and the DSM-vs-SRTM statistics are reported
   (``DSM - SRTM``: bias, NMAD...);
2. ring differences further than ``outlier_nmad`` NMADs from their median are dropped (a DSM
   blunder at a void's edge must not tilt the whole fill); optionally the others are averaged
   over ``2 smooth_cells + 1`` cells (for a reference noisy from cell to cell);
3. ``delta`` is interpolated across each void as a harmonic (Laplace) surface taking the
   differences of the cells touching the void as fixed values: the smoothest surface that
   meets them, so the filled heights join the reference at the border (the "blending") and
   follow the DSM's shape inside. A void part that touches no ring (its border has no DSM)
   takes the median difference of the whole ring;
4. filled height ``= DSM + delta``; void cells without a DSM height stay void.

The differences of the cells touching a void, unsmoothed, are the best correction on the
simulator: a DSM's error is correlated over a few cells (gridding, slopes, canopy), so the
nearest measurement predicts it best. Voids of radius 2-6 cells (7937 cells in all) punched
into a tile of the tiny scene's truth terrain and filled from its 80 m DSM (LE68 12.2 m
against the truth surface): LE68 9.9 m against the truth; 11.0 / 11.5 / 11.8 m with the ring
differences averaged over 3 / 5 / 7 cells; 13.7 m for the DSM alone on those cells
(``tests/flows/test_fill_voids_cli.py``).

Heights in metres, both grids on the same nodes and in the same vertical datum (the task
converts the DSM); NaN marks voids and missing DSM. No I/O here: ``tasks.evaluation.void_fill``
reads the tile and the DSM and writes the result.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

from core.errors import InputError
from core.evaluation.evaluation import DzAccumulator, DzStats, StatsConfig
from core.geoid import GeoidGrid
from core.heights import HeightFrame
from core.robust import nmad

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

#: 4-neighbour steps of the Laplacian
_STEPS = ((-1, 0), (1, 0), (0, -1), (0, 1))


@dataclass(frozen=True)
class FillConfig:
    """Settings of :func:`delta_surface_fill` (distances in cells of the reference grid).

    ``border_cells``: width of the ring of valid cells around each void where ``DSM - SRTM``
    is reported and the outliers are screened; ``outlier_nmad``: ring differences further than
    this many NMADs from their median are not used (0: keep all); ``smooth_cells``: half-width
    of the window averaging the ring differences before they are interpolated (0, the default:
    each void takes the differences of the cells touching it, as measured; raise it when the
    reference is noisy from cell to cell).
    """

    border_cells: int = 3
    outlier_nmad: float = 5.0
    smooth_cells: int = 0

    def __post_init__(self) -> None:
        if not 1 <= self.border_cells <= 50:
            raise InputError(f"the border ring (--border-cells) must be 1..50 tile cells "
                             f"wide, got {self.border_cells}")
        if not 0 <= self.smooth_cells <= 50:
            raise InputError(f"the smoothing (--smooth-cells) must be 0..50 tile cells, got "
                             f"{self.smooth_cells}")
        if not (self.outlier_nmad >= 0 and math.isfinite(self.outlier_nmad)):
            raise InputError(f"the outlier limit (--outlier-nmad) must be a finite number >= 0, "
                             f"got {self.outlier_nmad}; 0 keeps every ring difference")


@dataclass(frozen=True, eq=False)
class FillResult:
    """What :func:`delta_surface_fill` made.

    ``heights_m``: the reference with its filled cells (NaN: still void); ``filled``: the cells
    filled; ``delta_m``: ``SRTM - DSM`` added to the DSM on the filled cells (NaN elsewhere).
    Counts are cells, except ``n_voids`` and ``n_voids_unanchored``: void regions (8-connected)
    and parts of voids (4-connected) whose border had no DSM, filled with
    ``fallback_delta_m`` (the ring's median difference, 0 without a ring).
    ``ring``: statistics of ``DSM - SRTM`` on the ring (all of it, outliers included);
    ``n_ring_rejected``: ring cells left out of ``delta`` as outliers.
    """

    heights_m: FloatArray
    filled: BoolArray
    delta_m: FloatArray
    n_void: int
    n_filled: int
    n_still_void: int
    n_voids: int
    n_voids_unanchored: int
    n_cells_unanchored: int
    fallback_delta_m: float
    ring: DzStats
    n_ring_rejected: int


def dsm_to_datum(z: ArrayLike, frame: HeightFrame, datum: str, lon_deg: ArrayLike,
                 lat_deg: ArrayLike, geoid: GeoidGrid) -> FloatArray:
    """Heights stored in ``frame`` (datum and unit) as metres in ``datum`` (``"egm96"``:
    ``H = h - N``, ``"ellipsoidal"``: ``h = H + N``) at the points ``(lon_deg, lat_deg)``."""
    HeightFrame(datum)  # checks the name
    z_m = np.asarray(z, dtype=np.float64) * frame.z_factor_m
    if frame.datum == datum:
        return z_m
    if datum == "egm96":
        return geoid.ellipsoidal_to_orthometric(lon_deg, lat_deg, z_m)
    return geoid.orthometric_to_ellipsoidal(lon_deg, lat_deg, z_m)


def nanmean_window(values: FloatArray, half: int) -> FloatArray:
    """Mean of the finite values in the ``(2 half + 1)``-cell square around each cell; NaN
    where the window holds none."""
    ok = np.isfinite(values)
    size = 2 * half + 1
    total = ndimage.uniform_filter(np.where(ok, values, 0.0), size, mode="constant")
    count = ndimage.uniform_filter(ok.astype(np.float64), size, mode="constant")
    with np.errstate(invalid="ignore", divide="ignore"):
        out = total / count
    out[count < 0.5 / size ** 2] = np.nan
    return out


def harmonic_fill(boundary_m: FloatArray, domain: BoolArray) -> FloatArray:
    """Values on the ``domain`` cells forming a discrete harmonic surface: each is the mean of
    its 4 neighbours that are in the domain or hold a finite ``boundary_m`` value (fixed).

    Neighbours that are neither (off the grid, NaN) are left out, so the surface is flat
    across them; where every neighbour is in the domain or fixed, linear fields are reproduced
    exactly. Domain parts (4-connected) touching no boundary value get NaN. Solved as one
    sparse system (SuperLU): 0.5 M cells took 5.4 s here.
    """
    domain = np.asarray(domain, dtype=bool)
    boundary = np.asarray(boundary_m, dtype=np.float64)
    if boundary.shape != domain.shape or domain.ndim != 2:
        raise InputError(f"boundary {boundary.shape} and domain {domain.shape} must be 2-D "
                         "grids of the same shape")
    boundary = np.where(domain, np.nan, boundary)
    out = np.full(domain.shape, np.nan)
    n = int(domain.sum())
    if n == 0:
        return out
    index = np.full(domain.shape, -1, dtype=np.int64)
    index[domain] = np.arange(n)
    rows, cols = np.nonzero(domain)
    nr, nc = domain.shape
    diag = np.zeros(n)
    rhs = np.zeros(n)
    touches = np.zeros(n, dtype=bool)  # has a fixed neighbour
    a_rows, a_cols = [], []
    for di, dj in _STEPS:
        r, c = rows + di, cols + dj
        on = (r >= 0) & (r < nr) & (c >= 0) & (c < nc)
        me, r, c = np.flatnonzero(on), r[on], c[on]
        other = index[r, c]
        inner = other >= 0
        a_rows.append(me[inner])
        a_cols.append(other[inner])
        diag[me[inner]] += 1.0
        value = boundary[r, c]
        fixed = ~inner & np.isfinite(value)
        diag[me[fixed]] += 1.0
        touches[me[fixed]] = True
        np.add.at(rhs, me[fixed], value[fixed])
    # parts touching no fixed value have a singular block: leave them out (NaN)
    labels, n_parts = ndimage.label(domain)
    part = labels[rows, cols]
    anchored_parts = np.zeros(n_parts + 1, dtype=bool)
    anchored_parts[part[touches]] = True
    keep = anchored_parts[part]
    if not keep.any():
        return out
    i, j = np.concatenate(a_rows), np.concatenate(a_cols)
    sub = np.cumsum(keep) - 1  # indices among the kept cells
    both = keep[i] & keep[j]
    m = int(keep.sum())
    k = np.flatnonzero(keep)
    a = sp.csc_matrix(
        (np.concatenate([np.full(int(both.sum()), -1.0), diag[k]]),
         (np.concatenate([sub[i[both]], np.arange(m)]),
          np.concatenate([sub[j[both]], np.arange(m)]))), shape=(m, m))
    out[rows[k], cols[k]] = spla.spsolve(a, rhs[k]) if m > 1 else rhs[k] / diag[k]
    return out


def _ring_differences(srtm_m: FloatArray, dsm_m: FloatArray, void: BoolArray,
                      cfg: FillConfig) -> tuple[BoolArray, FloatArray, BoolArray]:
    """The ring, ``SRTM - DSM`` on it, and the ring cells kept (outliers dropped)."""
    size = 2 * cfg.border_cells + 1
    near = ndimage.binary_dilation(void, structure=np.ones((size, size), dtype=bool))
    ring = near & ~void & np.isfinite(dsm_m)
    delta = np.where(ring, srtm_m - dsm_m, np.nan)
    keep = ring.copy()
    if cfg.outlier_nmad > 0 and ring.any():
        d = delta[ring]
        med = float(np.median(d))
        spread = nmad(d, med)
        if spread > 0:
            keep &= np.abs(np.where(ring, delta, med) - med) <= cfg.outlier_nmad * spread
    return ring, delta, keep


def delta_surface_fill(srtm_m: ArrayLike, dsm_m: ArrayLike,
                       config: FillConfig | None = None) -> FillResult:
    """Fill the voids (NaN) of ``srtm_m`` with ``dsm_m`` (same nodes, same datum, NaN where the
    DSM has no height) corrected by the interpolated ``SRTM - DSM`` difference (module
    docstring). Valid reference cells are never changed."""
    cfg = config or FillConfig()
    srtm = np.asarray(srtm_m, dtype=np.float64)
    dsm = np.asarray(dsm_m, dtype=np.float64)
    if srtm.ndim != 2 or srtm.shape != dsm.shape:
        raise InputError(f"reference {srtm.shape} and DSM {dsm.shape} must be 2-D grids of the "
                         "same nodes; resample the DSM onto the reference grid first")
    void = np.isnan(srtm)
    fillable = void & np.isfinite(dsm)
    ring, delta, keep = _ring_differences(srtm, dsm, void, cfg)
    acc = DzAccumulator(StatsConfig(n_bootstrap=0))
    acc.add(-delta[ring])  # DSM - SRTM
    fallback = float(np.median(delta[keep])) if keep.any() else 0.0
    smooth = np.where(keep, delta, np.nan)
    if cfg.smooth_cells:
        smooth = nanmean_window(smooth, cfg.smooth_cells)
    d = harmonic_fill(np.where(void, np.nan, smooth), fillable)
    unanchored = fillable & np.isnan(d)
    d[unanchored] = fallback
    heights = srtm.copy()
    heights[fillable] = dsm[fillable] + d[fillable]
    _, n_voids = ndimage.label(void, structure=np.ones((3, 3), dtype=bool))
    _, n_unanchored = ndimage.label(unanchored)
    n_void, n_filled = int(void.sum()), int(fillable.sum())
    return FillResult(
        heights_m=heights, filled=fillable, delta_m=np.where(fillable, d, np.nan),
        n_void=n_void, n_filled=n_filled, n_still_void=n_void - n_filled, n_voids=int(n_voids),
        n_voids_unanchored=int(n_unanchored), n_cells_unanchored=int(unanchored.sum()),
        fallback_delta_m=fallback, ring=acc.stats(), n_ring_rejected=int(ring.sum() - keep.sum()))
