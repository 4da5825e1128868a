import numpy as np
import pytest

from core.dem import GeoDEM, SurfaceGrid, sample_bilinear
from core.errors import InputError


def test_bilinear_exact_on_a_plane_and_nan_outside():
    i, j = np.mgrid[0:5, 0:7].astype(float)
    z = 3.0 * i - 2.0 * j + 10.0
    fi, fj = np.array([0.0, 2.3, 4.0, -0.1, 2.0]), np.array([0.0, 5.9, 6.0, 1.0, 6.2])
    v = sample_bilinear(z, fi, fj)
    np.testing.assert_allclose(v[:3], 3.0 * fi[:3] - 2.0 * fj[:3] + 10.0, atol=1e-12)
    assert np.isnan(v[3:]).all()


def test_voids_are_not_invented():
    z = np.ones((3, 3))
    z[1, 1] = np.nan
    assert np.isnan(sample_bilinear(z, 0.5, 0.5))
    assert sample_bilinear(z, 0.0, 2.0) == 1.0


def test_geodem_from_north_up_transform():
    h = np.arange(12.0).reshape(3, 4)  # row 0 north
    dem = GeoDEM.from_transform(h, (0.5, 0.0, 10.0, 0.0, -0.5, 46.0))
    assert dem.height_m(10.25, 45.75) == pytest.approx(0.0)  # centre of the top-left pixel
    assert dem.height_m(10.75, 45.25) == pytest.approx(5.0)
    assert dem.height_m(10.5, 45.5) == pytest.approx(2.5)
    assert np.isnan(dem.height_m(9.0, 45.5))
    assert dem.bounds_deg() == pytest.approx((10.25, 44.75, 11.75, 45.75))
    with pytest.raises(InputError, match="rotated"):
        GeoDEM.from_transform(h, (0.5, 0.1, 10.0, 0.0, -0.5, 46.0))


def test_both_grid_types_read_one_transform_the_same_way():
    """GeoDEM (degrees) and SurfaceGrid (metres) share one convention: the same array and
    the same north-up transform give the same values at the same coordinates."""
    h = np.arange(20.0).reshape(4, 5)
    t = (30.0, 0.0, 600_000.0, 0.0, -30.0, 4_900_000.0)
    geo, proj = GeoDEM.from_transform(h, t), SurfaceGrid.from_transform(h, t)
    assert proj.axes == geo.axes == (600_015.0, 4_899_985.0, 30.0, -30.0)
    x, y = np.array([600_015.0, 600_050.0, 600_130.0]), np.array([4_899_985.0, 4_899_950.0,
                                                                4_899_900.0])
    np.testing.assert_array_equal(geo.sample(x, y), proj.sample(x, y))
    assert proj.sample(600_015.0, 4_899_985.0 - 30.0) == 5.0  # one row south
    np.testing.assert_array_equal(geo.nodes()[1][:, 0], 4_899_985.0 - 30.0 * np.arange(4))
    assert proj.bounds() == (600_015.0, 4_899_895.0, 600_135.0, 4_899_985.0)
    assert proj.with_values(h + 1.0).sample(600_015.0, 4_899_985.0) == 1.0
    with pytest.raises(InputError, match="non-zero"):
        SurfaceGrid(h, 0.0, 0.0, 30.0, 0.0)
