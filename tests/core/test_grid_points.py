"""Points on a raster grid: node indices against the affine library, windows that sample as the
whole grid, nearest cells."""

import numpy as np
import pytest
from affine import Affine

from core.dem import sample_bilinear
from core.grid_points import affine_nodes, inside_grid, sample_nearest, window_groups


@pytest.mark.parametrize("transform", [
    (2.0, 0.0, 500_000.0, 0.0, -2.0, 4_900_000.0),
    (0.5, 0.1, 10.0, 0.2, -0.4, 46.0),  # rotated
])
def test_affine_nodes_agree_with_the_affine_library(transform):
    x = np.array([500_003.0, 500_101.0, 10.3, 11.0])
    y = np.array([4_899_995.0, 4_899_900.0, 45.7, 45.1])
    fi, fj = affine_nodes(transform, x, y)
    col, row = ~Affine(*transform) * (x, y)
    np.testing.assert_allclose(fj, np.asarray(col) - 0.5, atol=1e-9)
    np.testing.assert_allclose(fi, np.asarray(row) - 0.5, atol=1e-9)


def test_window_groups_cover_the_points_and_sample_as_the_whole_grid():
    rng = np.random.default_rng(8)
    z = rng.normal(size=(300, 410))
    z[100:103, 50:60] = np.nan
    fi = rng.uniform(-5, 305, 3000)
    fj = rng.uniform(-5, 415, 3000)
    whole = sample_bilinear(z, fi, fj)
    groups = window_groups(fi, fj, z.shape, tile_cells=64)
    assert len(groups) > 10
    got = np.full(fi.size, np.nan)
    seen = np.zeros(fi.size, int)
    for g in groups:
        assert g.row1 - g.row0 <= 66 and g.col1 - g.col0 <= 66
        got[g.index] = sample_bilinear(z[g.row0:g.row1, g.col0:g.col1], fi[g.index] - g.row0,
                                       fj[g.index] - g.col0)
        seen[g.index] += 1
    inside = inside_grid(fi, fj, z.shape)
    assert (seen == inside).all()
    np.testing.assert_array_equal(got, whole)  # NaN off the grid and next to the void


def test_nearest_cells_and_their_windows():
    grid = np.arange(12).reshape(3, 4)
    fi = np.array([0.0, -0.49, 2.49, 1.51, -0.51, 1.0])
    fj = np.array([0.0, 3.49, -0.5, 2.2, 0.0, 3.6])
    np.testing.assert_array_equal(sample_nearest(grid, fi, fj, -1), [0, 3, 8, 10, -1, -1])
    got = np.full(fi.size, -1)
    for g in window_groups(fi, fj, grid.shape, nearest=True):
        got[g.index] = sample_nearest(grid[g.row0:g.row1, g.col0:g.col1], fi[g.index] - g.row0,
                                      fj[g.index] - g.col0, -1)
    np.testing.assert_array_equal(got, [0, 3, 8, 10, -1, -1])
