"""RPCModel: agreement with GDAL's RPC transformer on real vendor RPCs, exact localisation,
bias, crop offsets, readers and writers, and errors on bad input."""

import json
from pathlib import Path

import numpy as np
import pytest
import rasterio
from rasterio.rpc import RPC
from rasterio.transform import RPCTransformer

from core.dem import GeoDEM
from core.errors import ConvergenceError, InputError
from core.sensors.base import SensorModel
from core.sensors.rpc import RPCModel
from core.sensors.rpc00b import rational_functions

DATA = Path(__file__).resolve().parents[2] / "data"
DIMAP_VENTOUX = DATA / "dimap" / "RPC_PHR1B_P_201308051042194_SEN_690908101-001.XML"
GEOM_FILES = [
    DATA / "pleiades_ventoux" / "left_image.geom",
    DATA / "pleiades_ventoux" / "right_image.geom",
    DATA / "pleiades_gizeh" / "img1.geom",
    DATA / "pleiades_gizeh" / "img2.geom",
]
TIF_FILES = [DATA / "pleiades_reunion" / "img_01.tif", DATA / "pleiades_reunion" / "img_02.tif"]


def load(path: Path) -> RPCModel:
    if path.suffix == ".geom":
        return RPCModel.from_geom(path.read_text())
    if path.suffix == ".XML":
        return RPCModel.from_dimap_xml(path.read_text())
    with rasterio.open(path) as src:
        return RPCModel.from_gdal_tags(src.tags(ns="RPC"))


REAL = [pytest.param(p, id=f"{p.parent.name}/{p.name}") for p in GEOM_FILES + TIF_FILES]
REAL_ALL = REAL + [pytest.param(DIMAP_VENTOUX, id="dimap/ventoux")]


def domain_points(m: RPCModel, n: int = 10_000, seed: int = 0):
    """Points spanning the RPC's lon/lat/height normalisation domain ([-1, 1]^3)."""
    rng = np.random.default_rng(seed)
    lon = m.lon_off + m.lon_scale * rng.uniform(-1, 1, n)
    lat = m.lat_off + m.lat_scale * rng.uniform(-1, 1, n)
    h = m.alt_off + m.alt_scale * rng.uniform(-1, 1, n)
    return lon, lat, h


@pytest.fixture(scope="module")
def ventoux() -> RPCModel:
    return load(GEOM_FILES[0])


# ---------------------------------------------------------------- real RPCs


@pytest.mark.parametrize("path", REAL)
def test_project_agrees_with_gdal(path):
    m = load(path)
    lon, lat, h = domain_points(m)
    col, row = m.project(lon, lat, h)
    with RPCTransformer(RPC.from_gdal(m.to_gdal_tags())) as tr:
        g_row, g_col = tr.rowcol(lon, lat, zs=h, op=np.positive)
    # GDAL reports pixel-corner coordinates: its pixel centres sit at ours + 0.5
    assert np.max(np.abs(g_col - 0.5 - col)) < 1e-3
    assert np.max(np.abs(g_row - 0.5 - row)) < 1e-3


@pytest.mark.parametrize("path", TIF_FILES, ids=lambda p: p.name)
def test_project_agrees_with_gdal_on_raw_file_tags(path):
    """The raster's own RPC object (rasterio ``src.rpcs``), not our re-written tags."""
    m = load(path)
    with rasterio.open(path) as src:
        rpcs = src.rpcs
    lon, lat, h = domain_points(m, 2000, seed=3)
    col, row = m.project(lon, lat, h)
    with RPCTransformer(rpcs) as tr:
        g_row, g_col = tr.rowcol(lon, lat, zs=h, op=np.positive)
    assert np.max(np.hypot(g_col - 0.5 - col, g_row - 0.5 - row)) < 1e-3


@pytest.mark.parametrize("path", REAL_ALL)
def test_localize_round_trip(path):
    m = load(path)
    rng = np.random.default_rng(1)
    n = 10_000
    col = m.col_off + 0.95 * m.col_scale * rng.uniform(-1, 1, n)
    row = m.row_off + 0.95 * m.row_scale * rng.uniform(-1, 1, n)
    h = m.alt_off + m.alt_scale * rng.uniform(-1, 1, n)
    lon, lat = m.localize(col, row, h)
    c2, r2 = m.project(lon, lat, h)
    assert np.max(np.hypot(c2 - col, r2 - row)) < 1e-4


@pytest.mark.parametrize("path", REAL)
def test_localize_recovers_ground(path):
    m = load(path)
    lon, lat, h = domain_points(m, 2000, seed=2)
    lon2, lat2 = m.localize(*m.project(lon, lat, h), h)
    assert np.max(np.abs(lon2 - lon)) < 1e-9
    assert np.max(np.abs(lat2 - lat)) < 1e-9


def test_dimap_is_one_based_and_matches_the_geom_of_the_same_image(ventoux):
    """Ventoux left image 690908101-001: DIMAP offsets are the .geom ones + 1; after the -1
    both project identically, which pins the DIMAP 1-based and OSSIM 0-based conventions."""
    d = load(DIMAP_VENTOUX)
    assert d.col_off == pytest.approx(ventoux.col_off)
    assert d.row_off == pytest.approx(ventoux.row_off)
    lon, lat, h = domain_points(ventoux)
    c1, r1 = ventoux.project(lon, lat, h)
    c2, r2 = d.project(lon, lat, h)
    assert np.max(np.hypot(c1 - c2, r1 - r2)) < 1e-6


def test_dimap_direct_model_is_image_to_ground_and_only_approximate():
    d = load(DIMAP_VENTOUX)
    assert d.has_inverse
    lon, lat, h = domain_points(d, 2000)
    col, row = d.project(lon, lat, h)
    # the vendor inverse alone (the formula of the module docstring): close (a few
    # thousandths of a pixel) but not exact
    z = (h - d.alt_off) / d.alt_scale
    inverse = np.stack([d.lon_num, d.lon_den, d.lat_num, d.lat_den])
    x, y = rational_functions(inverse, (col - d.col_off) / d.col_scale,
                              (row - d.row_off) / d.row_scale, z)
    c_v, r_v = d.project(x * d.lon_scale + d.lon_off, y * d.lat_scale + d.lat_off, h)
    err_vendor = np.max(np.hypot(c_v - col, r_v - row))
    assert 1e-5 < err_vendor < 0.05
    # localize refines it
    c_n, r_n = d.project(*d.localize(col, row, h), h)
    assert np.max(np.hypot(c_n - col, r_n - row)) < 1e-6


def test_localize_without_inverse_agrees_with_inverse():
    d = load(DIMAP_VENTOUX)
    fwd = RPCModel.from_dict({k: v for k, v in d.to_dict().items() if not k.startswith("l")
                              or k in ("lon_off", "lon_scale", "lat_off", "lat_scale")})
    assert not fwd.has_inverse
    col = np.array([0.0, 10_000.0, 39_181.0])
    row = np.array([0.0, 20_000.0, 41_800.0])
    a = d.localize(col, row, 500.0)
    b = fwd.localize(col, row, 500.0)
    np.testing.assert_allclose(a, b, atol=1e-10)


def test_is_a_sensor_model(ventoux):
    assert isinstance(ventoux, SensorModel)


# ---------------------------------------------------------------- shapes and edge cases


def test_scalars_and_broadcasting(ventoux):
    c, r = ventoux.project(5.28, 44.13, 1000.0)
    assert c.shape == () and r.shape == ()
    c, r = ventoux.project(np.full((3, 1), 5.28), np.linspace(44.1, 44.2, 4), 1000.0)
    assert c.shape == (3, 4)
    lon, lat = ventoux.localize(c, r, np.full((3, 4), 1000.0))
    assert lon.shape == (3, 4)
    np.testing.assert_allclose(lat[0], np.linspace(44.1, 44.2, 4), atol=1e-10)


def test_nan_propagates(ventoux):
    lon, lat = ventoux.localize([np.nan, 19000.0], [100.0, 20000.0], 800.0)
    assert np.isnan(lon[0]) and np.isnan(lat[0])
    assert np.isfinite(lon[1]) and np.isfinite(lat[1])


def test_convergence_error_counts_points(ventoux):
    with pytest.raises(ConvergenceError, match="3 of 3 points"):
        ventoux.localize([0.0, 1.0, 2.0], [0.0, 1.0, 2.0], 500.0, max_iter=0)


def test_far_outside_the_domain_raises_convergence_error():
    d = load(DIMAP_VENTOUX)
    with pytest.raises(ConvergenceError, match="1 of 2 points"):
        d.localize([1e9, 100.0], [1e9, 100.0], 500.0)


def test_a_wrong_inverse_polynomial_still_localizes_exactly():
    kw = load(DIMAP_VENTOUX).to_dict()
    kw["lon_num"] = (np.array(kw["lon_num"]) * 40).tolist()
    kw["lat_den"] = (np.array(kw["lat_den"]) + 0.9).tolist()
    bad = RPCModel.from_dict(kw)
    col, row = np.linspace(0, 39_000, 50), np.linspace(0, 41_000, 50)
    c, r = bad.project(*bad.localize(col, row, 500.0), 500.0)
    assert np.max(np.hypot(c - col, r - row)) < 1e-6


def test_localize_on_dem_flat(ventoux):
    lon0, lat0 = ventoux.lon_off, ventoux.lat_off
    g = np.arange(-0.05, 0.05001, 0.001)
    dem = GeoDEM(np.full((g.size, g.size), 700.0), lon0 - 0.05, lat0 + 0.05, 0.001, -0.001)
    col, row = ventoux.project(lon0 + np.array([0.0, 0.01]), lat0 + np.array([0.0, -0.02]),
                               700.0)
    lon, lat, h = ventoux.localize_on_dem(col, row, dem)
    np.testing.assert_allclose(h, 700.0, atol=2e-3)
    np.testing.assert_allclose(lon, lon0 + np.array([0.0, 0.01]), atol=1e-7)
    np.testing.assert_allclose(lat, lat0 + np.array([0.0, -0.02]), atol=1e-7)


# ---------------------------------------------------------------- bias


def test_shift_bias_moves_projection(ventoux):
    m = ventoux.with_bias_mode("shift").with_params([2.5, -1.25])
    np.testing.assert_array_equal(m.params, [2.5, -1.25])
    lon, lat, h = domain_points(ventoux, 500)
    c0, r0 = ventoux.project(lon, lat, h)
    c1, r1 = m.project(lon, lat, h)
    np.testing.assert_allclose(c1 - c0, 2.5, atol=1e-9)
    np.testing.assert_allclose(r1 - r0, -1.25, atol=1e-9)
    lon2, lat2 = m.localize(c1, r1, h)
    np.testing.assert_allclose(lon2, lon, atol=1e-10)
    np.testing.assert_allclose(lat2, lat, atol=1e-10)


def test_affine_bias_follows_its_definition(ventoux):
    """Affine terms in pixels, on the image coordinates normalised by the RPC's own offsets and
    scales (module docstring)."""
    p = np.array([3.0, 2.5, -1.5, -4.0, 0.75, 1.25])
    m = ventoux.with_bias_mode("affine").with_params(p)
    lon, lat, h = domain_points(ventoux, 500)
    c0, r0 = ventoux.project(lon, lat, h)
    c1, r1 = m.project(lon, lat, h)
    cn = (c0 - ventoux.col_off) / ventoux.col_scale
    rn = (r0 - ventoux.row_off) / ventoux.row_scale
    np.testing.assert_allclose(c1, c0 + p[0] + p[1] * cn + p[2] * rn, atol=1e-8)
    np.testing.assert_allclose(r1, r0 + p[3] + p[4] * cn + p[5] * rn, atol=1e-8)
    lon2, lat2 = m.localize(c1, r1, h)
    np.testing.assert_allclose(lon2, lon, atol=1e-10)
    np.testing.assert_allclose(lat2, lat, atol=1e-10)
    c2, r2 = m.project(lon2, lat2, h)
    assert np.max(np.hypot(c2 - c1, r2 - r1)) < 1e-6


def test_bias_modes_and_params_checks(ventoux):
    assert ventoux.params.size == 0
    with pytest.raises(InputError, match="takes 2 parameters"):
        ventoux.with_bias_mode("shift").with_params([1.0, 2.0, 3.0])
    with pytest.raises(InputError, match="bias_mode"):
        ventoux.with_bias_mode("quadratic")
    aff = ventoux.with_bias_mode("shift").with_params([1.0, 2.0]).with_bias_mode("affine")
    np.testing.assert_array_equal(aff.params, [1.0, 0, 0, 2.0, 0, 0])
    with pytest.raises(InputError, match="cannot be expressed"):
        aff.with_params([1.0, 0.5, 0, 2.0, 0, 0]).with_bias_mode("shift")
    # models are immutable values
    assert ventoux.params.size == 0
    with pytest.raises(ValueError):
        aff.bias[0] = 5.0


# ---------------------------------------------------------------- crop offset


@pytest.mark.parametrize("mode,p", [("none", []), ("shift", [1.5, -0.5]),
                                    ("affine", [1.0, 2.0, -1.0, -2.0, 1.0, 3.0])])
def test_with_image_offset(ventoux, mode, p):
    full = ventoux.with_bias_mode(mode).with_params(p)
    crop = full.with_image_offset(5000, 4000)
    lon, lat, h = domain_points(ventoux, 500)
    cf, rf = full.project(lon, lat, h)
    cc, rc = crop.project(lon, lat, h)
    np.testing.assert_allclose(cc, cf - 5000, atol=1e-7)
    np.testing.assert_allclose(rc, rf - 4000, atol=1e-7)
    lon2, lat2 = crop.localize(cc, rc, h)
    np.testing.assert_allclose(lon2, lon, atol=1e-10)
    np.testing.assert_allclose(lat2, lat, atol=1e-10)


# ---------------------------------------------------------------- writers


def test_gdal_tags_round_trip_with_units_and_folded_shift(ventoux):
    tags = ventoux.to_gdal_tags()
    assert set(tags) >= {"LINE_OFF", "SAMP_SCALE", "LONG_OFF", "HEIGHT_SCALE", "LINE_NUM_COEFF"}
    tags["LINE_OFF"] += " pixels"
    tags["HEIGHT_OFF"] += " meters"
    m = RPCModel.from_gdal_tags(tags)
    lon, lat, h = domain_points(ventoux, 500)
    np.testing.assert_array_equal(m.project(lon, lat, h), ventoux.project(lon, lat, h))

    shifted = ventoux.with_bias_mode("shift").with_params([3.0, -2.0])
    folded = RPCModel.from_gdal_tags(shifted.to_gdal_tags())
    np.testing.assert_allclose(folded.project(lon, lat, h), shifted.project(lon, lat, h),
                               atol=1e-8)


def test_gdal_tags_affine_bias(ventoux):
    lon, lat, h = domain_points(ventoux, 500)
    diag = ventoux.with_bias_mode("affine").with_params([1.0, 2.0, 0.0, 2.0, 0.0, -1.5])
    folded = RPCModel.from_gdal_tags(diag.to_gdal_tags())
    np.testing.assert_allclose(folded.project(lon, lat, h), diag.project(lon, lat, h), atol=1e-7)
    cross = diag.with_params([1.0, 2.0, 0.1, 2.0, 0.0, -1.5])
    with pytest.raises(InputError, match="cross terms"):
        cross.to_gdal_tags()


def test_dict_json_round_trip():
    d = load(DIMAP_VENTOUX).with_bias_mode("affine").with_params([1, 2e-5, 3e-5, 4, 5e-5, 6e-5])
    back = RPCModel.from_dict(json.loads(json.dumps(d.to_dict())))
    assert back.bias_mode == "affine" and back.has_inverse
    np.testing.assert_array_equal(back.params, d.params)
    for name in ("col_num", "row_den", "lon_num", "lat_den"):
        np.testing.assert_array_equal(getattr(back, name), getattr(d, name))
    assert back.col_off == d.col_off


# ---------------------------------------------------------------- bad input


GEOM_TEXT = GEOM_FILES[0].read_text()


def test_geom_missing_key():
    text = "\n".join(li for li in GEOM_TEXT.splitlines() if not li.startswith("samp_scale"))
    with pytest.raises(InputError, match="samp_scale"):
        RPCModel.from_geom(text)


def test_geom_missing_coefficient():
    text = "\n".join(li for li in GEOM_TEXT.splitlines()
                     if not li.startswith("line_den_coeff_07"))
    with pytest.raises(InputError, match="line_den_coeff_07"):
        RPCModel.from_geom(text)


def test_geom_non_numeric():
    text = GEOM_TEXT.replace("lat_off:  44.1371659937345", "lat_off:  north")
    with pytest.raises(InputError, match="lat_off"):
        RPCModel.from_geom(text)


@pytest.mark.parametrize("text", ["", "   \n\n"])
def test_geom_empty(text):
    with pytest.raises(InputError, match="empty"):
        RPCModel.from_geom(text)


def test_geom_polynomial_format_a_refused():
    with pytest.raises(InputError, match="polynomial_format"):
        RPCModel.from_geom(GEOM_TEXT.replace("polynomial_format:  B", "polynomial_format:  A"))


def test_zero_scale(ventoux):
    tags = ventoux.to_gdal_tags()
    tags["LAT_SCALE"] = "0"
    with pytest.raises(InputError, match="lat_scale"):
        RPCModel.from_gdal_tags(tags)


def test_gdal_tags_errors(ventoux):
    tags = ventoux.to_gdal_tags()
    with pytest.raises(InputError, match="empty"):
        RPCModel.from_gdal_tags({})
    bad = dict(tags)
    del bad["SAMP_DEN_COEFF"]
    with pytest.raises(InputError, match="SAMP_DEN_COEFF"):
        RPCModel.from_gdal_tags(bad)
    bad = dict(tags, LINE_NUM_COEFF=" ".join(tags["LINE_NUM_COEFF"].split()[:19]))
    with pytest.raises(InputError, match="LINE_NUM_COEFF.*19"):
        RPCModel.from_gdal_tags(bad)
    bad = dict(tags, LONG_OFF="abc degrees")
    with pytest.raises(InputError, match="LONG_OFF"):
        RPCModel.from_gdal_tags(bad)


def test_dimap_errors():
    text = DIMAP_VENTOUX.read_text()
    with pytest.raises(InputError, match="empty"):
        RPCModel.from_dimap_xml("")
    with pytest.raises(InputError, match="parsed"):
        RPCModel.from_dimap_xml("<Dimap_Document><unclosed>")
    with pytest.raises(InputError, match="Global_RFM"):
        RPCModel.from_dimap_xml("<Dimap_Document/>")
    with pytest.raises(InputError, match="LINE_NUM_COEFF_5"):
        RPCModel.from_dimap_xml(text.replace("<LINE_NUM_COEFF_5>", "<X>").replace(
            "</LINE_NUM_COEFF_5>", "</X>"))
    with pytest.raises(InputError, match="SAMP_SCALE"):
        RPCModel.from_dimap_xml(text.replace("<SAMP_SCALE>19999.5", "<SAMP_SCALE>0"))


def test_keyword_construction_checks(ventoux):
    kw = ventoux.to_dict()
    kw.pop("type"), kw.pop("version")
    with pytest.raises(InputError, match="col_num"):
        RPCModel(**dict(kw, col_num=[1.0] * 19))
    with pytest.raises(InputError, match="inverse RPC incomplete"):
        RPCModel(**dict(kw, lon_num=[0.0] * 20))
    with pytest.raises(InputError, match="takes 6 parameters"):
        RPCModel(**dict(kw, bias_mode="affine", bias=[1.0, 2.0]))


@pytest.mark.parametrize("mode", ["none", "shift", "affine"])
def test_jacobian_agrees_with_finite_differences(ventoux, mode):
    """The analytic d(col, row)/d(bias) against central differences of project, on a real RPC,
    with the bias away from zero (the affine terms multiply the unbiased coordinates)."""
    from core.sensors.base import numeric_jacobian

    p = {"none": [], "shift": [2.0, -1.5], "affine": [2.0, 1.5, -3.0, -1.5, 2.0, 0.5]}[mode]
    m = ventoux.with_bias_mode(mode).with_params(p)
    assert m.param_names == {"none": (), "shift": ("a0", "b0"),
                             "affine": ("a0", "a1", "a2", "b0", "b1", "b2")}[mode]
    lon, lat, h = domain_points(m, 200)
    jac = m.jacobian(lon, lat, h)
    assert jac.shape == (200, 2, len(m.param_names))
    if mode == "none":
        return
    steps = np.ones(6) if mode == "affine" else np.ones(2)
    num = numeric_jacobian(m, lon, lat, h, steps)
    np.testing.assert_allclose(jac, num, atol=1e-6 * np.abs(num).max())
    # and it predicts the effect of a small change
    dp = steps * 0.3
    c0, r0 = m.project(lon, lat, h)
    c1, r1 = m.with_params(m.params + dp).project(lon, lat, h)
    np.testing.assert_allclose(np.stack([c1 - c0, r1 - r0], axis=1), jac @ dp, atol=1e-6)
