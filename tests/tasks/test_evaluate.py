"""``tasks.evaluation.lidar`` on real and synthetic lidar: units and CRS proven on the Autzen tile
(feet) against a DSM gridded from its own ground points; known biases recovered per LAS class
and per land-cover class through a UTM + EGM96 compound CRS and a feet + EGM96 (US feet)
compound CRS; points off the DEM and on voids counted; the mask and GCP hooks; bad input.

Expected values come from outside the code under test: pyproj (coordinates, units, and the
EGM96 undulation through PROJ's vgridshift on the bundled grid), scipy's
RegularGridInterpolator (the DEM at the points) and scipy's binned median (the Autzen DSM).
"""

from __future__ import annotations

import json
from pathlib import Path

import laspy
import numpy as np
import pyproj
import pytest
import rasterio
from affine import Affine
from scipy.interpolate import RegularGridInterpolator
from scipy.stats import binned_statistic_2d

from core.errors import CoverageError, InputError, InsufficientDataError
from core.evaluation.evaluation import StatsConfig
from core.evaluation.evaluation_report import EvaluationReport
from tasks.evaluation.lidar import (
    EvaluationOptions,
    evaluate_lidar,
    evaluate_plan,
    plan_evaluation,
    write_evaluation,
)
from tasks.io.geoid import EGM96_GTX
from tasks.io.lidar import inspect_lidar
from tasks.io.products import EVALUATION
from tasks.io.rasters_at_points import parse_landcover_names

DATA = Path(__file__).resolve().parents[1] / "data"
AUTZEN = DATA / "lidar" / "autzen_trim.laz"
US_FT = 1200.0 / 3937.0

# UTM 31N near Mont Ventoux; the DEM is 2 m cells
UTM31 = "EPSG:32631"
X0, Y1, CELL, NR, NC = 680_000.0, 4_896_000.0, 2.0, 150, 200
BIAS_BY_CLASS = {2: 0.30, 5: -1.25, 6: 2.0}  # dz = DEM - lidar


def egm96_n_m(lon: np.ndarray, lat: np.ndarray) -> np.ndarray:
    """EGM96 undulation from PROJ (vgridshift on the bundled grid): an oracle independent of
    core.geoid."""
    t = pyproj.Transformer.from_pipeline(
        "+proj=pipeline +step +proj=unitconvert +xy_in=deg +xy_out=rad "
        f"+step +proj=vgridshift +grids={EGM96_GTX} +multiplier=1 "
        "+step +proj=unitconvert +xy_in=rad +xy_out=deg")
    return np.asarray(t.transform(lon, lat, np.zeros_like(lon))[2])


def write_raster(path: Path, data: np.ndarray, crs: str, transform: tuple, *,
                 tags: dict[str, str] | None = None, nodata: float | None = np.nan) -> Path:
    with rasterio.open(path, "w", driver="GTiff", width=data.shape[1], height=data.shape[0],
                       count=1, dtype=data.dtype, crs=crs, transform=Affine(*transform),
                       nodata=nodata) as dst:
        dst.write(data, 1)
        if tags:
            dst.update_tags(**tags)
    return path


def write_las(path: Path, x, y, z, classes, crs: pyproj.CRS | None, *, scale: float = 0.001,
              version: str = "1.4", point_format: int = 6) -> Path:
    header = laspy.LasHeader(point_format=point_format, version=version)
    header.scales = np.array([scale] * 3)
    header.offsets = np.array([np.floor(np.min(x)), np.floor(np.min(y)), 0.0])
    if crs is not None:
        header.add_crs(crs)
    with laspy.open(path, mode="w", header=header) as w:
        rec = laspy.ScaleAwarePointRecord.zeros(len(x), header=header)
        rec.x, rec.y, rec.z = x, y, z
        rec.classification = np.asarray(classes, dtype=np.uint8)
        w.write_points(rec)
    return path


def dem_surface(nr: int = NR, nc: int = NC) -> np.ndarray:
    r, c = np.mgrid[0:nr, 0:nc].astype(float)
    return (350.0 + 0.08 * c - 0.05 * r + 4.0 * np.sin(c / 9.0) * np.cos(r / 7.0)).astype(
        np.float32)


def dem_at(z: np.ndarray, x0: float, y1: float, cell: float, x, y) -> np.ndarray:
    """Bilinear DEM value at (x, y) with scipy (node = pixel centre)."""
    ys = y1 - (np.arange(z.shape[0]) + 0.5) * cell
    xs = x0 + (np.arange(z.shape[1]) + 0.5) * cell
    f = RegularGridInterpolator((ys[::-1], xs), z[::-1].astype(float), method="linear")
    return f(np.column_stack([y, x]))


@pytest.fixture(scope="module")
def utm_scene(tmp_path_factory) -> dict:
    """A DEM (ellipsoidal, UTM 31N) and lidar in UTM 31N + EGM96 heights with a known bias per
    class; 5 % of the points off the DEM, a void in the DEM, and a land-cover raster."""
    tmp = tmp_path_factory.mktemp("utm")
    rng = np.random.default_rng(42)
    z = dem_surface()
    z_void = z.copy()
    z_void[60:80, 60:90] = np.nan
    transform = (CELL, 0.0, X0, 0.0, -CELL, Y1)
    dem = write_raster(tmp / "dsm.tif", z_void, UTM31, transform,
                       tags={"vertical_datum": "WGS84 ellipsoid", "units": "m"})
    n = 12_000
    # node grid spans centres 1 m .. 399 m east and 1 m .. 299 m south of the corner
    x = X0 + rng.uniform(1.0, 399.0, n)
    y = Y1 - rng.uniform(1.0, 299.0, n)
    out = rng.random(n) < 0.05
    x[out] = X0 + 400.0 + rng.uniform(5.0, 50.0, out.sum())  # east of the DEM
    classes = rng.choice(list(BIAS_BY_CLASS), n)
    h_dem = np.full(n, np.nan)
    h_dem[~out] = dem_at(z, X0, Y1, CELL, x[~out], y[~out])
    bias = np.vectorize(BIAS_BY_CLASS.get)(classes)
    noise = rng.normal(0.0, 0.05, n)
    h_lidar = np.where(out, 400.0, h_dem - bias + noise)
    lon, lat = pyproj.Transformer.from_crs(UTM31, "EPSG:4326", always_xy=True).transform(x, y)
    H_lidar = h_lidar - egm96_n_m(np.asarray(lon), np.asarray(lat))
    laz = write_las(tmp / "points.laz", x, y, H_lidar, classes, pyproj.CRS(f"{UTM31}+5773"))
    # land cover on a 10 m grid: west third bare soil, middle forest, east urban, a nodata band
    lc = np.ones((30, 40), np.uint8)
    lc[:, 13:26] = 2
    lc[:, 26:] = 3
    lc[:3, :] = 0
    lc_path = write_raster(tmp / "landcover.tif", lc, UTM31, (10.0, 0, X0, 0, -10.0, Y1),
                           tags={"BARE_SOIL": "1", "FOREST": "2", "URBAN": "3", "WATER": "4"},
                           nodata=0)
    col = np.floor((x - X0) / 10.0).astype(int)
    row = np.floor((Y1 - y) / 10.0).astype(int)
    in_void = (~out) & (y < Y1 - 2 * 60 - 4) & (y > Y1 - 2 * 80 + 4) & (x > X0 + 2 * 60 + 4) \
        & (x < X0 + 2 * 90 - 4)
    return {"dir": tmp, "dem": dem, "laz": laz, "landcover": lc_path, "x": x, "y": y,
            "classes": classes, "out": out, "noise": noise, "in_void": in_void,
            "lc_code": np.where(out | (row < 3), 0, lc[np.clip(row, 0, 29), np.clip(col, 0, 39)]),
            "z": z, "n": n}


def _evaluate(**kw) -> EvaluationReport:
    return evaluate_plan(plan_evaluation(EvaluationOptions(**kw)))


def test_utm_egm96_lidar_recovers_the_bias_of_each_class(utm_scene):
    s = utm_scene
    report = _evaluate(dem=s["dem"], lidar=s["laz"], chunk_points=2500)
    assert report.lidar.vertical == "egm96" and report.lidar.crs.authority == "EPSG:32631+5773"
    assert report.dem.vertical == "ellipsoidal" and "tag" in report.dem.vertical_source
    p = report.points
    assert p.read == s["n"] and p.outside_dem == s["out"].sum()
    assert p.on_void >= s["in_void"].sum() > 100
    assert p.read == p.withheld + p.excluded_class + p.outside_dem + p.on_void + p.evaluated
    assert set(report.classes) == {"2", "5", "6"} and report.class_labels["6"] == "building"
    for code, bias in BIAS_BY_CLASS.items():
        st = report.classes[str(code)]
        assert st.mean_m == pytest.approx(bias, abs=0.006)  # noise 0.05 m, ~3500 points
        assert st.std_m == pytest.approx(0.05, rel=0.1)
        assert st.nmad_m == pytest.approx(0.05, rel=0.1)
    assert report.all.count == p.evaluated
    # the same points, one chunk: the same figures
    one = _evaluate(dem=s["dem"], lidar=s["laz"])
    for k, st in one.classes.items():
        assert st.le68_m == report.classes[k].le68_m and st.count == report.classes[k].count
        assert st.mean_m == pytest.approx(report.classes[k].mean_m, rel=1e-12)


def test_class_filter_and_the_lidar_datum_matter(utm_scene):
    s = utm_scene
    report = _evaluate(dem=s["dem"], lidar=s["laz"], classes=(2, 6))
    assert set(report.classes) == {"2", "6"}
    assert report.points.excluded_class == (s["classes"] == 5).sum()
    # declared ellipsoidal, the EGM96 heights are ~50 m too low: the geoid shows in the bias
    wrong = _evaluate(dem=s["dem"], lidar=s["laz"], lidar_vertical="ellipsoidal", classes=(2,))
    assert 48.0 < wrong.classes["2"].mean_m - 0.30 < 53.0


def test_landcover_classes_with_names_from_the_tags(utm_scene):
    s = utm_scene
    report = _evaluate(dem=s["dem"], lidar=s["laz"], landcover=s["landcover"])
    assert report.classes_from == "landcover"
    assert set(report.classes) == {"bare_soil", "forest", "urban", "no_landcover"}
    assert dict(report.landcover.names)[2] == "forest"
    ok = ~s["out"] & ~s["in_void"]
    for code, name in ((1, "bare_soil"), (2, "forest"), (3, "urban"), (0, "no_landcover")):
        want = ok & (s["lc_code"] == code)
        # points near the void edges are on voids too: at most a few per cent fewer
        assert 0.9 * want.sum() <= report.classes[name].count <= want.sum()
    renamed = _evaluate(dem=s["dem"], lidar=s["laz"], landcover=s["landcover"],
                        landcover_names="1=soil,2=trees,3=town")
    assert set(renamed.classes) == {"soil", "trees", "town", "no_landcover"}


def test_feet_and_us_feet_through_a_compound_crs(tmp_path):
    """NAD83 Oregon Lambert (international feet) + EGM96 heights in US survey feet, against a
    DEM in UTM 10N metres with EGM96 heights (tag)."""
    rng = np.random.default_rng(5)
    x0, y1 = 493_800.0, 4_877_700.0
    z = dem_surface(100, 120)
    dem = write_raster(tmp_path / "dem.tif", z, "EPSG:32610", (CELL, 0, x0, 0, -CELL, y1),
                       tags={"vertical_datum": "EGM96 geoid"})
    n = 4000
    x = x0 + rng.uniform(2, 238, n)
    y = y1 - rng.uniform(2, 198, n)
    H = dem_at(z, x0, y1, CELL, x, y) - 0.7
    h2992 = pyproj.CRS.from_epsg(2992)
    vert = ('VERTCRS["EGM96 height (US survey foot)",VDATUM["EGM96 geoid"],CS[vertical,1],'
            'AXIS["gravity-related height (H)",up,LENGTHUNIT["US survey foot",0.304800609601219'
            ']]]')
    crs = pyproj.CRS.from_wkt(f'COMPOUNDCRS["Oregon GIC (ft) + EGM96 (ftUS)",{h2992.to_wkt()},'
                              f'{vert}]')
    xf, yf = pyproj.Transformer.from_crs("EPSG:32610", h2992, always_xy=True).transform(x, y)
    laz = write_las(tmp_path / "feet.laz", xf, yf, H / US_FT, np.full(n, 2), crs)
    report = _evaluate(dem=dem, lidar=laz)
    li = report.lidar
    assert li.xy_factor_m == 0.3048 and li.z_factor_m == pytest.approx(US_FT, rel=1e-15)
    assert li.vertical == "egm96" and report.dem.vertical == "egm96"
    st = report.classes["2"]
    assert st.count == n and st.mean_m == pytest.approx(0.7, abs=0.002)
    assert st.le90_m == pytest.approx(0.7, abs=0.002)  # the scale 0.001 ft is the only noise


def test_las12_geotiff_keys_give_the_vertical_datum_and_unit(utm_scene, tmp_path):
    """LAS 1.2 with GeoTIFF keys only: VerticalCSTypeGeoKey 5773 (EGM96 height) and
    VerticalUnitsGeoKey 9002 (international foot) over a horizontal CRS in metres."""
    s = utm_scene
    keep = ~s["out"]
    with laspy.open(s["laz"]) as f:
        H_m = np.asarray(f.read().z)[keep]
    header = laspy.LasHeader(point_format=3, version="1.2")
    header.scales, header.offsets = np.array([0.001] * 3), np.array([X0, Y1 - 400.0, 0.0])
    header.add_crs(pyproj.CRS(UTM31))
    keys = header.vlrs.get("GeoKeyDirectoryVlr")[0]
    for key_id, value in ((4096, 5773), (4099, 9002)):
        entry = laspy.vlrs.known.GeoKeyEntryStruct()
        entry.id, entry.tiff_tag_location, entry.count, entry.value_offset = key_id, 0, 1, value
        keys.geo_keys.append(entry)
    keys.geo_keys_header.number_of_keys = len(keys.geo_keys)
    path = tmp_path / "keys.las"
    with laspy.open(path, mode="w", header=header) as w:
        rec = laspy.ScaleAwarePointRecord.zeros(int(keep.sum()), header=header)
        rec.x, rec.y, rec.z = s["x"][keep], s["y"][keep], H_m / 0.3048
        rec.classification = s["classes"][keep]
        w.write_points(rec)
    report = _evaluate(dem=s["dem"], lidar=path)
    assert report.lidar.vertical == "egm96" and report.lidar.z_factor_m == 0.3048
    assert report.lidar.crs.authority == "EPSG:32631"
    for code, bias in BIAS_BY_CLASS.items():
        assert report.classes[str(code)].mean_m == pytest.approx(bias, abs=0.006)


def _autzen_dsm(path: Path) -> tuple[Path, float]:
    """Median height of the class-2 points per 2 m cell in UTM 10N (metres); returns the DSM
    and the number of cells filled. Built with pyproj and scipy only."""
    with laspy.open(AUTZEN) as f:
        pts = f.read()
        crs = f.header.parse_crs()
    ground = np.asarray(pts.classification) == 2
    e, n = pyproj.Transformer.from_crs(crs, "EPSG:32610", always_xy=True).transform(
        np.asarray(pts.x)[ground], np.asarray(pts.y)[ground])
    z_m = np.asarray(pts.z)[ground] * 0.3048  # the international foot, exactly
    x0, y1 = np.floor(e.min() / 2) * 2 - 2, np.ceil(n.max() / 2) * 2 + 2
    nc, nr = int((e.max() - x0) // 2) + 2, int((y1 - n.min()) // 2) + 2
    med, _, _, _ = binned_statistic_2d(n, e, z_m, "median",
                                       bins=[y1 - 2 * np.arange(nr + 1)[::-1],
                                             x0 + 2 * np.arange(nc + 1)])
    dsm = med[::-1].astype(np.float32)  # rows from the north
    write_raster(path, dsm, "EPSG:32610", (2.0, 0, x0, 0, -2.0, y1))
    return path, float(np.isfinite(dsm).sum())


def test_autzen_is_read_in_metres_and_its_ground_has_no_bias(tmp_path):
    """Units and CRS on real data: NAD83(HARN) Lambert in international feet (x, y, z)."""
    src = inspect_lidar(AUTZEN)
    crs = pyproj.CRS.from_wkt(src.info.crs.wkt)
    feet = crs.axis_info[0]
    assert feet.unit_name == "foot" and feet.unit_conversion_factor == 0.3048
    assert src.info.xy_factor_m == 0.3048 and src.info.z_factor_m == 0.3048
    assert "horizontal unit" in src.info.z_unit_source and src.info.vertical == "ellipsoidal"
    dsm, cells = _autzen_dsm(tmp_path / "autzen_dsm.tif")
    assert cells > 5000
    # the DSM is made of the lidar's own heights, whose datum no file says: declared
    with pytest.raises(InputError, match="--dem-vertical egm96"):
        _evaluate(dem=dsm, lidar=AUTZEN)
    report = _evaluate(dem=dsm, lidar=AUTZEN, dem_vertical="ellipsoidal")
    ground = report.classes["2"]
    assert ground.count > 20_000 and abs(ground.mean_m) < 0.05 and ground.nmad_m < 0.1
    assert report.points.outside_dem == 0
    assert "NAD83(HARN) to WGS 84" in report.transformation  # a real datum shift, no ballpark
    assert "ballpark" not in report.transformation.lower()
    assert report.classes["1"].count > 40_000  # unclassified points over ground cells
    # read as metres the heights are 3.3 times too large: the unit is what makes the bias 0
    wrong = _evaluate(dem=dsm, lidar=AUTZEN, lidar_z_unit="m", classes=(2,),
                      dem_vertical="ellipsoidal")
    assert wrong.classes["2"].mean_m < -200.0


def test_the_task_and_the_json(utm_scene, tmp_path):
    s = utm_scene
    mask = np.zeros((10, 20), np.uint8)
    mask[0, :5] = 1
    mask[1:3, :] = 2
    mask_path = write_raster(tmp_path / "mask.tif", mask, UTM31, (20.0, 0, X0, 0, -20.0, Y1),
                             nodata=None)
    lon, lat = pyproj.Transformer.from_crs(UTM31, "EPSG:4326", always_xy=True).transform(
        X0 + np.array([50.0, 250.0, 390.0]), Y1 - np.array([30.0, 250.0, 280.0]))
    h = dem_at(s["z"], X0, Y1, CELL, X0 + np.array([50.0, 250.0, 390.0]),
               Y1 - np.array([30.0, 250.0, 280.0])) - 0.5
    gcps = tmp_path / "gcps.json"
    gcps.write_text(json.dumps([[a, b, c] for a, b, c in zip(lon, lat, h, strict=True)]
                               + [[0.0, 0.0, 0.0]]))  # one far off the DEM
    report = evaluate_lidar.fn(EvaluationOptions(dem=s["dem"], lidar=s["laz"], mask=mask_path,
                                                 gcps=gcps, stats=StatsConfig(seed=3)))
    assert report.mask.mismatched_pct == pytest.approx(100 * 5 / 200)
    assert report.mask.occluded_pct == pytest.approx(100 * 40 / 200)
    assert report.gcps.points == 4 and report.gcps.outside_dem == 1
    assert report.gcps.stats.rmse_m == pytest.approx(0.5, abs=1e-4)
    out = write_evaluation.fn(report, tmp_path / "deep" / "eval.json")
    d = json.loads(out.read_text())
    for block in (*d["classes"].values(), d["all"]):
        assert {"count", "mean", "std", "rmse", "nmad", "le68", "le90", "le68_ci"} <= set(block)
    assert d["gcps"]["rms_m"] == pytest.approx(0.5, abs=1e-4)
    assert d["lidar"]["vertical"] == "egm96" and d["points"]["outside_dem"] == s["out"].sum()
    assert d["statistics"]["seed"] == 3
    assert EVALUATION.load(d).classes["2"] == report.classes["2"]


def test_a_lidar_without_crs_asks_for_lidar_crs(utm_scene, tmp_path):
    s = utm_scene
    keep = ~s["out"]
    with laspy.open(s["laz"]) as f:
        z = np.asarray(f.read().z)[keep]
    bare = write_las(tmp_path / "nocrs.laz", s["x"][keep], s["y"][keep], z, s["classes"][keep],
                     None)
    with pytest.raises(InputError, match="no CRS.*--lidar-crs"):
        plan_evaluation(EvaluationOptions(dem=s["dem"], lidar=bare))
    report = _evaluate(dem=s["dem"], lidar=bare, lidar_crs=f"{UTM31}+5773")
    assert report.lidar.crs_source == "--lidar-crs"
    assert report.classes["2"].mean_m == pytest.approx(0.30, abs=0.006)
    with pytest.raises(InputError, match="not a CRS"):
        plan_evaluation(EvaluationOptions(dem=s["dem"], lidar=bare, lidar_crs="EPSG:999999"))


def test_bad_input_is_named(utm_scene, tmp_path):
    s = utm_scene
    with pytest.raises(InputError, match="does not exist"):
        plan_evaluation(EvaluationOptions(dem=s["dem"], lidar=tmp_path / "none.laz"))
    with pytest.raises(InputError, match="DEM .* does not exist"):
        plan_evaluation(EvaluationOptions(dem=tmp_path / "none.tif", lidar=s["laz"]))
    junk = tmp_path / "junk.laz"
    junk.write_text("not lidar")
    with pytest.raises(InputError, match="cannot read lidar"):
        plan_evaluation(EvaluationOptions(dem=s["dem"], lidar=junk))
    # a DEM 50 km away: the extents are named
    far = write_raster(tmp_path / "far.tif", dem_surface(20, 20), UTM31,
                       (CELL, 0, X0 + 50_000, 0, -CELL, Y1),
                       tags={"vertical_datum": "WGS84 ellipsoid"})
    with pytest.raises(CoverageError, match=r"does not cover the lidar \(x 680"):
        plan_evaluation(EvaluationOptions(dem=far, lidar=s["laz"]))
    # a DEM all void over the lidar
    void = write_raster(tmp_path / "void.tif", np.full((NR, NC), np.nan, np.float32), UTM31,
                        (CELL, 0, X0, 0, -CELL, Y1), tags={"vertical_datum": "WGS84 ellipsoid"})
    with pytest.raises(InsufficientDataError, match="voids"):
        _evaluate(dem=void, lidar=s["laz"])
    # NAVD88 heights cannot be converted
    navd = write_las(tmp_path / "navd.laz", s["x"][:10], s["y"][:10], np.zeros(10),
                     np.full(10, 2), pyproj.CRS(f"{UTM31}+5703"))
    with pytest.raises(InputError, match="NAVD88 height.*--lidar-vertical"):
        plan_evaluation(EvaluationOptions(dem=s["dem"], lidar=navd))
    assert plan_evaluation(EvaluationOptions(dem=s["dem"], lidar=navd,
                                             lidar_vertical="egm96")).lidar.frame.datum == "egm96"
    with pytest.raises(InputError, match="lidar-vertical"):
        EvaluationOptions(dem=s["dem"], lidar=s["laz"], lidar_vertical="navd88")
    with pytest.raises(InputError, match="needs --landcover"):
        EvaluationOptions(dem=s["dem"], lidar=s["laz"], landcover_names="1=a")


@pytest.mark.parametrize("suffix", [".laz", ".las"])
def test_a_truncated_file_is_refused(utm_scene, tmp_path, suffix):
    s = utm_scene
    src = tmp_path / f"full{suffix}"
    with laspy.open(s["laz"]) as f:
        f.read().write(src)
    cut = tmp_path / f"cut{suffix}"
    data = src.read_bytes()
    cut.write_bytes(data[: len(data) * 2 // 3])
    with pytest.raises(InputError, match="truncated"):  # found before anything streams
        plan_evaluation(EvaluationOptions(dem=s["dem"], lidar=cut, chunk_points=1000))


def test_landcover_names_spec():
    assert parse_landcover_names('{"1": "bare_soil", "2": "forest"}') == {1: "bare_soil",
                                                                          2: "forest"}
    assert parse_landcover_names("BARE_SOIL=1, forest=2") == {1: "BARE_SOIL", 2: "forest"}
    for bad in ("1=a,2=a", "x=y", "1", "{not json", "1=no_landcover"):
        with pytest.raises(InputError):
            parse_landcover_names(bad)



def test_simulated_truth_dtm_against_its_ground_lidar(tiny_scene):
    """The simulator's own files (truth DTM with its vertical_datum tag, lidar in UTM + EGM96,
    land cover with NAME=code tags): ground returns against the DTM have no bias in any land
    cover, so the EGM96 heights (~50 m off otherwise) were converted."""
    out = Path(tiny_scene[0])  # rendered once per session (tests/conftest.py)
    report = _evaluate(dem=out / "truth" / "dtm.tif", lidar=out / "truth" / "lidar.laz",
                       landcover=out / "truth" / "landcover.tif", classes=(2,))
    assert report.lidar.vertical == "egm96" and report.dem.vertical == "ellipsoidal"
    for name in ("bare_soil", "forest", "urban"):  # forest: ground returns under the canopy
        st = report.classes[name]
        assert st.count > 10_000 and abs(st.mean_m) < 0.02, name
        assert 0.15 < st.std_m < 0.4  # the lidar's 0.15 m noise and the 20 m grid
