"""Several stereo pairs' heights fused cell by cell: the multi-view DSM (step 2 of the chain
for three or more views).

Each pair's matched points give a cell the median of their heights
(:func:`core.matching.grid.median_per_cell`), and the pairs' heights of a cell are fused, each
pair weighted by (B/H)^2 (one matching error in pixels is a height error inversely
proportional to B/H: (B/H)^2 is the inverse of a pair's height variance):

- ``weighted_median`` (the default): the weighted median, the height where half the weight
  lies on either side. Where one pair's geometry outweighs the others it is that pair's
  height (its blunders too, as in its own DSM), elsewhere the median of comparable pairs;
  the others' blunders never move it.
- ``weighted_mean``: the weighted mean of the pairs within ``k_sigma`` robust sigmas of the
  weighted median (a pair's sigma: its NMAD about it over the cells it shares with another
  pair in the block). The best when the pairs' errors are independent.
- ``median``: the median of the pairs' heights (each pair counts alike).

Why the default. On a triplet of one pass the pairs' errors are not independent: the two
narrow pairs share the middle image, and their heights average into the wide pair's (both
measure the outer images' parallax). Measured on the Pleiades Marseille triplet after the
joint relative orientation (B/H 0.11, 0.11, 0.23; 0.5 m cells), the noise of each DSM as the
NMAD of its discrete Laplacian over the 227 000 cells where the three pairs have heights
throughout the stencil: the narrow pairs 0.41 m each, the wide one 0.21 m; fused, the
weighted median 0.21 m (it keeps the wide pair's heights where it has them), the weighted
mean 0.21 m (0.214: the narrow pairs add noise, not information), the median 0.31 m (it
follows the noisier pairs). With independent errors (a synthetic test) the weighted mean is
the best of the three and the weighted median only the best pair's; the matcher keeps no
per-pixel correlation in its point files, so the pairs are weighted by their geometry alone.

A cell's count of views is the number of images among the pairs that agree with its height
(within ``k_sigma`` robust sigmas of the weighted median; every pair with a height for the
median). The heights of each pair are also kept per cell, to compare the pairs
(:func:`difference_histograms`). No I/O here.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.errors import InputError
from core.matching.grid import median_per_cell

FloatArray = NDArray[np.float64]
FUSION_METHODS = ("weighted_median", "weighted_mean", "median")
#: bins of the pairs' height differences (m): 5 mm, over +-100 m
DIFF_EDGES_M = np.linspace(-100.0, 100.0, 40001)


@dataclass(frozen=True)
class FusionConfig:
    """How the pairs' heights of a cell are fused (module docstring): ``method`` one of
    :data:`FUSION_METHODS`; ``k_sigma`` the robust sigmas beyond which a pair disagrees with
    the weighted median (left out of the weighted mean and of the count of views); a pair
    sharing fewer than ``min_shared_cells`` cells with another in a block is never left out
    there (its sigma unknown)."""

    method: str = "weighted_median"
    k_sigma: float = 3.0
    min_shared_cells: int = 100

    def __post_init__(self) -> None:
        if self.method not in FUSION_METHODS:
            raise InputError(f"fusion method {self.method!r} unknown; use one of "
                             f"{', '.join(FUSION_METHODS)}")
        if not self.k_sigma > 0 or self.min_shared_cells < 1:
            raise InputError("fusion needs k_sigma > 0 and min_shared_cells >= 1")


DEFAULT_FUSION = FusionConfig()


@dataclass(frozen=True, eq=False)
class FusedCells:
    """Fused heights ``z_m`` (NaN where no pair has one) and the views each cell's height
    comes from (``views``: images among the pairs kept; 0 without a height)."""

    z_m: NDArray[np.float32]
    views: NDArray[np.uint8]


def pair_heights(x_m: ArrayLike, y_m: ArrayLike, h_m: ArrayLike, pair: ArrayLike,
                 n_pairs: int, x0_m: float, y0_m: float, res_m: float,
                 shape: tuple[int, int]) -> NDArray[np.float32]:
    """(n_pairs, rows, cols): each pair's median height per cell (``pair`` the pair of each
    point), NaN where the pair has none."""
    x, y, h = (np.asarray(a, dtype=np.float64).ravel() for a in (x_m, y_m, h_m))
    p = np.asarray(pair).ravel()
    return np.stack([median_per_cell(x[p == k], y[p == k], h[p == k], x0_m, y0_m, res_m, shape)
                     for k in range(n_pairs)])


def weighted_median(z: ArrayLike, weights: ArrayLike) -> NDArray[np.float32]:
    """Along the first axis: the value where the finite values' cumulated weight (ascending)
    first reaches half their total (NaN where none is finite)."""
    z = np.asarray(z, dtype=np.float32)
    w = np.asarray(weights, dtype=np.float64).reshape((-1,) + (1,) * (z.ndim - 1))
    finite = np.isfinite(z)
    order = np.argsort(np.where(finite, z, np.inf), axis=0)
    zs = np.take_along_axis(z, order, axis=0)
    ws = np.take_along_axis(np.where(finite, np.broadcast_to(w, z.shape), 0.0), order, axis=0)
    cum = np.cumsum(ws, axis=0)
    total = cum[-1]
    first = np.argmax(cum >= 0.5 * total, axis=0)
    out = np.take_along_axis(zs, first[None], axis=0)[0]
    return np.where(total > 0, out, np.float32(np.nan)).astype(np.float32)


def _kept(z_pairs: NDArray[np.float32], weights: FloatArray, cfg: FusionConfig
          ) -> tuple[NDArray[np.bool_], NDArray[np.float32]]:
    """Which pairs' heights the weighted fusion keeps per cell, and the weighted median."""
    finite = np.isfinite(z_pairs)
    med = weighted_median(z_pairs, weights)
    shared = finite.sum(axis=0) >= 2
    keep = finite.copy()
    for k in range(z_pairs.shape[0]):
        use = finite[k] & shared
        if use.sum() < cfg.min_shared_cells:
            continue
        d = z_pairs[k][use] - med[use]
        sigma = 1.4826 * float(np.median(np.abs(d - np.median(d))))
        with np.errstate(invalid="ignore"):
            keep[k] &= ~(np.abs(z_pairs[k] - med) > cfg.k_sigma * max(sigma, 1e-6))
    return keep, med


def median_of_pairs(z_pairs: ArrayLike) -> NDArray[np.float32]:
    """Along the first axis: the median of the finite values (NaN where none)."""
    z = np.sort(np.asarray(z_pairs, dtype=np.float32), axis=0)  # NaN last
    n = np.isfinite(z).sum(axis=0)
    lo = np.take_along_axis(z, np.maximum((n - 1) // 2, 0)[None], axis=0)[0]
    hi = np.take_along_axis(z, np.maximum(n // 2, 0)[None], axis=0)[0]
    return np.where(n > 0, 0.5 * (lo + hi), np.float32(np.nan)).astype(np.float32)


def fuse_heights(z_pairs: ArrayLike, weights: ArrayLike, pair_images: ArrayLike,
                 cfg: FusionConfig = DEFAULT_FUSION) -> FusedCells:
    """The pairs' heights of each cell (``z_pairs`` (n_pairs, rows, cols)) fused by
    ``cfg.method``; ``weights`` per pair ((B/H)^2), ``pair_images`` (n_pairs, 2) the images
    of each pair (for the count of views)."""
    z = np.asarray(z_pairs, dtype=np.float32)
    w = np.asarray(weights, dtype=np.float64).ravel()
    images = np.asarray(pair_images, dtype=np.intp).reshape(-1, 2)
    if z.ndim != 3 or w.size != z.shape[0] or images.shape[0] != z.shape[0]:
        raise InputError(f"fusion: {z.shape[0] if z.ndim == 3 else z.shape} pairs of heights, "
                         f"{w.size} weights and {images.shape[0]} image pairs; give one of "
                         "each per pair")
    if not (np.all(w > 0) and np.all(np.isfinite(w))):
        raise InputError("fusion weights must be finite and > 0")
    if cfg.method == "median":
        keep = np.isfinite(z)
        fused = median_of_pairs(z)
    elif cfg.method == "weighted_median":
        keep, fused = _kept(z, w, cfg)
    else:
        keep, _ = _kept(z, w, cfg)
        wk = np.where(keep, w[:, None, None], 0.0)
        total = wk.sum(axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            fused = np.where(total > 0, np.sum(np.where(keep, z, 0.0) * wk, axis=0) / total,
                             np.nan)
    seen = np.zeros(z.shape[1:], dtype=np.uint8)
    for image in np.unique(images):
        has = np.zeros(z.shape[1:], dtype=bool)
        for k in np.flatnonzero((images == image).any(axis=1)):
            has |= keep[k]
        seen += has.astype(np.uint8)
    return FusedCells(np.asarray(fused, dtype=np.float32), seen)


def difference_histograms(z_pairs: ArrayLike, edges: FloatArray = DIFF_EDGES_M
                          ) -> NDArray[np.int64]:
    """(n_pairs * (n_pairs - 1) / 2, len(edges) - 1): for each two pairs (p < q, in order) the
    histogram of their height differences z_p - z_q over the cells both have."""
    z = np.asarray(z_pairs, dtype=np.float64)
    out = []
    for p in range(z.shape[0]):
        for q in range(p + 1, z.shape[0]):
            d = z[p] - z[q]
            out.append(np.histogram(d[np.isfinite(d)], bins=edges)[0])
    return np.array(out, dtype=np.int64).reshape(-1, edges.size - 1)


def histogram_median(counts: ArrayLike, edges: FloatArray = DIFF_EDGES_M) -> float:
    """The median of a histogram (linear within its bin); NaN when it is empty."""
    c = np.asarray(counts, dtype=np.float64)
    total = c.sum()
    if total <= 0:
        return float("nan")
    cum = np.cumsum(c)
    k = int(np.searchsorted(cum, 0.5 * total))
    before = cum[k - 1] if k > 0 else 0.0
    frac = (0.5 * total - before) / c[k] if c[k] > 0 else 0.0
    return float(edges[k] + frac * (edges[k + 1] - edges[k]))
