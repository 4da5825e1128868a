"""The scene simulator on the tiny preset: truth, images, metadata, check points, lidar."""

from __future__ import annotations

import json
from pathlib import Path

import laspy
import numpy as np
import pyproj
import pytest
import rasterio
from rasterio.transform import RPCTransformer, from_origin
from scipy.ndimage import map_coordinates

from core.errors import CoverageError, InputError
from core.sensors.pushbroom import PushbroomModel
from core.simulation.landcover import LandCover
from core.simulation.scene import ErrorConfig
from tasks.io.geoid import EGM96_GTX, load_geoid
from tasks.simulate import scene as S
from tasks.simulate.io import check_dem
from tests.scenes import CENTRE, DEM, run_scene


@pytest.fixture(scope="module")
def scene_dir(tiny_scene):
    return tiny_scene


def models(out: Path, kind: str):
    names = ("left", "right")
    if kind == "truth":
        return [PushbroomModel.from_json((out / "truth" / f"{n}_truth.json").read_text())
                for n in names]
    return [PushbroomModel.from_json((out / f"{n}.json").read_text()) for n in names]


def test_delivered_metadata_error_at_centre(scene_dir):
    out, scene = scene_dir
    truth, delivered = models(out, "truth"), models(out, "delivered")
    geod = pyproj.Geod(ellps="WGS84")
    for name, t, d in zip(scene.image_names, truth, delivered, strict=True):
        err = scene.injected[name].centre_error_m
        assert 100.0 <= err <= 300.0
        c, r = (t.n_cols - 1) / 2, (t.n_rows - 1) / 2
        h = scene.centre.h_m
        lt, at = t.localize(c, r, h)
        ld, ad = d.localize(c, r, h)
        # geodesic distance on the ellipsoid (PROJ), scaled to height h
        _, _, dist = geod.inv(float(lt), float(at), float(ld), float(ad))
        assert dist * (1 + h / 6.371e6) == pytest.approx(err, rel=2e-3)
        assert t.attitude.jitter and not d.attitude.jitter  # errors the metadata lack
        assert t.distortion.k3 != 0 and d.distortion.k3 == 0


def test_spot_metadata_beside_each_image_reads_back_as_the_delivered_model(scene_dir):
    """DIR/left.DIM (SPOT 1-4 style METADATA.DIM) is what the chain finds for DIR/left.tif, and
    it projects within 1e-3 px of the delivered JSON model over the scene and heights."""
    from tasks.io.sensors import load_model

    out, scene = scene_dir
    lo, hi = scene.dsm_range_m
    for name, d in zip(scene.image_names, models(out, "delivered"), strict=True):
        loaded = load_model(out / f"{name}.tif")
        assert loaded.source == out / f"{name}.DIM" and loaded.spot.mission_index == 2
        c, r = np.meshgrid(np.linspace(0, 599, 11), np.linspace(0, 599, 11))
        for h in (lo - 100.0, 0.5 * (lo + hi), hi + 100.0):
            lon, lat = d.localize(c.ravel(), r.ravel(), h)
            c2, r2 = loaded.model.project(lon, lat, h)
            assert np.hypot(c2 - c.ravel(), r2 - r.ravel()).max() < 1e-3


def test_truth_models_round_trip(scene_dir):
    out, _ = scene_dir
    for m in models(out, "truth"):
        r, c = np.mgrid[0:600:29, 0:600:31].astype(float)
        for h in (-400.0, 800.0, 4800.0):
            lon, lat = m.localize(c, r, np.full(c.shape, h))
            c2, r2 = m.project(lon, lat, np.full(c.shape, h))
            assert np.hypot(c2 - c, r2 - r).max() < 1e-3


def test_checkpoints_are_what_their_pixels_see(scene_dir):
    """Independent of the simulator's ray caster: each check point's line of sight through its
    stored pixel (the truth model's ``localize``, not ``project``) is walked down in 0.25 m
    steps against the truth DSM read by GDAL and interpolated here; it first meets the surface
    at the check point."""
    out, scene = scene_dir
    doc = json.loads((out / "truth" / "checkpoints.json").read_text())
    pts = doc["points"]
    assert len(pts) >= 50 and doc["images"] == list(scene.image_names)
    lon = np.array([p["lon_deg"] for p in pts])
    lat = np.array([p["lat_deg"] for p in pts])
    h = np.array([p["h_m"] for p in pts])
    to_utm = pyproj.Transformer.from_crs("EPSG:4326", doc["crs"], always_xy=True)
    with rasterio.open(out / "truth" / "dsm.tif") as src:
        dsm, t = src.read(1).astype(float), src.transform
    steps = np.arange(300.0, -30.0, -0.25)  # metres above / below the point
    for name, m in zip(scene.image_names, models(out, "truth"), strict=True):
        cs = np.array([p[name]["col"] for p in pts])
        rs = np.array([p[name]["row"] for p in pts])
        assert ((cs > 0) & (cs < m.n_cols - 1) & (rs > 0) & (rs < m.n_rows - 1)).all()
        # the stored pixel's line of sight passes through the point at its height
        lo, la = m.localize(cs, rs, h)
        x, y = to_utm.transform(lo, la)
        px, py = to_utm.transform(lon, lat)
        assert np.hypot(x - px, y - py).max() < 0.001 * 40.0  # 1e-3 px at 40 m
        # and meets the DSM there first
        hh = h[:, None] + steps[None, :]
        lo, la = m.localize(np.repeat(cs, steps.size), np.repeat(rs, steps.size), hh.ravel())
        x, y = to_utm.transform(lo, la)
        col_f, row_f = ~t * (np.asarray(x), np.asarray(y))
        z = map_coordinates(dsm, [row_f - 0.5, col_f - 0.5], order=1, cval=np.nan)
        below = (hh.ravel() <= z).reshape(hh.shape)
        first = np.argmax(below, axis=1)
        assert below.any(axis=1).all()
        k = np.arange(len(pts))
        h_hit = hh[k, first]
        x_hit = np.asarray(x).reshape(hh.shape)[k, first]
        y_hit = np.asarray(y).reshape(hh.shape)[k, first]
        # visible: the first hit is within 1.5 cells of the point (a tree or roof in front
        # would stop the ray tens of metres away), at the point's height within the
        # bilinear DSM's rendering of sub-cell relief
        assert np.hypot(x_hit - px, y_hit - py).max() < 1.5 * scene.grid.res_m, name
        assert np.median(np.abs(h_hit - h)) < 0.5, name
        assert np.percentile(np.abs(h_hit - h), 90) < 2.0, name
    # they carry consistent EGM96 heights (PROJ's vgridshift on the bundled grid)
    egm = pyproj.Transformer.from_pipeline(
        f"+proj=vgridshift +grids={EGM96_GTX} +multiplier=-1")
    _, _, H = egm.transform(lon, lat, h)
    np.testing.assert_allclose([p["H_egm96_m"] for p in pts], H, atol=1e-6)


def test_images_carry_the_rpc_of_their_delivered_metadata(scene_dir):
    out, _ = scene_dir
    for name, d in zip(("left", "right"), models(out, "delivered")):
        with rasterio.open(out / f"{name}.tif") as src:
            assert src.rpcs is not None and src.dtypes[0] == "uint8"
            assert (src.width, src.height) == (600, 600)
            assert src.crs is None  # raw sensor geometry
            img = src.read(1)
        assert img.std() > 5 and (img == 0).mean() < 0.01
        rng = np.random.default_rng(0)
        c, r = rng.uniform(0, 599, 500), rng.uniform(0, 599, 500)
        h = rng.uniform(200, 1900, 500)
        lon, lat = d.localize(c, r, h)
        with RPCTransformer(src.rpcs) as tr:
            g_row, g_col = tr.rowcol(lon, lat, zs=h, op=np.positive)
        assert np.hypot(np.asarray(g_col) - 0.5 - c, np.asarray(g_row) - 0.5 - r).max() < 0.05


def ncc(a: np.ndarray, b: np.ndarray) -> float:
    a = a - a.mean()
    b = b - b.mean()
    return float((a * b).sum() / np.sqrt((a * a).sum() * (b * b).sum() + 1e-12))


def test_rendering_puts_ground_where_the_truth_models_say(scene_dir):
    """At a check point's true image position the DN is the ground radiance there (gain x L
    plus noise and sub-pixel texture); one pixel off, it matches clearly worse."""
    out, _ = scene_dir
    pts = json.loads((out / "truth" / "checkpoints.json").read_text())["points"]
    gain = 0.8 * 255
    for name in ("left", "right"):
        with rasterio.open(out / f"{name}.tif") as s:
            img = s.read(1).astype(float)
        with rasterio.open(out / "work" / f"radiance_{name}.tif") as s:
            L = np.array([v[0] for v in s.sample([(p["x_m"], p["y_m"]) for p in pts])])
        c = np.array([p[name]["col"] for p in pts])
        r = np.array([p[name]["row"] for p in pts])

        def residual(dc: float, dr: float, img=img, c=c, r=r, L=L) -> float:
            dn = map_coordinates(img, [r + dr, c + dc], order=1)
            return float(np.median(np.abs(dn - gain * L)))

        at_truth = residual(0, 0)
        shifted = min(residual(dc, dr) for dc, dr in ((1, 0), (-1, 0), (0, 1), (0, -1)))
        assert at_truth < 0.85 * shifted
        dn = map_coordinates(img, [r, c], order=1)
        assert np.corrcoef(dn, L)[0, 1] > 0.6


def test_left_and_right_agree_at_the_check_points(scene_dir):
    """Correlating patches of the two images: the best offset is zero, in the median."""
    out, _ = scene_dir
    with rasterio.open(out / "left.tif") as s1, rasterio.open(out / "right.tif") as s2:
        left, right = s1.read(1).astype(float), s2.read(1).astype(float)
    pts = json.loads((out / "truth" / "checkpoints.json").read_text())["points"]
    best = []
    w = 7
    for p in pts:
        cl, rl = round(p["left"]["col"]), round(p["left"]["row"])
        cr, rr = round(p["right"]["col"]), round(p["right"]["row"])
        if min(cl, rl, cr, rr) < w + 4 or max(cl, rl, cr, rr) > 599 - w - 4:
            continue
        a = left[rl - w : rl + w + 1, cl - w : cl + w + 1]
        scores = {}
        for dr in range(-3, 4):
            for dc in range(-3, 4):
                b = right[rr + dr - w : rr + dr + w + 1, cr + dc - w : cr + dc + w + 1]
                scores[(dc, dr)] = ncc(a, b)
        best.append(max(scores, key=scores.get))
    best = np.array(best)
    assert len(best) >= 30
    assert np.median(best, axis=0).tolist() == [0.0, 0.0]
    assert np.mean(np.abs(best).max(axis=1) <= 1) > 0.5


def test_truth_surface_rules(scene_dir):
    out, scene = scene_dir
    with rasterio.open(out / "truth" / "dsm.tif") as s:
        dsm = s.read(1)
        assert s.crs.to_epsg() == scene.epsg and s.overviews(1)
    with rasterio.open(out / "truth" / "dtm.tif") as s:
        dtm = s.read(1)
    with rasterio.open(out / "truth" / "landcover.tif") as s:
        lc = s.read(1)
    diff = dsm - dtm
    forest = lc == LandCover.FOREST
    assert forest.mean() > 0.1
    assert diff[forest].min() >= 10.0 - 1e-3 and diff[forest].max() <= 25.0 + 1e-3
    bare = lc == LandCover.BARE_SOIL
    assert np.abs(diff[bare]).max() < 1e-3
    urban = lc == LandCover.URBAN
    roofs = urban & (diff > 1.0)
    assert roofs.any() and np.percentile(diff[roofs], 99) < 20.0
    water = lc == LandCover.WATER
    if water.any():
        assert np.ptp(dtm[water]) < 1e-3
    assert np.isfinite(dsm).all()  # voids of the DEM are filled in the truth


def test_lidar_reads_back_with_crs_and_classes(scene_dir):
    out, scene = scene_dir
    las = laspy.read(out / "truth" / "lidar.laz")
    crs = las.header.parse_crs()
    assert crs is not None
    assert pyproj.CRS.from_user_input(f"EPSG:{scene.epsg}+5773").equals(crs)
    classes = set(np.unique(las.classification).tolist())
    assert classes <= {2, 5, 6, 9} and {2, 5} <= classes
    x, y, z = np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)
    # density: irregular, about the preset's spacing
    g = scene.grid
    spacing = scene.preset_spec.lidar_spacing_m
    assert 0.6 < len(x) / (g.width * g.height * g.res_m**2 / spacing**2) < 1.05
    # heights are EGM96: adding N gives the ellipsoidal truth DSM at ground points
    ground = np.flatnonzero(las.classification == 2)[::50]
    lon, lat = pyproj.Transformer.from_crs(scene.epsg, 4326, always_xy=True).transform(
        x[ground], y[ground])
    h = z[ground] + load_geoid().undulation_m(lon, lat)
    with rasterio.open(out / "truth" / "dtm.tif") as s:
        dtm = np.array([v[0] for v in s.sample(list(zip(x[ground], y[ground])))])
    assert np.median(np.abs(h - dtm)) < 1.5


def test_rerun_resumes_and_refuses_another_scene(scene_dir):
    out, scene = scene_dir
    before = (out / "left.tif").stat().st_mtime_ns
    again = S.define_scene.fn(DEM, out, "tiny", scene.seed, ErrorConfig(lens=True, jitter=True),
                              centre_lonlat=CENTRE, date_change=0.1)
    assert again == scene
    S.render_image.fn(again, out, 0)
    assert (out / "left.tif").stat().st_mtime_ns == before
    with pytest.raises(InputError, match="different simulated scene"):
        S.define_scene.fn(DEM, out, "tiny", scene.seed + 1, ErrorConfig(), centre_lonlat=CENTRE)


def test_relief_factor_flattens(tmp_path, scene_dir):
    scene = S.define_scene.fn(DEM, tmp_path, "tiny", 11, ErrorConfig(), centre_lonlat=CENTRE,
                              relief_factor=0.05)
    scene = S.build_truth_surface.fn(scene, tmp_path)
    with rasterio.open(tmp_path / "truth" / "dtm.tif") as s:
        flat = s.read(1)
    with rasterio.open(ref_dir_dtm(scene_dir)) as s:
        full = s.read(1)
    assert np.ptp(flat) < 0.1 * np.ptp(full)


def ref_dir_dtm(scene_dir) -> Path:
    return scene_dir[0] / "truth" / "dtm.tif"


def write_dem(path: Path, lon0: float, lat1: float, res_deg: float, shape, crs="EPSG:4326",
              plus_m: float = 0.0, tags: dict[str, str] | None = None):
    rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]]
    lon = lon0 + (cols + 0.5) * res_deg
    lat = lat1 - (rows + 0.5) * res_deg
    H = 900 + 500 * np.sin(lon * 20) * np.cos(lat * 17) + 200 * np.sin(lat * 50)
    with rasterio.open(path, "w", driver="GTiff", width=shape[1], height=shape[0], count=1,
                       dtype="float32", crs=crs, nodata=-9999,
                       transform=from_origin(lon0, lat1, res_deg, res_deg)) as dst:
        dst.write((H + plus_m).astype(np.float32), 1)
        dst.update_tags(**(tags or {}))
    return H


@pytest.mark.slow
def test_any_geographic_dem_geotiff(tmp_path):
    """A DEM of ellipsoidal heights (its tag says so) is brought to orthometric heights for
    the world: the truth DSM is at the same ellipsoidal heights, not one undulation higher."""
    dem = tmp_path / "my_dem.tif"
    n = load_geoid().undulation_m(10.25, 46.22)
    H = write_dem(dem, 10.0, 46.45, 1.5 / 3600, (1080, 1200), plus_m=float(n),
                  tags={"vertical_datum": "WGS84 ellipsoid"})  # 0.5 x 0.45 deg at 1.5"
    out = tmp_path / "scene"
    scene = run_scene(out, dem=dem, centre=None, seed=5, lidar=False)
    assert scene.epsg == 32632 and scene.dem_vertical == "ellipsoidal"
    lo, hi = scene.dsm_range_m
    assert 40 < n < 55  # one undulation more would put the DSM out of the bounds below
    assert H.min() + n - 30 < lo and hi < H.max() + n + 40
    pts = json.loads((out / "truth" / "checkpoints.json").read_text())["points"]
    assert len(pts) >= 50


def test_dem_that_does_not_cover_the_scene(tmp_path):
    dem = tmp_path / "small.tif"
    write_dem(dem, 10.0, 46.1, 1.5 / 3600, (120, 120))  # 0.05 deg: far too small
    with pytest.raises(CoverageError, match="does not cover the simulated scene"):
        S.define_scene.fn(dem, tmp_path / "o", "tiny", 0, ErrorConfig(), dem_vertical="egm96")


def test_projected_or_missing_dem_is_refused(tmp_path):
    dem = tmp_path / "utm.tif"
    write_dem(dem, 600000.0, 5000000.0, 30.0, (50, 50), crs="EPSG:32632")
    with pytest.raises(InputError, match="reproject it to EPSG:4326"):
        check_dem(dem)
    with pytest.raises(InputError, match="does not exist"):
        check_dem(tmp_path / "nope.tif")
    with pytest.raises(InputError, match="date-change"):
        S.define_scene.fn(DEM, tmp_path / "o", "tiny", 0, ErrorConfig(), date_change=2.0)
