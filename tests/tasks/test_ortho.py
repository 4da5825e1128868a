"""Orthorectification and the ortho-versus-ortho check on data with known truth.

- Simulator (tiny scene): the ortho of each image through its truth model on the truth DSM
  lands on the simulator's own ground radiance of that date (the texture the image was
  rendered from) within a few hundredths of a cell; the left and right orthos agree; a model
  biased by 2 image columns moves the ortho by the ground distance of 2 columns (computed from
  the truth model's localisation); the image position of every cell of a tile agrees with the
  exact chain (pyproj, the DSM read by rasterio and interpolated by scipy, the truth model)
  within 0.01 px on a model with attitude jitter; tiles join without seams.
- Real Pleiades crop with its RPC on SRTM: the same output grid warped by GDAL's RPC
  transformer (rasterio ``reproject`` with ``rpcs=`` and ``RPC_DEM``) agrees in geometry and in
  values.
- Bad input: one line.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import rasterio
import rasterio.warp
from affine import Affine
from rasterio.enums import Resampling
from rasterio.rpc import RPC
from scipy.interpolate import RegularGridInterpolator

from core.errors import CoverageError, InputError
from core.geodesy import BBox
from core.matching.grid import GridSpec
from core.ortho.ortho import OrthoConfig, tile_geometry
from core.ortho.ortho_compare import CompareConfig
from core.sensors.footprint import footprint_lonlat
from tasks.io.crs import Projection
from tasks.io.dem import read_reference
from tasks.io.geoid import BUNDLED_SRTM_DIR
from tasks.io.sensors import LoadedModel, load_model
from tasks.ortho import orthorectify as T
from tasks.ortho.compare import compare_orthos, plan_compare
from tasks.ortho.inputs import describe_dem, read_tile_dem

RES = 40.0  # the tiny scene's GSD


def truth(scene_dir: Path, name: str) -> LoadedModel:
    return load_model(scene_dir / f"{name}.tif", model=scene_dir / "truth" / f"{name}_truth.json")


def make_ortho(loaded: LoadedModel, dem: Path, out: Path, **kw: Any) -> T.OrthoSummary:
    config = kw.pop("config", OrthoConfig())
    plan = T.plan_ortho.fn(loaded, describe_dem(dem), RES, occlusion=config.occlusion, **kw)
    return T.orthorectify.fn(plan, out, config)


def compare(left: Path, right: Path, out: Path, **kw: Any) -> dict:
    plan = plan_compare.fn(left, right, CompareConfig(**kw))
    compare_orthos.fn(plan, out)
    return json.loads(out.read_text())


def radiance_at_res(scene_dir: Path, name: str, out: Path) -> Path:
    """The simulator's ground radiance of one date (20 m) averaged 2 x 2 onto the 40 m
    lattice."""
    with rasterio.open(scene_dir / "work" / f"radiance_{name}.tif") as src:
        z, t, crs = src.read(1).astype(np.float64), src.transform, src.crs
    assert t.a == 20.0 and t.c % RES == 0 and t.f % RES == 0
    h, w = z.shape[0] // 2 * 2, z.shape[1] // 2 * 2
    a = z[:h, :w].reshape(h // 2, 2, w // 2, 2).mean(axis=(1, 3)).astype(np.float32)
    with rasterio.open(out, "w", driver="GTiff", width=a.shape[1], height=a.shape[0], count=1,
                       dtype="float32", crs=crs, transform=Affine(RES, 0, t.c, 0, -RES, t.f),
                       nodata=math.nan) as dst:
        dst.write(a, 1)
    return out


@pytest.fixture(scope="module")
def orthos(tiny_scene, tmp_path_factory):
    scene_dir, _ = tiny_scene
    out = tmp_path_factory.mktemp("ortho")
    dsm = scene_dir / "truth" / "dsm.tif"
    s = {name: make_ortho(truth(scene_dir, name), dsm, out / f"{name}.tif",
                          config=OrthoConfig(occlusion=True))
         for name in ("left", "right")}
    return scene_dir, out, s


@pytest.mark.parametrize("name", ["left", "right"])
def test_ortho_from_the_truth_lands_on_the_simulated_ground(orthos, name):
    scene_dir, out, summaries = orthos
    s = summaries[name]
    assert s.epsg == 32631 and s.resolution_m == RES and s.max_error_px <= 0.01
    rad = radiance_at_res(scene_dir, name, out / f"radiance_{name}.tif")
    doc = compare(rad, Path(s.path), out / f"truth_{name}.json", window_px=32, step_px=48)
    assert doc["n_valid"] > 100
    assert doc["px"]["median_norm"] < 0.05
    assert doc["px"]["p95_norm"] < 0.1
    assert abs(doc["px"]["median_dx"]) < 0.02 and abs(doc["px"]["median_dy"]) < 0.02


def test_the_two_truth_orthos_agree(orthos):
    _, out, s = orthos
    doc = compare(Path(s["left"].path), Path(s["right"].path), out / "lr.json", step_px=64)
    # the two dates differ by their sun and 10 % changed ground: the ground radiances
    # themselves disagree by ~0.1 px on 64-cell windows
    assert doc["n_valid"] > 20
    assert abs(doc["px"]["median_dx"]) < 0.2 and abs(doc["px"]["median_dy"]) < 0.2
    assert doc["px"]["median_norm"] < 0.35


@dataclass(frozen=True)
class ColumnBias:
    """A model whose image positions are ``dcol`` columns further."""

    model: Any
    dcol: float

    def project(self, lon, lat, h):
        c, r = self.model.project(lon, lat, h)
        return c + self.dcol, r

    def localize(self, col, row, h):
        return self.model.localize(np.asarray(col) - self.dcol, row, h)


def test_a_biased_model_moves_the_ortho_by_the_known_shift(orthos):
    scene_dir, out, s = orthos
    loaded = truth(scene_dir, "left")
    plan = T.plan_ortho.fn(loaded, describe_dem(scene_dir / "truth" / "dsm.tif"), RES)
    biased = replace(plan, model=replace(loaded, model=ColumnBias(loaded.model, 2.0)))
    T.orthorectify.fn(biased, out / "biased.tif")
    doc = compare(Path(s["left"].path), out / "biased.tif", out / "biased.json", step_px=64)
    # truth: the biased ortho shows at X what the image has 2 columns further, which the
    # true ortho shows at X' = localize(col + 2): content moves by X - X'
    c = np.array([300.0, 150.0, 450.0])
    r = np.array([300.0, 150.0, 450.0])
    h = np.full(3, 0.5 * sum(plan.h_range_m))
    proj = Projection(plan.epsg)
    x, y = proj.to_xy(*loaded.model.localize(c, r, h))
    x2, y2 = proj.to_xy(*loaded.model.localize(c + 2.0, r, h))
    dx, dy = float(np.mean(x - x2)) / RES, float(np.mean(y - y2)) / RES
    assert math.hypot(dx, dy) > 1.5
    assert doc["px"]["median_dx"] == pytest.approx(dx, abs=0.05)
    assert doc["px"]["median_dy"] == pytest.approx(dy, abs=0.05)


def test_tile_positions_agree_with_the_exact_chain_on_a_jittered_model(tiny_scene):
    scene_dir, _ = tiny_scene
    loaded = truth(scene_dir, "left")
    dsm = describe_dem(scene_dir / "truth" / "dsm.tif")
    plan = T.plan_ortho.fn(loaded, dsm, 20.0)
    g = plan.grid
    cells = GridSpec(g.x0_m + 300 * 20.0, g.y0_m - 300 * 20.0, 20.0, 400, 400)
    dem = read_tile_dem(dsm, cells.bounds_of(0, 400, 0, 400), plan.epsg, 0.0)
    proj = Projection(plan.epsg)
    geo = tile_geometry(loaded.model, cells, dem, proj.to_lonlat, OrthoConfig(step_px=128))
    i, j = np.mgrid[0:400, 0:400]
    x, y = cells.x0_m + (j + 0.5) * 20.0, cells.y0_m - (i + 0.5) * 20.0
    with rasterio.open(dsm.path) as src:
        z, t = src.read(1).astype(np.float64), src.transform
    ys = t.f + (np.arange(z.shape[0]) + 0.5) * t.e
    xs = t.c + (np.arange(z.shape[1]) + 0.5) * t.a
    h = RegularGridInterpolator((ys[::-1], xs), z[::-1])(np.stack([y, x], -1))
    col, row = loaded.model.project(*proj.to_lonlat(x, y), h)
    err = np.hypot(geo.col - col, geo.row - row)
    assert np.isfinite(err).mean() > 0.5
    assert np.nanmax(err) < 0.01


def test_tiles_join_without_seams_and_the_outputs_are_cogs(orthos, monkeypatch):
    scene_dir, out, s = orthos
    monkeypatch.setattr(T, "CHUNK", 200)
    small = make_ortho(truth(scene_dir, "left"), scene_dir / "truth" / "dsm.tif",
                       out / "tiled.tif")
    with rasterio.open(small.path) as a, rasterio.open(s["left"].path) as b:
        va, vb = a.read(1).astype(int), b.read(1).astype(int)
        assert a.profile["tiled"] and a.overviews(1) and a.nodata == 0
        assert a.transform == b.transform and a.tags()["dem_vertical"] == "ellipsoidal"
    both = (va > 0) & (vb > 0)
    assert ((va > 0) != (vb > 0)).sum() <= 10  # the footprint's edge, within 0.01 px
    assert np.abs(va - vb)[both].max() <= 1 and (va == vb)[both].mean() > 0.99
    with rasterio.open(s["left"].occlusion_path) as m:
        codes = m.read(1)
    assert set(np.unique(codes)) <= {0, 1, 255}
    assert ((codes == 255) == (vb == 0)).mean() > 0.999
    doc = json.loads(Path(s["left"].json_path).read_text())
    assert doc["format"] == "gcpfree.ortho" and doc["width"] == va.shape[1]


def test_tiles_in_worker_processes_write_what_threads_write(orthos, monkeypatch):
    """Two workers and 9 tiles run the tiles in processes (each saves its tile, the writer
    streams them back): the same bytes and the same counts as one worker's threads."""
    scene_dir, out, _ = orthos
    monkeypatch.setattr(T, "CHUNK", 200)
    used = []
    original = T._tiles_in_processes
    monkeypatch.setattr(T, "_tiles_in_processes",
                        lambda *a, **k: used.append(1) or original(*a, **k))
    cfg = OrthoConfig(occlusion=True)
    plan = T.plan_ortho.fn(truth(scene_dir, "right"), describe_dem(scene_dir / "truth" /
                                                                   "dsm.tif"), RES,
                           occlusion=True)
    one = T.orthorectify.fn(plan, out / "threads.tif", cfg, num_workers=1)
    assert not used
    two = T.orthorectify.fn(plan, out / "processes.tif", cfg, num_workers=2)
    assert used
    for a, b in ((one.path, two.path), (one.occlusion_path, two.occlusion_path)):
        with rasterio.open(a) as fa, rasterio.open(b) as fb:
            assert fa.profile == fb.profile
            assert np.array_equal(fa.read(1), fb.read(1))
    keys = ("valid_pct", "occluded_pct", "max_error_px", "min_step_px")
    assert [getattr(one, k) for k in keys] == [getattr(two, k) for k in keys]
    assert not list(out.glob(".processes.tif.tmp*"))  # the tiles' folder is gone


def test_window_blocks_in_worker_processes_find_what_threads_find(orthos, monkeypatch):
    """Blocks of 2 x 2 windows (at least 8 blocks) with two workers run in processes: every
    window's shift, correlation and status as one worker's."""
    import tasks.ortho.compare as C

    _, out, s = orthos
    monkeypatch.setattr(C, "BLOCK_WINDOWS", 2)
    plan = plan_compare.fn(Path(s["left"].path), Path(s["right"].path),
                           CompareConfig(step_px=64))
    docs = []
    for workers in (1, 2):
        compare_orthos.fn(plan, out / f"w{workers}.json", num_workers=workers)
        docs.append(json.loads((out / f"w{workers}.json").read_text()))
    assert C.schedule(16, 2, processes=None).scheduler == "processes"
    assert len(docs[0]["windows"]["status"]) >= 8 * 4
    assert docs[0]["windows"] == docs[1]["windows"]


# ---------------------------------------------------------------------------- GDAL


@pytest.fixture(scope="module")
def ventoux(data_dir, tmp_path_factory):
    """The Ventoux left crop, its RPC, and SRTM over it as an ellipsoidal lon/lat GeoTIFF."""
    out = tmp_path_factory.mktemp("ventoux")
    loaded = load_model(data_dir / "pleiades_ventoux" / "left_image.tif")
    lon, lat = footprint_lonlat(loaded.model, *loaded.size, (0.0, 2000.0))
    box = BBox(lon.min(), lat.min(), lon.max(), lat.max()).expanded(0.01)
    g = read_reference(BUNDLED_SRTM_DIR / "N44E005.hgt", box, "egm96")
    dem = out / "srtm_ellipsoidal.tif"
    t = Affine(g.dlon_deg, 0, g.lon0_deg - 0.5 * g.dlon_deg, 0, g.dlat_deg,
               g.lat0_deg - 0.5 * g.dlat_deg)
    with rasterio.open(dem, "w", driver="GTiff", width=g.h_m.shape[1], height=g.h_m.shape[0],
                       count=1, dtype="float64", crs="EPSG:4326", transform=t) as dst:
        dst.write(g.h_m, 1)
        dst.update_tags(vertical_datum="WGS84 ellipsoid")
    return out, loaded, dem


@pytest.mark.parametrize("resampling", ["bilinear", "cubic"])
def test_rpc_ortho_agrees_with_gdal_rpc_warp(ventoux, resampling):
    out, loaded, dem = ventoux
    plan = T.plan_ortho.fn(loaded, describe_dem(dem), 0.5)
    ours = T.orthorectify.fn(plan, out / f"ours_{resampling}.tif",
                             OrthoConfig(resampling=resampling))
    g = plan.grid
    with rasterio.open(loaded.image) as src:
        image = src.read(1)
    gdal = np.zeros(g.shape, np.uint16)
    rasterio.warp.reproject(
        image, gdal, rpcs=RPC.from_gdal(loaded.model.to_gdal_tags()), src_crs="EPSG:4326",
        dst_transform=Affine(*g.geotransform()), dst_crs=f"EPSG:{plan.epsg}",
        resampling=Resampling[resampling], dst_nodata=0, RPC_DEM=str(dem))
    gdal_path = out / f"gdal_{resampling}.tif"
    with rasterio.open(gdal_path, "w", driver="GTiff", width=g.n_cols, height=g.n_rows,
                       count=1, dtype="uint16", crs=f"EPSG:{plan.epsg}",
                       transform=Affine(*g.geotransform()), nodata=0) as dst:
        dst.write(gdal, 1)
    with rasterio.open(ours.path) as src:
        mine = src.read(1)
    both = (mine > 0) & (gdal > 0)
    assert both.mean() > 0.5
    assert ((mine > 0) != (gdal > 0)).mean() < 0.01  # the same footprint
    diff = np.abs(mine[both].astype(float) - gdal[both])
    assert diff.mean() < 0.5 and np.percentile(diff, 99) <= 2  # DN of a 0..1000+ image
    doc = compare(gdal_path, Path(ours.path), out / f"gdal_{resampling}.json", window_px=48,
                  step_px=48)
    assert doc["n_valid"] > 30
    assert doc["px"]["rms_norm"] < 0.05


# ---------------------------------------------------------------------------- bad input


def test_a_dem_away_from_the_image_is_one_line(ventoux, tmp_path):
    _, loaded, _ = ventoux
    far = tmp_path / "far.tif"
    with rasterio.open(far, "w", driver="GTiff", width=10, height=10, count=1,
                       dtype="float32", crs="EPSG:4326",
                       transform=Affine(0.01, 0, 10.0, 0, -0.01, 10.0)) as dst:
        dst.write(np.full((10, 10), 100.0, np.float32), 1)
    with pytest.raises(CoverageError, match="give a DEM covering the scene"):
        T.plan_ortho.fn(loaded, describe_dem(far, "ellipsoidal"))


def test_a_model_of_another_image_is_one_line(ventoux, tiny_scene):
    scene_dir, _ = tiny_scene
    _, loaded, dem = ventoux
    # a 600x600 pushbroom model named for a 500x500 crop at (5000, 5000): refused as it loads
    with pytest.raises(InputError, match="give the model of this image"):
        load_model(loaded.image, model=scene_dir / "truth" / "left_truth.json")


def test_bad_crs_and_untagged_projected_dem_are_one_line(ventoux, tiny_scene, tmp_path):
    scene_dir, _ = tiny_scene
    _, loaded, dem = ventoux
    with pytest.raises(InputError, match="not a projected CRS"):
        T.plan_ortho.fn(loaded, describe_dem(dem), epsg=4326)
    untagged = tmp_path / "dsm.tif"
    with rasterio.open(scene_dir / "truth" / "dsm.tif") as src:
        profile, z = src.profile, src.read(1)
    with rasterio.open(untagged, "w", **profile) as dst:
        dst.write(z, 1)
    with pytest.raises(InputError, match="--dem-vertical"):
        describe_dem(untagged)
    assert describe_dem(untagged, "egm96").vertical == "egm96"
