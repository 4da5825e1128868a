"""The compiled RPC projection (:func:`core.sensors.rpc_kernels.rpc_project`, behind
``RPCModel.project``) against the NumPy evaluation of the same model and against rpcm (an
independent implementation, when installed), on real vendor RPCs, with every bias mode, NaN
inputs, broadcasting and arrays large enough to be split over threads."""

from __future__ import annotations

import numpy as np
import pytest

from core.parallel import MIN_SPLIT
from core.sensors.rpc import RPCModel
from tests.core.sensors.test_rpc import REAL_ALL, domain_points, load
from tests.peers import rpcm_model_module

TOL_PX = 1e-9


def biased(m: RPCModel, mode: str) -> RPCModel:
    if mode == "none":
        return m
    if mode == "shift":
        return m.with_bias_mode("shift").with_params([3.25, -1.5])
    return m.with_bias_mode("affine").with_params([3.25, 0.4, -0.7, -1.5, 0.2, 0.9])


@pytest.mark.parametrize("mode", ["none", "shift", "affine"])
@pytest.mark.parametrize("path", REAL_ALL)
def test_compiled_projection_equals_the_numpy_evaluation(path, mode):
    m = biased(load(path), mode)
    # more points than one thread takes, so the split over threads is exercised
    lon, lat, h = domain_points(m, 3 * MIN_SPLIT + 17, seed=5)
    col, row = m.project(lon, lat, h)
    col_np, row_np = m._project_numpy(lon, lat, h)
    assert np.max(np.abs(col - col_np)) < TOL_PX
    assert np.max(np.abs(row - row_np)) < TOL_PX
    # the bias did something (the test would not notice a kernel that ignores it otherwise)
    if mode != "none":
        c0, r0 = load(path).project(lon[:100], lat[:100], h[:100])
        assert np.min(np.hypot(col[:100] - c0, row[:100] - r0)) > 0.1


def test_nan_scalars_and_shapes_follow_numpy():
    m = biased(load(REAL_ALL[0].values[0]), "affine")
    lon, lat, h = domain_points(m, 12, seed=6)
    lon[3], lat[7], h[9] = np.nan, np.nan, np.nan
    col, row = m.project(lon.reshape(3, 4), lat.reshape(3, 4), h.reshape(3, 4))
    col_np, row_np = m._project_numpy(lon.reshape(3, 4), lat.reshape(3, 4), h.reshape(3, 4))
    assert col.shape == (3, 4)
    np.testing.assert_allclose(col, col_np, rtol=0, atol=TOL_PX)
    np.testing.assert_allclose(row, row_np, rtol=0, atol=TOL_PX)
    assert np.isnan(col.ravel()[[3, 7, 9]]).all() and np.isfinite(np.delete(col, [3, 7, 9])).all()
    c, r = m.project(float(lon[0]), float(lat[0]), 500.0)  # scalars and broadcasting
    cn, rn = m._project_numpy(float(lon[0]), float(lat[0]), 500.0)
    assert np.shape(c) == () and abs(c - cn) < TOL_PX and abs(r - rn) < TOL_PX
    c, r = m.project(lon[:3], lat[:3], np.array([[100.0], [900.0]]))
    assert c.shape == (2, 3)
    assert np.max(np.abs(c - m._project_numpy(lon[:3], lat[:3], [[100.0], [900.0]])[0])) < TOL_PX


@pytest.mark.parametrize("path", REAL_ALL)
def test_compiled_projection_agrees_with_rpcm(path):
    rpcm = rpcm_model_module()
    if rpcm is None:
        pytest.skip("rpcm is not installed (pip install --no-deps 'rpcm>=1.4')")
    m = load(path)
    lon, lat, h = domain_points(m, 20_000, seed=7)
    col, row = m.project(lon, lat, h)
    theirs = rpcm.RPCModel(m.to_gdal_tags())  # GDAL keys, our pixel convention
    c, r = theirs.projection(lon, lat, h)
    assert np.max(np.abs(np.asarray(c) - col)) < TOL_PX
    assert np.max(np.abs(np.asarray(r) - row)) < TOL_PX
