"""tasks.io.sentinel1 through load_model and info: a Sentinel-1 annotation given alone or found
for a measurement TIFF inside a .SAFE, recognised by content; damaged or foreign annotations
and a measurement TIFF without annotation refused in one line; the grid check of info."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
import rasterio
from rasterio.control import GroundControlPoint

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
