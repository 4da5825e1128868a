"""core.matching.grid.median_per_cell: the float32 points' one-key sort against a plain
per-cell median."""

from __future__ import annotations

import numpy as np

from core.matching.grid import median_per_cell


def test_median_per_cell_of_float32_heights_is_the_plain_median():
    """Negative, zero (both signs), NaN and repeated heights, points outside the grid: each
    cell holds the median of its finite points (the mean of the middle two when even), the
    same for float32 (one 64-bit key sorted) and float64 (lexsort) heights."""
    rng = np.random.default_rng(3)
    n, res, shape = 20_000, 10.0, (12, 17)
    x = rng.uniform(-15, 185, n)
    y = rng.uniform(-135, 15, n)
    h = rng.normal(0, 300, n).astype(np.float32)
    h[::9] = np.round(h[::9] / 100) * 100  # ties
    h[::13], h[1::13], h[::17] = 0.0, -0.0, np.nan
    got32 = median_per_cell(x, y, h, 0.0, 0.0, res, shape)
    got64 = median_per_cell(x, y, h.astype(np.float64), 0.0, 0.0, res, shape)
    want = np.full(shape, np.nan, dtype=np.float32)
    col, row = np.floor(x / res), np.floor(-y / res)
    for i in range(shape[0]):
        for j in range(shape[1]):
            v = h[(row == i) & (col == j) & np.isfinite(h)].astype(np.float64)
            if v.size:
                want[i, j] = np.median(v)
    assert np.array_equal(got32, want, equal_nan=True)
    assert np.array_equal(got64, want, equal_nan=True)
    empty = median_per_cell(np.array([1.0]), np.array([-1.0]), np.array([np.nan], np.float32),
                            0.0, 0.0, res, shape)
    assert np.isnan(empty).all()
