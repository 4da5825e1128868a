"""The block's products: an image's oriented model exported as an RPC that GDAL reads (a VRT
over the image with the RPC in its metadata domain), checked with GDAL's own RPC transformer
against the model it was fitted to."""

from __future__ import annotations

import json
import warnings

import numpy as np
import rasterio
from rasterio.errors import NotGeoreferencedWarning
from rasterio.transform import RPCTransformer

from core.sensors.pushbroom_synthetic import SyntheticSpec, synthetic_pushbroom
from tasks.block.products import export_rpc


def test_the_rpc_export_is_read_by_gdal_and_projects_as_the_model(tmp_path):
    model = synthetic_pushbroom(SyntheticSpec(5.25, 44.2, 800.0, n_cols=400, n_rows=300,
                                              gsd_m=10.0, incidence_deg=22.0,
                                              epoch_utc="2023-07-12T10:00:00Z"))
    model = model.with_params([1e-4, -5e-5, 2e-5, 1e-6, 0.0, 0.0])  # an oriented model
    image = tmp_path / "img.tif"
    with warnings.catch_warnings():  # an image in sensor geometry: no georeferencing
        warnings.simplefilter("ignore", NotGeoreferencedWarning)
        with rasterio.open(image, "w", driver="GTiff", width=400, height=300, count=1,
                           dtype="uint8") as dst:
            dst.write(np.arange(120000, dtype=np.uint8).reshape(1, 300, 400))
    got = export_rpc(model, image, (400, 300), (500.0, 1200.0), tmp_path / "img")
    assert got["fit_rms_px"] < 0.01 and (tmp_path / "img.rpc.json").is_file()
    assert json.loads((tmp_path / "img.rpc.json").read_text())["type"] == "rpc"
    rng = np.random.default_rng(3)
    col, row = rng.uniform(0, 399, 50), rng.uniform(0, 299, 50)
    h = rng.uniform(450.0, 1250.0, 50)
    lon, lat = model.localize(col, row, h)
    with rasterio.open(tmp_path / "img.vrt") as src:
        assert (src.width, src.height) == (400, 300)
        assert np.array_equal(src.read(1), np.arange(120000, dtype=np.uint8).reshape(300, 400))
        with RPCTransformer(src.rpcs) as tr:
            g_row, g_col = tr.rowcol(lon, lat, zs=h, op=np.positive)
    # GDAL reports pixel-corner coordinates: its pixel centres sit at ours + 0.5
    assert np.max(np.hypot(np.asarray(g_col) - 0.5 - col, np.asarray(g_row) - 0.5 - row)) < 0.02
