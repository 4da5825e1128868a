"""core.matching.lattice.correlations (one compiled pass over shifts and cells) against the
same partial correlations written out over arrays with core.dem.sample_bilinear."""

from __future__ import annotations

import numpy as np
import pytest

from core.dem import GeoDEM
from core.geodesy import ARCSEC
from core.matching.lattice import correlations, surface_basis, window_cells
from tests.core.matching.test_surface_match import LAT0, LON0, reference, relative_dem


def array_correlations(cells, ref: GeoDEM, shifts_deg, detrend):
    ok = np.isfinite(cells.h_m)
    lon, lat = cells.lon_deg[ok], cells.lat_deg[ok]
    h0 = float(np.mean(cells.h_m[ok]))
    h = cells.h_m[ok] - h0
    b = surface_basis(cells, ok, detrend)
    rho, count = np.full(len(shifts_deg), np.nan), np.zeros(len(shifts_deg))
    for s, (sx, sy) in enumerate(shifts_deg):
        r = ref.height_m(lon + sx, lat + sy)
        v = np.isfinite(r)
        count[s] = v.sum()
        if v.sum() <= b.shape[1]:
            continue
        bv, hv, rv = b[v], h[v], r[v] - h0
        rh = hv - bv @ np.linalg.lstsq(bv, hv, rcond=None)[0]
        rr = rv - bv @ np.linalg.lstsq(bv, rv, rcond=None)[0]
        rho[s] = rh @ rr / np.sqrt((rh @ rh) * (rr @ rr))
    return rho, count


@pytest.mark.parametrize("detrend", [0, 1, 2])
def test_compiled_sums_give_the_array_correlations(detrend):
    """Shifts inside, at the edge of and beyond a reference with voids: the same counts, the
    same correlations within 1e-9 (sums in another order), NaN where no pair is valid."""
    ref = reference(void_fraction=0.05)
    lon, lat, h = relative_dem((4.0, -3.0, 10.0))
    h[::17] = np.nan
    cells = window_cells(lon, lat, h, (LON0, LAT0), 4000.0, 90.0)
    g = np.arange(-20.0, 21.0, 4.0)
    gx, gy = np.meshgrid(g, g)
    shifts = np.vstack([np.stack([gx.ravel(), gy.ravel()], 1) * ARCSEC,
                        [[0.15, 0.0], [0.0, -0.155], [1.0, 1.0]]])  # the edge, and far off
    rho, count = correlations(cells, ref, shifts, detrend)
    want_rho, want_count = array_correlations(cells, ref, shifts, detrend)
    assert np.array_equal(count, want_count)
    assert count[-1] == 0 and np.isnan(rho[-1]) and 0 < count[-2] < count[0]
    assert np.isfinite(rho[:-1]).all()
    assert np.allclose(rho[:-1], want_rho[:-1], rtol=0, atol=1e-9)
