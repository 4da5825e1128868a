"""The generic line-of-sight / DEM intersection on steep terrain (a 79 degree cliff)."""

import numpy as np
import pytest

from core.dem import GeoDEM
from core.geodesy import metres_per_degree
from core.sensors.base import localize_on_dem
from core.sensors.pushbroom_synthetic import SyntheticSpec, synthetic_pushbroom


@pytest.fixture(scope="module")
def model():
    return synthetic_pushbroom(SyntheticSpec(5.3, 44.2, centre_h_m=1000.0, n_cols=2000, n_rows=2000,
                                    gsd_m=10.0, incidence_deg=25.0))


def cliff_dem() -> GeoDEM:
    """1500 m rise over 300 m across a N-S cliff at lon 5.3, on a 10 m-ish grid."""
    dlon, dlat = 1.0 / 8000, 1.0 / 11000
    lon = 5.15 + np.arange(2400) * dlon
    lat = 44.32 - np.arange(2640) * dlat
    x_m = (lon - 5.3) * metres_per_degree(44.2)[0]
    h = 500.0 + 1500.0 * np.clip(x_m / 300.0, 0.0, 1.0)
    return GeoDEM(np.broadcast_to(h, (lat.size, lon.size)).copy(), lon[0], lat[0], dlon, -dlat)


def test_first_visible_intersection_on_a_cliff(model):
    dem = cliff_dem()
    rng = np.random.default_rng(4)
    col, row = rng.uniform(0, 1999, 400), rng.uniform(0, 1999, 400)
    lon, lat, h = localize_on_dem(model, col, row, dem, tol_m=1e-4)
    ok = np.isfinite(h)
    assert ok.mean() > 0.95
    # on the surface, and seen from the pixel it came from
    np.testing.assert_allclose(h[ok], dem.height_m(lon[ok], lat[ok]), atol=1e-3)
    c2, r2 = model.project(lon[ok], lat[ok], h[ok])
    assert np.hypot(c2 - col[ok], r2 - row[ok]).max() < 1e-3
    # the first crossing: every point of the ray above it is above the terrain
    for dh in (1.0, 5.0, 50.0, 200.0, 1000.0):
        lo2, la2 = model.localize(col[ok], row[ok], h[ok] + dh)
        above = h[ok] + dh - dem.height_m(lo2, la2)
        assert np.all((above > -1e-3) | np.isnan(above))
    # some rays do land on the cliff face itself
    on_face = (h[ok] > 520.0) & (h[ok] < 1980.0)
    assert on_face.sum() >= 3
