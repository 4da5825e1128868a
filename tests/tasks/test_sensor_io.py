"""read_rpc: source order, crop offsets from pixel-offset geotransforms, errors."""

import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest
import rasterio
from affine import Affine
from rasterio.errors import NotGeoreferencedWarning
from rasterio.windows import Window

from core.errors import InputError
from core.sensors.rpc import RPCModel
from tasks.io.sensors import pixel_offset_of, read_rpc, rpc_from_dimap_file, rpc_from_geom_file

DATA = Path(__file__).resolve().parents[1] / "data"
VENTOUX = DATA / "pleiades_ventoux"
DIMAP = DATA / "dimap" / "RPC_PHR1B_P_201308051042194_SEN_690908101-001.XML"


def _points(m: RPCModel, n: int = 200):
    rng = np.random.default_rng(5)
    return (m.lon_off + 0.5 * m.lon_scale * rng.uniform(-1, 1, n),
            m.lat_off + 0.5 * m.lat_scale * rng.uniform(-1, 1, n),
            m.alt_off + 0.5 * m.alt_scale * rng.uniform(-1, 1, n))


@pytest.mark.parametrize("name,offset", [("left_image", (5000.0, 5000.0)),
                                         ("right_image", (4915.0, 5162.0))])
def test_ventoux_crop_uses_geom_and_geotransform_offset(name, offset):
    full = rpc_from_geom_file(VENTOUX / f"{name}.geom")
    crop = read_rpc(VENTOUX / f"{name}.tif")
    lon, lat, h = _points(full)
    cf, rf = full.project(lon, lat, h)
    cc, rc = crop.project(lon, lat, h)
    np.testing.assert_allclose(cc, cf - offset[0], atol=1e-7)
    np.testing.assert_allclose(rc, rf - offset[1], atol=1e-7)


def test_ventoux_crop_lands_inside_the_crop():
    """The crop's centre localised at the RPC's mean height reprojects inside the 500x500 crop,
    i.e. the offset has the right sign and size."""
    m = read_rpc(VENTOUX / "left_image.tif")
    lon, lat = m.localize(249.5, 249.5, 1000.0)
    c, r = m.project(lon, lat, 1000.0)
    assert abs(c - 249.5) < 1e-6 and abs(r - 249.5) < 1e-6
    assert abs(lon - 5.19) < 0.1 and abs(lat - 44.2) < 0.1


def _write(path: Path, data: np.ndarray, transform: Affine | None = None, rpcs=None) -> None:
    profile = {"driver": "GTiff", "width": data.shape[1], "height": data.shape[0], "count": 1,
               "dtype": data.dtype}
    if transform is not None:
        profile["transform"] = transform
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NotGeoreferencedWarning)
        with rasterio.open(path, "w", **profile) as dst:
            dst.write(data, 1)
            if rpcs is not None:
                dst.update_tags(ns="RPC", **rpcs)


def test_crop_offset_convention_empirically(tmp_path):
    """A crop written as gdal_translate -srcwin would (rasterio window_transform of an
    ungeoreferenced raster) holds, at its pixel (0, 0), full-image pixel (c, f) of its
    geotransform: no half-pixel term. read_rpc follows that."""
    rows, cols = np.mgrid[0:60, 0:80]
    full = (rows * 1000 + cols).astype(np.int32)
    _write(tmp_path / "full.tif", full)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NotGeoreferencedWarning)
        with rasterio.open(tmp_path / "full.tif") as src:
            win = Window(col_off=13, row_off=21, width=30, height=25)
            crop_data = src.read(1, window=win)
            crop_tf = src.window_transform(win)
    _write(tmp_path / "crop.tif", crop_data, crop_tf)
    assert (crop_tf.c, crop_tf.f) == (13.0, 21.0)
    assert crop_data[0, 0] == full[21, 13]  # crop (0,0) is full-image pixel (col 13, row 21)

    for stem in ("full", "crop"):
        shutil.copy(VENTOUX / "left_image.geom", tmp_path / f"{stem}.geom")
    m_full, m_crop = read_rpc(tmp_path / "full.tif"), read_rpc(tmp_path / "crop.tif")
    # a ground point seen at full-image pixel (col 30, row 40) ...
    lon, lat = m_full.localize(30.0, 40.0, 900.0)
    c, r = m_crop.project(lon, lat, 900.0)
    # ... is at the crop pixel holding the same image sample
    ci, ri = round(float(c)), round(float(r))
    assert abs(c - ci) < 1e-6 and abs(r - ri) < 1e-6
    assert crop_data[ri, ci] == full[40, 30]


def test_reunion_rpc_tags_identity_transform():
    path = DATA / "pleiades_reunion" / "img_01.tif"
    m = read_rpc(path)
    with rasterio.open(path) as src:
        assert m.col_off == float(src.tags(ns="RPC")["SAMP_OFF"])
        h, w = src.shape
    # the RPC, already re-normalised to the 1024x1024 crop, localises it around Reunion
    lon, lat = m.localize([0.0, w - 1.0], [0.0, h - 1.0], 1295.0)
    assert np.all(np.abs(lon - 55.6) < 0.3) and np.all(np.abs(lat + 21.2) < 0.3)


def test_explicit_dimap_wins_and_is_offset(tmp_path):
    data = np.zeros((4, 5), dtype=np.uint8)
    _write(tmp_path / "crop.tif", data, Affine.translation(100, 200))
    m = read_rpc(tmp_path / "crop.tif", model_file=DIMAP)
    full = rpc_from_dimap_file(DIMAP)
    assert m.has_inverse
    assert m.col_off == pytest.approx(full.col_off - 100)
    assert m.row_off == pytest.approx(full.row_off - 200)


def test_no_rpc_found(tmp_path):
    _write(tmp_path / "plain.tif", np.zeros((4, 5), dtype=np.uint8))
    with pytest.raises(InputError, match="no sensor model found.*plain.tif"):
        read_rpc(tmp_path / "plain.tif")


def test_missing_image(tmp_path):
    with pytest.raises(InputError, match="nope.tif does not exist"):
        read_rpc(tmp_path / "nope.tif")


def test_bad_geom_names_file_and_key(tmp_path):
    _write(tmp_path / "a.tif", np.zeros((4, 5), dtype=np.uint8))
    (tmp_path / "a.geom").write_text("line_off: 10\n")
    with pytest.raises(InputError, match=r"a\.geom.*samp_off"):
        read_rpc(tmp_path / "a.tif")
    (tmp_path / "a.geom").write_text("")
    with pytest.raises(InputError, match="empty"):
        read_rpc(tmp_path / "a.tif")


def test_bad_rpc_tags(tmp_path):
    tags = rpc_from_geom_file(VENTOUX / "left_image.geom").to_gdal_tags()
    tags["LINE_NUM_COEFF"] = "1 2 3"  # GDAL's GeoTIFF writer silently stores 20 zeros
    _write(tmp_path / "t.tif", np.zeros((4, 5), dtype=np.uint8), rpcs=tags)
    with pytest.raises(InputError, match="LINE_NUM_COEFF.*all zero"):
        read_rpc(tmp_path / "t.tif")


def test_pixel_offset_of():
    assert pixel_offset_of(Affine.identity(), has_crs=False) == (0.0, 0.0)
    assert pixel_offset_of(Affine.translation(5000, 5000), has_crs=False) == (5000.0, 5000.0)
    assert pixel_offset_of(Affine(0.5, 0, 300000, 0, -0.5, 5e6), has_crs=True) == (0.0, 0.0)
    with pytest.raises(InputError, match="not a pure pixel"):
        pixel_offset_of(Affine(2, 0, 10, 0, 2, 10), has_crs=False)


# -- load_model: the model of an image, found as ASP finds it ------------------------------------
def _blank(path: Path, width: int, height: int) -> Path:
    """A raw (unreferenced) uint8 image, as a Level 1A scene is."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NotGeoreferencedWarning)
        with rasterio.open(path, "w", driver="GTiff", width=width, height=height, count=1,
                           dtype="uint8") as dst:
            dst.write(np.zeros((height, width), np.uint8), 1)
    return path


@pytest.fixture(scope="module")
def spot_scene_files(tmp_path_factory):
    """A small SPOT-like model written as JSON and as METADATA.DIM, and a blank image."""
    from core.sensors.pushbroom_synthetic import SyntheticSpec, synthetic_pushbroom
    from core.sensors.spot import spot_scene_from_model
    from tasks.io.dimap import write_dimap

    d = tmp_path_factory.mktemp("spot")
    m = synthetic_pushbroom(SyntheticSpec(5.2, 44.2, n_cols=300, n_rows=200, gsd_m=20.0,
                                          incidence_deg=12.0, epoch_utc="2001-05-04T10:00:00Z"))
    (d / "scene").mkdir()
    _blank(d / "scene" / "IMAGERY.TIF", 300, 200)
    write_dimap(spot_scene_from_model(m), d / "scene" / "METADATA.DIM")
    return d, m


def test_imagery_tif_finds_metadata_dim_beside_it(spot_scene_files):
    from tasks.io.sensors import load_model

    d, m = spot_scene_files
    loaded = load_model(d / "scene" / "IMAGERY.TIF")
    assert loaded.family == "pushbroom" and loaded.source.name == "METADATA.DIM"
    assert loaded.size == (300, 200) and loaded.spot is not None and loaded.band == 1
    lon, lat = m.localize(np.array([0.0, 150.0, 299.0]), np.array([0.0, 100.0, 199.0]), 500.0)
    c, r = loaded.model.project(lon, lat, 500.0)
    np.testing.assert_allclose(c, [0.0, 150.0, 299.0], atol=1e-3)
    np.testing.assert_allclose(r, [0.0, 100.0, 199.0], atol=1e-3)
    # the .DIM alone, and as --model of another image of the same size
    assert load_model(d / "scene" / "METADATA.DIM").family == "pushbroom"
    shutil.copy(d / "scene" / "IMAGERY.TIF", d / "other.tif")
    assert load_model(d / "other.tif", model=d / "scene" / "METADATA.DIM").image == d / "other.tif"


def test_same_name_dim_json_then_rpc_and_errors(spot_scene_files, tmp_path):
    from tasks.io.sensors import load_model

    d, m = spot_scene_files
    img = tmp_path / "left.tif"
    shutil.copy(d / "scene" / "IMAGERY.TIF", img)
    (tmp_path / "left.json").write_text(m.to_json())
    assert load_model(img).source.name == "left.json"  # a gcpfree pushbroom model
    shutil.copy(d / "scene" / "METADATA.DIM", tmp_path / "left.DIM")
    assert load_model(img).source.name == "left.DIM"  # SPOT metadata win
    assert load_model(VENTOUX / "left_image.tif").family == "rpc"
    small = _blank(tmp_path / "small.tif", 10, 10)
    with pytest.raises(InputError, match="not the same image"):
        load_model(small, model=tmp_path / "left.DIM")
    with pytest.raises(InputError, match="does not exist"):
        load_model(tmp_path / "none.tif")
    (tmp_path / "m.txt").write_text("x")
    with pytest.raises(InputError, match="unknown model format"):
        load_model(small, model=tmp_path / "m.txt")


def test_a_model_file_carries_the_sun_of_its_metadata(spot_scene_files, tmp_path):
    """A gcpfree model file may carry the sun its metadata stated (``gcpfree orient`` writes
    it): read back as ``LoadedModel.sun``, as a ``.DIM``'s is (the orient flow's test: the
    tiny pair's); none without the key; a damaged one refused in one line naming the key."""
    import json

    from tasks.io.sensors import SUN_KEY, load_model, sun_to_dict

    d, m = spot_scene_files
    assert load_model(d / "scene" / "METADATA.DIM").sun is None  # this .DIM states none
    path = tmp_path / "left.json"
    path.write_text(json.dumps({**m.to_dict(), **sun_to_dict((140.25, 63.5))}))
    assert load_model(path).sun == (140.25, 63.5)
    path.write_text(m.to_json())
    assert load_model(path).sun is None and sun_to_dict(None) == {}
    for bad in ({"azimuth_deg": 140.0}, {"azimuth_deg": 1.0, "elevation_deg": 95.0}, "east"):
        path.write_text(json.dumps({**m.to_dict(), SUN_KEY: bad}))
        with pytest.raises(InputError, match=f"{path}: pushbroom model: key 'sun") as err:
            load_model(path)
        assert "\n" not in str(err.value) and str(err.value).count(str(path)) == 1
