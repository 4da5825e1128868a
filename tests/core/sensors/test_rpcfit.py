"""RPC fitting from a rigorous pushbroom model, checked independently and through GDAL."""

from __future__ import annotations

import numpy as np
import pytest
import rasterio
from rasterio.rpc import RPC
from rasterio.transform import RPCTransformer

from core.errors import InputError
from core.sensors.linear_array import LensDistortion
from core.sensors.pushbroom_synthetic import SyntheticSpec, synthetic_pushbroom
from core.sensors.rpcfit import RPCFitConfig, fit_rpc

H_RANGE = (-400.0, 4800.0)


@pytest.fixture(scope="module")
def spot_like():
    return synthetic_pushbroom(SyntheticSpec(5.3, 44.2, centre_h_m=500.0, n_cols=6000, n_rows=6000,
                                    gsd_m=10.0, incidence_deg=25.0))


@pytest.fixture(scope="module")
def fitted(spot_like):
    return fit_rpc(spot_like, 6000, 6000, H_RANGE)


def random_ground(model, n=5000, seed=0):
    rng = np.random.default_rng(seed)
    col = rng.uniform(-0.5, 5999.5, n)
    row = rng.uniform(-0.5, 5999.5, n)
    h = rng.uniform(*H_RANGE, n)
    lon, lat = model.localize(col, row, h)
    return col, row, h, lon, lat


def test_fit_meets_002_px_on_independent_grid(fitted):
    _, report = fitted
    assert report.max_px <= 0.02
    assert report.rms_px <= report.max_px
    assert report.n_check > 1000


def test_fit_on_random_points(spot_like, fitted):
    rpc, _ = fitted
    col, row, h, lon, lat = random_ground(spot_like)
    pc, pr = rpc.project(lon, lat, h)
    assert np.hypot(pc - col, pr - row).max() <= 0.02
    # and the inverse direction through the RPC's own localize
    lon2, lat2 = rpc.localize(col, row, h)
    dm = np.hypot((lon2 - lon) * 111e3 * np.cos(np.radians(lat)), (lat2 - lat) * 111e3)
    assert dm.max() < 0.02 * 10.0  # 0.02 px of 10 m


def test_fit_with_lens_distortion_and_rotation():
    m = synthetic_pushbroom(SyntheticSpec(
        -70.0, -33.0, centre_h_m=1000.0, n_cols=3000, n_rows=4000, gsd_m=20.0,
        incidence_deg=-18.0, pitch_deg=10.0, ccd_rotation_rad=2e-4,
        distortion=LensDistortion(k1=1e-5, k3=2e-3, p1=1e-6, p2=-2e-6),
    ))
    rpc, report = fit_rpc(m, 3000, 4000, (0.0, 6000.0))
    assert report.max_px <= 0.02
    col, row = np.array([0.0, 2999.0, 1500.0]), np.array([0.0, 3999.0, 2000.0])
    lon, lat = m.localize(col, row, np.full(3, 3000.0))
    pc, pr = rpc.project(lon, lat, 3000.0)
    assert np.hypot(pc - col, pr - row).max() <= 0.02


def test_too_small_fit_grid_is_refused(spot_like):
    with pytest.raises(InputError, match="78 unknowns"):
        RPCFitConfig(n_cols=4)
    with pytest.raises(InputError, match="h_max > h_min"):
        fit_rpc(spot_like, 6000, 6000, (100.0, 100.0))


def test_geotiff_with_fitted_rpc_opens_in_gdal(tmp_path, spot_like, fitted):
    rpc, _ = fitted
    path = tmp_path / "img.tif"
    with rasterio.open(path, "w", driver="GTiff", width=64, height=64, count=1, dtype="uint8",
                       rpcs=RPC.from_gdal(rpc.to_gdal_tags())) as dst:
        dst.write(np.zeros((1, 64, 64), np.uint8))
    with rasterio.open(path) as src:
        rpcs = src.rpcs
    assert rpcs is not None
    col, row, h, lon, lat = random_ground(spot_like, n=2000, seed=1)
    with RPCTransformer(rpcs) as tr:
        g_row, g_col = tr.rowcol(lon, lat, zs=h, op=np.positive)
    # GDAL counts from the pixel corner: its coordinates are ours + 0.5
    err = np.hypot(np.asarray(g_col) - 0.5 - col, np.asarray(g_row) - 0.5 - row)
    assert err.max() < 0.05
