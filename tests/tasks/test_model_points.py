"""gcpfree project / localize (tasks.io.model_points): every model family, CSV in and out,
through the command line: image points localised at a height and projected back land on
themselves; other columns are kept; SAR rows get their azimuth and slant-range times."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from core.sensors.dimap import dimap_xml
from core.sensors.pushbroom_synthetic import SyntheticSpec, synthetic_pushbroom
from core.sensors.sentinel1 import parse_annotation
from core.sensors.spot import spot_scene_from_model
from flows.cli import main
from tasks.io.sensors import load_model

DATA = Path(__file__).resolve().parents[1] / "data"
S1 = DATA / "sentinel1"
SLC = S1 / "s1a-s3-slc-vh-20210401t152855-20210401t152914-037258-04638e-001.xml"
GRD = S1 / "s1b-iw-grd-vv-20210401t052623-20210401t052648-026269-032297-001.xml"


def _pushbroom_json(tmp: Path) -> Path:
    m = synthetic_pushbroom(SyntheticSpec(5.0, 44.0, n_cols=400, n_rows=300, gsd_m=10.0))
    (tmp / "model.json").write_text(m.to_json())
    return tmp / "model.json"


def _spot_dim(tmp: Path) -> Path:
    m = synthetic_pushbroom(SyntheticSpec(5.0, 44.0, n_cols=400, n_rows=300, gsd_m=10.0))
    (tmp / "METADATA.DIM").write_text(dimap_xml(spot_scene_from_model(m, mission_index=2)))
    return tmp / "METADATA.DIM"


MODELS = {
    "rpc_geom": lambda _t: DATA / "pleiades_gizeh" / "img1.geom",
    "rpc_dimap": lambda _t: DATA / "dimap" / "RPC_PHR1B_P_201308051042194_SEN_690908101-001.XML",
    "rpc_tags": lambda _t: DATA / "pleiades_reunion" / "img_01.tif",
    "pushbroom_json": _pushbroom_json,
    "spot_dim": _spot_dim,
    "sar_slc": lambda _t: SLC,
    "sar_grd": lambda _t: GRD,
}


def _read(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


@pytest.mark.parametrize("family", list(MODELS))
def test_localize_then_project_round_trip(family, tmp_path, capsys):
    model = MODELS[family](tmp_path)
    lm = load_model(model)
    n_cols, n_rows = lm.size
    h0 = float(getattr(lm.model, "alt_off", 100.0))
    cols = np.linspace(0, n_cols - 1, 4)
    rows = np.linspace(0, n_rows - 1, 3)
    c, r = (a.ravel() for a in np.meshgrid(cols, rows))
    pix = tmp_path / "pix.csv"
    pix.write_text("name,col,row,h\n" + "".join(
        f"p{i},{float(ci)!r},{float(ri)!r},{h0}\n"
        for i, (ci, ri) in enumerate(zip(c, r, strict=True))))
    ground = tmp_path / "ground.csv"
    assert main(["localize", "--model", str(model), "--points", str(pix), "--out",
                 str(ground)]) == 0
    rows_g = _read(ground)
    assert [x["name"] for x in rows_g] == [f"p{i}" for i in range(c.size)]
    sar = family.startswith("sar")
    assert ("azimuth_time_utc" in rows_g[0]) == sar
    lonlat = tmp_path / "lonlat.csv"  # only the ground columns, as a user would give them
    lonlat.write_text("name,lon,lat,h\n" + "".join(
        f"{x['name']},{x['lon']},{x['lat']},{x['h']}\n" for x in rows_g))
    back = tmp_path / "back.csv"
    assert main(["project", "--model", str(model), "--points", str(lonlat), "--out",
                 str(back)]) == 0
    rows_b = _read(back)
    np.testing.assert_allclose([float(x["col"]) for x in rows_b], c, atol=1e-3)
    np.testing.assert_allclose([float(x["row"]) for x in rows_b], r, atol=1e-3)
    if sar:
        for a, b in zip(rows_g, rows_b, strict=True):
            assert a["azimuth_time_utc"][:23] == b["azimuth_time_utc"][:23]  # same ms
            assert abs(float(a["slant_range_time_s"]) - float(b["slant_range_time_s"])) < 1e-12
    assert "points" in capsys.readouterr().out


def test_sar_project_reproduces_the_grid(tmp_path):
    """The annotation's own grid points projected by the command: its line and pixel, its
    azimuth time (ISO 8601 UTC) and slant-range time."""
    a = parse_annotation(GRD.read_text(), GRD.name)
    g = a.grid
    k = np.arange(0, g.line.size, 15)
    pts = tmp_path / "grid.csv"
    pts.write_text("lon,lat,h\n" + "".join(
        f"{float(g.lon_deg[i])!r},{float(g.lat_deg[i])!r},{float(g.h_m[i])!r}\n"
        for i in k))
    out = tmp_path / "out.csv"
    assert main(["project", "--model", str(GRD), "--points", str(pts), "--out", str(out)]) == 0
    rows = _read(out)
    np.testing.assert_allclose([float(x["col"]) for x in rows], g.pixel[k], atol=0.01)
    np.testing.assert_allclose([float(x["row"]) for x in rows], g.line[k], atol=0.25)
    tau = np.array([float(x["slant_range_time_s"]) for x in rows])
    np.testing.assert_allclose(tau, g.slant_range_time_s[k], atol=1e-11)  # 1.5 mm
    times = a.model.utc_of_times(g.azimuth_time_s[k])
    for x, t in zip(rows, times, strict=True):
        assert x["azimuth_time_utc"].endswith("Z")
        dt = np.datetime64(x["azimuth_time_utc"][:-1]) - np.datetime64(t[:-1])
        assert abs(dt / np.timedelta64(1, "us")) <= 5  # 5 us: 3.5 cm along track
