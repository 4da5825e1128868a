"""tasks.io.sensor_info: the reference DEM reader, the report of one image (against GDAL's RPC
transformer and real SPOT metadata) and of a real stereo pair."""

import json
from datetime import datetime, timedelta
from pathlib import Path

import numpy as np
import pytest
import rasterio
from rasterio.transform import RPCTransformer, from_origin

from core.errors import CoverageError, InputError
from core.geodesy import BBox
from core.sensors.pushbroom_synthetic import SyntheticSpec, synthetic_pushbroom
from tasks.io.dem import check_reference, read_reference
from tasks.io.geoid import BUNDLED_SRTM_DIR, load_geoid
from tasks.io.sensor_info import describe_image, gather_info, write_info_json

DATA = Path(__file__).resolve().parents[1] / "data"
VENTOUX = DATA / "pleiades_ventoux"
REUNION = DATA / "pleiades_reunion"
SRTM_TILE = BUNDLED_SRTM_DIR / "N44E005.hgt"
SHARED = Path(__file__).resolve().parents[3] / "shared" / "data" / "spot_dimap"
REAL_SPOT = pytest.mark.skipif(not SHARED.is_dir(), reason="../shared/data/spot_dimap is absent")
CORNERS = [(0, 0), (1, 0), (1, 1), (0, 1)]  # in units of (cols-1, rows-1)


def write_geotiff(path: Path, h: np.ndarray, west: float, north: float, res: float) -> Path:
    with rasterio.open(path, "w", driver="GTiff", width=h.shape[1], height=h.shape[0], count=1,
                       dtype="float32", crs="EPSG:4326", nodata=np.nan,
                       transform=from_origin(west, north, res, res)) as dst:
        dst.write(h.astype(np.float32), 1)
    return path


@pytest.fixture(scope="module")
def synthetic_json(tmp_path_factory) -> Path:
    m = synthetic_pushbroom(SyntheticSpec(5.25, 44.2, n_cols=300, n_rows=200, gsd_m=40.0,
                                          incidence_deg=10.0))
    path = tmp_path_factory.mktemp("model") / "scene.json"
    path.write_text(m.to_json())
    return path


# ------------------------------------------------------------------------- reference


def test_reference_window_in_egm96_is_converted_to_ellipsoidal_heights():
    box = BBox(5.20, 44.15, 5.30, 44.25)
    h = read_reference(SRTM_TILE, box, "egm96")
    raw = read_reference(SRTM_TILE, box, "ellipsoidal")
    lon, lat = 5.2786, 44.1742  # Mont Ventoux
    with rasterio.open(SRTM_TILE) as src:
        H = float(next(src.sample([(lon, lat)]))[0])
    n = float(load_geoid().undulation_m(lon, lat))
    assert float(raw.height_m(lon, lat)) == pytest.approx(H, abs=15.0)  # bilinear vs nearest
    assert float(h.height_m(lon, lat) - raw.height_m(lon, lat)) == pytest.approx(n, abs=0.01)
    assert 1850 < H < 1912 and 50 < n < 52
    lo0, la0, lo1, la1 = h.bounds_deg()
    assert lo0 <= 5.2 and la0 <= 44.15 and lo1 >= 5.3 and la1 >= 44.25


def test_reference_errors(tmp_path):
    with pytest.raises(CoverageError, match="does not cover"):
        read_reference(SRTM_TILE, BBox(10.0, 44.0, 10.5, 44.5), "egm96")
    with pytest.raises(InputError, match="does not exist"):
        check_reference(tmp_path / "missing.tif")
    bad = tmp_path / "ref.tif"
    bad.write_text("not a raster")
    with pytest.raises(InputError, match="cannot read"):
        check_reference(bad)
    utm = tmp_path / "utm.tif"
    with rasterio.open(utm, "w", driver="GTiff", width=4, height=4, count=1, dtype="float32",
                       crs="EPSG:32631", transform=from_origin(600000, 4900000, 30, 30)) as dst:
        dst.write(np.zeros((1, 4, 4), np.float32))
    with pytest.raises(InputError, match="EPSG:4326"):
        check_reference(utm)


# ------------------------------------------------------------------------- one image


def test_model_file_alone_with_a_flat_ellipsoidal_reference(synthetic_json, tmp_path):
    ref = write_geotiff(tmp_path / "flat.tif", np.full((200, 200), 650.0), 4.5, 45.0, 0.01)
    # an untagged, non-SRTM DEM says nothing of its datum: refused unless given
    with pytest.raises(InputError, match="--reference-vertical egm96"):
        describe_image(synthetic_json, reference=ref)
    info = describe_image(synthetic_json, reference=ref, vertical="ellipsoidal")
    d = info.to_dict()
    assert d["family"] == "pushbroom" and d["size"] == {"cols": 300, "rows": 200}
    assert d["image"] is None and d["acquisition_utc"].startswith("2024-06-01T10:")
    assert d["reference"]["vertical"] == "ellipsoidal"
    assert d["reference"]["vertical_source"] == "given: --reference-vertical ellipsoidal"
    assert d["reference"]["mean_h_m"] == pytest.approx(650.0)
    assert d["reference"]["covered_pct"] == 100.0
    assert d["view_h_m"] == pytest.approx(650.0)
    m = info.loaded.model
    for key, h in (("corners", 0.0), ("reference", 650.0)):
        corners = d[key] if key == "corners" else d[key]["corners"]
        assert [(c["col"], c["row"]) for c in corners] == [(299 * a, 199 * b) for a, b in CORNERS]
        col, row = m.project([c["lon_deg"] for c in corners], [c["lat_deg"] for c in corners],
                             np.full(4, h))
        np.testing.assert_allclose(col, [c["col"] for c in corners], atol=1e-6)
        np.testing.assert_allclose(row, [c["row"] for c in corners], atol=1e-6)
    assert d["incidence_deg"] == pytest.approx(10.0, abs=0.1)
    assert d["gsd_m"]["across"] == pytest.approx(40.0, rel=1e-3)
    assert d["metadata_corner_check_m"] is None and d["mission"] is None


@pytest.mark.parametrize("name", ["img_01.tif", "img_02.tif"])
def test_rpc_corners_agree_with_gdal(name):
    """GDAL's RPC transformer, on the raster's own RPC tags, puts the corner pixel centres
    (GDAL pixel = ours + 0.5) where info says."""
    info = describe_image(REUNION / name)
    d = info.to_dict()
    assert d["family"] == "rpc"
    with rasterio.open(REUNION / name) as src:
        rpcs, (w, h) = src.rpcs, (src.width, src.height)
    assert d["size"] == {"cols": w, "rows": h}
    rows = [c["row"] for c in d["corners"]]
    cols = [c["col"] for c in d["corners"]]
    with RPCTransformer(rpcs) as tr:
        lon, lat = tr.xy(rows, cols, zs=[0.0] * 4, offset="center")
    # 1e-7 deg is about 1 cm: GDAL's iterative inverse stops a little short of ours
    np.testing.assert_allclose([c["lon_deg"] for c in d["corners"]], lon, atol=1e-7)
    np.testing.assert_allclose([c["lat_deg"] for c in d["corners"]], lat, atol=1e-7)
    # Pleiades: 0.5 m pixels (about 0.7 m native, resampled), view angle under 30 deg
    assert 0.4 < d["gsd_m"]["across"] < 0.8 and 0.4 < d["gsd_m"]["along"] < 0.8
    assert 0 < d["incidence_deg"] < 30
    assert d["view_h_m"] == pytest.approx(info.loaded.model.alt_off)


@REAL_SPOT
@pytest.mark.parametrize("name,max_m", [("SPOT5.DIM", 1.0), ("SPOT2.DIM", 5.0)])
def test_real_spot_metadata(name, max_m):
    info = describe_image(SHARED / name)
    d = info.to_dict()
    spot = info.loaded.spot
    check = d["metadata_corner_check_m"]
    assert check["max"] < max_m and len(check["points"]) == 5
    assert check["max"] == max(p["error_m"] for p in check["points"])
    assert d["mission"] == f"SPOT {spot.mission_index}" and d["family"] == "pushbroom"
    # the time of the centre row is the stated scene centre time (within a line)
    epoch = datetime.fromisoformat(spot.epoch_utc.replace("Z", "+00:00"))
    stated = epoch + timedelta(seconds=spot.centre_time_s)
    got = datetime.fromisoformat(d["acquisition_utc"].replace("Z", "+00:00"))
    assert abs((got - stated).total_seconds()) <= spot.line_period_s
    # our corners at h = 0 are within a few tens of metres of the stated ones (the stated
    # ones are computed as the producer did, SPOT 1-4 without the measured attitude)
    stated_corners = [(p.lon_deg, p.lat_deg) for p in spot.frame[:4]]
    ours = [(c["lon_deg"], c["lat_deg"]) for c in d["corners"]]
    assert np.max(np.abs(np.subtract(ours, stated_corners))) < 5e-4
    assert d["gsd_m"]["across"] == pytest.approx(10.0 if spot.mission_index < 5 else 5.0,
                                                 rel=0.05)


@REAL_SPOT
def test_spot2_incidence_is_the_stated_one():
    """SPOT 1-4 state the incidence at the scene centre, signed (negative: satellite east)."""
    d = describe_image(SHARED / "SPOT2.DIM").to_dict()
    stated = d["stated"]["incidence_deg"]
    assert d["incidence_deg"] == pytest.approx(abs(stated), abs=0.01)
    assert np.sign(d["across_track_incidence_deg"]) == np.sign(stated)


# ------------------------------------------------------------------------- pairs


def test_real_ventoux_pair_is_a_plausible_stereo_pair():
    """A real Pleiades pair: along-track stereo (the satellite north, then south of the
    scene), B/H between the usual 0.15 and 0.8 of Pleiades stereo. Without a reference the
    crops overlap where their centre lines of sight meet (they were cut around h = 50 m)."""
    r = gather_info(VENTOUX / "left_image.tif", VENTOUX / "right_image.tif")
    p = r.to_dict()["pair"]
    assert 0.15 < p["b_over_h"] < 0.8 and 10 < p["convergence_deg"] < 40
    assert p["b_over_h"] == pytest.approx(2 * np.tan(np.radians(p["convergence_deg"]) / 2))
    assert p["overlap_pct"] > 90 and "meet" in p["height"]
    i1, i2 = p["image1"], p["image2"]
    assert abs(((i1["azimuth_deg"] - i2["azimuth_deg"]) % 360) - 180) < 20  # opposite sides
    assert p["convergence_deg"] == pytest.approx(i1["incidence_deg"] + i2["incidence_deg"],
                                                 abs=1.0)
    with_ref = gather_info(VENTOUX / "left_image.tif", VENTOUX / "right_image.tif",
                           reference=SRTM_TILE).to_dict()
    q = with_ref["pair"]
    assert q["h_m"] == pytest.approx(with_ref["reference"]["mean_h_m"])
    assert 450 < q["h_m"] < 700  # the SRTM under the crops (H about 470 m, N about 51 m)
    assert q["convergence_deg"] == pytest.approx(p["convergence_deg"], abs=0.1)
    assert q["overlap_pct"] < p["overlap_pct"]


def test_json_is_strict_and_written_atomically(tmp_path):
    r = gather_info(REUNION / "img_01.tif", REUNION / "img_02.tif")
    out = write_info_json(r, tmp_path / "sub" / "info.json")
    d = json.loads(out.read_text())
    assert d["format"] == "gcpfree.info" and d["image2"]["size"] == {"cols": 1031, "rows": 1102}
    assert set(d["pair"]) >= {"b_over_h", "convergence_deg", "overlap_pct", "h_m"}
    assert [p.name for p in out.parent.iterdir()] == ["info.json"]
    lines = r.lines()
    assert any(line.startswith("pair ") and "B/H" in line for line in lines)


def test_gather_info_input_errors():
    with pytest.raises(InputError, match="IMAGE2"):
        gather_info(REUNION / "img_01.tif", model2=REUNION / "img_02.tif")
    with pytest.raises(InputError, match="starts at 1"):
        gather_info(REUNION / "img_01.tif", band=0)
    with pytest.raises(InputError, match="does not exist"):
        gather_info(REUNION / "nothing.tif")
