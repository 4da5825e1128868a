"""tasks.io.sentinel1 through load_model and info: a Sentinel-1 annotation given alone or found
for a measurement TIFF inside a .SAFE, recognised by content; damaged or foreign annotations
and a measurement TIFF without annotation refused in one line; the grid check of info."""

from __future__ import annotations

import json
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest
import rasterio
from affine import Affine
from rasterio.control import GroundControlPoint
from rasterio.errors import NotGeoreferencedWarning

from core.errors import InputError
from core.sensors.sar import SarModel
from flows.cli import main
from tasks.io.sensor_info import gather_info
from tasks.io.sensors import load_model, model_beside

S1 = Path(__file__).resolve().parents[1] / "data" / "sentinel1"
SLC = S1 / "s1a-s3-slc-vh-20210401t152855-20210401t152914-037258-04638e-001.xml"
GRD = S1 / "s1b-iw-grd-vv-20210401t052623-20210401t052648-026269-032297-001.xml"


def _sparse_tiff(path: Path, width: int, height: int) -> Path:
    """A GeoTIFF of the product's size with no data written (sparse: instant, tiny), with
    GCPs as Sentinel-1 measurement TIFFs carry them (values irrelevant here)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    gcps = [GroundControlPoint(row=r, col=c, x=10.0 + c * 1e-4, y=46.0 + r * 1e-4, z=0.0)
            for r, c in ((0, 0), (0, width - 1), (height - 1, 0))]
    with rasterio.open(path, "w", driver="GTiff", width=width, height=height, count=1,
                       dtype="uint8", tiled=True, sparse_ok=True, gcps=gcps,
                       crs="EPSG:4326"):
        pass
    return path


@pytest.mark.parametrize(("path", "kind"), [(SLC, "slc"), (GRD, "grd")])
def test_annotation_alone(path, kind):
    lm = load_model(path)
    assert lm.family == "sar" and isinstance(lm.model, SarModel) and lm.model.kind == kind
    assert lm.size == (lm.model.n_cols, lm.model.n_rows)
    assert lm.sar is not None and lm.sar.grid.line.size > 200


def test_measurement_tiff_in_safe(tmp_path):
    safe = tmp_path / "S1B_IW_GRDH.SAFE"
    (safe / "annotation").mkdir(parents=True)
    shutil.copy(GRD, safe / "annotation" / (GRD.stem + ".xml"))
    tif = _sparse_tiff(safe / "measurement" / (GRD.stem + ".tiff"), 25788, 16685)
    assert model_beside(tif) == safe / "annotation" / (GRD.stem + ".xml")
    lm = load_model(tif)
    assert lm.family == "sar" and lm.image == tif and lm.model.kind == "grd"
    # the wrong size is refused in one line
    small = _sparse_tiff(safe / "measurement" / "x.tiff", 100, 100)
    with pytest.raises(InputError, match="not the same image") as e:
        load_model(small, model=safe / "annotation" / (GRD.stem + ".xml"))
    assert "\n" not in str(e.value)
    # a measurement TIFF with no annotation
    with pytest.raises(InputError, match="no sensor model found") as e:
        load_model(_sparse_tiff(tmp_path / "other.SAFE" / "measurement" / "y.tiff", 10, 10))
    assert "\n" not in str(e.value)


def test_damaged_and_foreign_annotations_refused(tmp_path):
    text = GRD.read_text()
    cases = {
        "cut.xml": text[: len(text) // 3],
        "rs2.xml": text.replace("<missionId>S1B</missionId>", "<missionId>RS2</missionId>"),
        "noorbit.xml": text.replace("<orbitList", "<orbitListX").replace(
            "</orbitList>", "</orbitListX>"),
        "other.xml": "<?xml version='1.0'?><whatever><a>1</a></whatever>",
    }
    for name, body in cases.items():
        (tmp_path / name).write_text(body)
        with pytest.raises(InputError) as e:
            load_model(tmp_path / name)
        assert "\n" not in str(e.value), name
        assert name in str(e.value)


def test_info_reports_the_grid_check(tmp_path, capsys):
    report = gather_info(SLC)
    d = report.to_dict()
    chk = d["sar"]["grid_check"]
    assert d["family"] == "sar" and d["sar"]["mode"] == "S3"
    assert chk["pixel_max_px"] < 0.001 and chk["line_max_px"] < 0.25
    assert chk["azimuth_max_m"] < 0.015 and chk["range_max_mm"] < 1.0
    assert abs(d["incidence_deg"] - 32.03) < 3.0  # the annotation's mid-swath incidence
    out = tmp_path / "info.json"
    assert main(["info", str(GRD), "--json", str(out)]) == 0
    assert "grid check" in capsys.readouterr().out
    g = json.loads(out.read_text())["sar"]["grid_check"]
    assert g["pixel_max_px"] < 0.01 and g["line_max_px"] < 0.25 and g["n_points"] == 210


def _offset_tiff(path: Path, width: int, height: int, offset: tuple[float, float]) -> Path:
    """A crop as rasterio's window_transform writes it for a raster without georeferencing:
    no CRS, a pure pixel-offset geotransform."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NotGeoreferencedWarning)
        with rasterio.open(path, "w", driver="GTiff", width=width, height=height, count=1,
                           dtype="uint8", tiled=True, sparse_ok=True,
                           transform=Affine.translation(*offset)):
            pass
    return path


def test_cropped_measurement_tiff_is_placed(tmp_path):
    """A crop of a measurement TIFF carrying its pixel offset gets the product's model moved by
    that offset (as a .geom or .DIM is), found in the .SAFE or named; the grid check, which is
    in the product's pixels, is not attached to it."""
    safe = tmp_path / "S1B_IW_GRDH.SAFE"
    (safe / "annotation").mkdir(parents=True)
    ann = safe / "annotation" / (GRD.stem + ".xml")
    shutil.copy(GRD, ann)
    tif = _offset_tiff(safe / "measurement" / (GRD.stem + ".tiff"), 400, 300, (12000.0, 8000.0))
    product = load_model(GRD).model
    c, r = np.meshgrid(np.linspace(0, 399, 3), np.linspace(0, 299, 3))
    lon, lat = product.localize(c.ravel() + 12000.0, r.ravel() + 8000.0, 150.0)
    for lm in (load_model(tif), load_model(tif, model=ann)):
        assert lm.family == "sar" and lm.crop == (12000.0, 8000.0) and lm.sar is None
        assert (lm.model.n_cols, lm.model.n_rows) == lm.size == (400, 300)
        np.testing.assert_allclose(np.stack(lm.model.project(lon, lat, 150.0)),
                                   [c.ravel(), r.ravel()], atol=1e-5)
    # a crop reaching past the product is refused in one line
    far = _offset_tiff(tmp_path / "far.tiff", 400, 300, (25500.0, 0.0))
    with pytest.raises(InputError, match="does not fit") as e:
        load_model(far, model=ann)
    assert "\n" not in str(e.value)


def test_adjusted_sar_json_reads_back(tmp_path):
    """An adjusted SAR model written as gcpfree JSON is loaded as a SAR model with its
    corrections, alone, beside an image of its size, and moved onto a crop of that image."""
    adjusted = load_model(SLC).model.with_params([2.5e-3, -4e-8])
    path = tmp_path / "slc.json"
    path.write_text(adjusted.to_json(indent=1))
    alone = load_model(path)
    assert alone.family == "sar" and isinstance(alone.model, SarModel) and alone.image is None
    np.testing.assert_array_equal(alone.model.params, [2.5e-3, -4e-8])
    assert alone.size == (adjusted.n_cols, adjusted.n_rows)
    c, r = np.array([10.0, 5000.0, 15000.0]), np.array([20.0, 3000.0, 9000.0])
    lon, lat = adjusted.localize(c, r, 100.0)
    np.testing.assert_allclose(np.stack(alone.model.project(lon, lat, 100.0)), [c, r],
                               atol=1e-6)
    crop = _offset_tiff(tmp_path / "crop.tif", 16000, 10000, (7.0, 9.0))
    placed = load_model(crop, model=path)
    assert placed.family == "sar" and placed.crop == (7.0, 9.0)
    np.testing.assert_allclose(np.stack(placed.model.project(lon, lat, 100.0)),
                               [c - 7.0, r - 9.0], atol=1e-6)
    bad = tmp_path / "bad.json"
    d = json.loads(path.read_text())
    del d["timing"]["line_interval_s"]
    bad.write_text(json.dumps(d))
    with pytest.raises(InputError, match="bad.json.*SAR model: key 'timing.line_interval_s'"):
        load_model(bad)
