"""The DEM tasks on the tiny simulated pair (true models, so consistent) against its truth DSM,
and the refusals: a pair that does not correlate, no overlap, an ROI outside the image."""

from __future__ import annotations

import json
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import rasterio
from rasterio.errors import NotGeoreferencedWarning

from core.dem import sample_bilinear
from core.errors import GeometryError, InputError, InsufficientDataError
from core.matching.grid import MASK_VALID, remove_offset_and_tilt
from core.sensors.pushbroom import PushbroomModel
from core.simulation.landcover import LandCover
from tasks.dense.blocks import check_roi, tile_boxes
from tasks.dense.dem import DenseConfig, grid_dem_cog, match_tiles, plan_dense
from tasks.io.geoid import BUNDLED_SRTM_DIR
from tasks.io.sensors import LoadedModel, load_model

SRTM = BUNDLED_SRTM_DIR / "N44E005.hgt"
GSD_M = 40.0  # the tiny preset
CFG = DenseConfig(tile_px=300, progress=False)


def truth_pair(scene_dir: Path, right_image: Path | None = None) -> tuple[LoadedModel, ...]:
    out = []
    for name in ("left", "right"):
        model = PushbroomModel.from_json((scene_dir / "truth" / f"{name}_truth.json").read_text())
        image = scene_dir / f"{name}.tif"
        if name == "right" and right_image is not None:
            image = right_image
        out.append(LoadedModel(model, "pushbroom", scene_dir / "truth" / f"{name}_truth.json",
                               image, (model.n_cols, model.n_rows)))
    return tuple(out)


@pytest.fixture(scope="module")
def dem(tiny_clean_scene, tmp_path_factory):
    scene_dir, _ = tiny_clean_scene
    left, right = truth_pair(scene_dir)
    out = tmp_path_factory.mktemp("dense") / "dem.tif"
    plan = plan_dense.fn(left, right, None, SRTM, (0.0, 3000.0), "auto", CFG)
    work = out.parent / ".work"
    stats = match_tiles.fn(plan, left, right, work, CFG)
    summary = grid_dem_cog.fn(plan, stats, work, out, CFG)
    return scene_dir, plan, summary, out


def test_the_relative_dem_matches_the_truth_dsm_on_bare_soil(dem):
    """NMAD <= 1 GSD on bare soil after the best-fit 3-D offset and tilt (issue 10)."""
    scene_dir, plan, _summary, out = dem
    with rasterio.open(out) as src:
        z = src.read(1)
        t = src.transform
        assert src.crs.to_epsg() == plan.epsg
    rows, cols = np.nonzero(np.isfinite(z))
    x = t.c + (cols + 0.5) * t.a
    y = t.f + (rows + 0.5) * t.e
    with rasterio.open(scene_dir / "truth" / "dsm.tif") as src:
        truth = src.read(1).astype(np.float64)
        tt = src.transform
        assert src.crs.to_epsg() == plan.epsg
    with rasterio.open(scene_dir / "truth" / "landcover.tif") as src:
        classes = src.read(1)
    fi = (tt.f - y) / -tt.e - 0.5
    fj = (x - tt.c) / tt.a - 0.5
    z_true = sample_bilinear(truth, fi, fj)
    gy, gx = np.gradient(truth, -tt.e, tt.a)  # per metre, rows go south
    slope_x = sample_bilinear(gx, fi, fj)
    slope_y = -sample_bilinear(gy, fi, fj)
    fit = remove_offset_and_tilt(z[rows, cols] - z_true, x, y, slope_x, slope_y)
    cls = classes[np.clip(np.rint(fi).astype(int), 0, classes.shape[0] - 1),
                  np.clip(np.rint(fj).astype(int), 0, classes.shape[1] - 1)]
    bare = fit.residual_m[(cls == LandCover.BARE_SOIL) & np.isfinite(fit.residual_m)]
    nmad = 1.4826 * np.median(np.abs(bare - np.median(bare)))
    assert bare.size > 5000
    assert nmad <= GSD_M  # measured 13 m (0.3 GSD)
    # the true models leave no datum error worth a pixel, nor a horizontal shift: OpenCV's
    # 3-way SGM alone drags disparities from the rows above (a 10 m shift here; 0.45 m with
    # the second matching upside down)
    assert abs(fit.dz_m) < GSD_M and np.hypot(fit.dx_m, fit.dy_m) < 0.15 * GSD_M


def test_products_and_figures(dem):
    _, _plan, summary, out = dem
    assert summary.completeness_pct > 95.0 and summary.match_rate_pct > 95.0
    assert summary.mismatched_pct < 5.0 and summary.y_residual_max_px < 0.1
    assert summary.resolution_m == pytest.approx(2 * GSD_M, rel=0.05)
    assert 100.0 < summary.h_min_m < summary.h_max_m < 2100.0
    with rasterio.open(out) as src:
        assert "WGS84 ellipsoid" in src.tags()["vertical_datum"]
        assert src.tags(ns="IMAGE_STRUCTURE").get("LAYOUT") == "COG"
        z = src.read(1)
    with rasterio.open(summary.mask_path) as src:
        mask = src.read(1)
    assert set(np.unique(mask)) <= {0, 1, 2}
    assert ((mask == MASK_VALID) == np.isfinite(z)).all()
    doc = json.loads(Path(summary.json_path).read_text())
    assert doc["format"] == "gcpfree.dem" and len(doc["tiles"]) == summary.n_tiles
    assert all(0.9 < t["match_rate"] <= 1.0 for t in doc["tiles"])
    assert not (out.parent / ".work").exists()  # the tiles' points are removed


def test_a_pair_that_does_not_correlate_is_refused(tiny_clean_scene, tmp_path):
    scene_dir, _ = tiny_clean_scene
    with rasterio.open(scene_dir / "right.tif") as src:
        profile = src.profile
        noise = np.random.default_rng(0).integers(1, 255, (src.height, src.width), np.uint8)
    fake = tmp_path / "clouds.tif"
    profile.update(driver="GTiff")
    with warnings.catch_warnings():  # a raw sensor image has no geotransform
        warnings.simplefilter("ignore", NotGeoreferencedWarning)
        with rasterio.open(fake, "w", **profile) as dst:
            dst.write(noise, 1)
    left, right = truth_pair(scene_dir, right_image=fake)
    plan = plan_dense.fn(left, right, (150, 150, 300, 300), SRTM, (0.0, 3000.0), "auto", CFG)
    with pytest.raises(InsufficientDataError, match="do not correlate"):
        match_tiles.fn(plan, left, right, tmp_path / "work", CFG)


def test_no_overlap_and_an_roi_outside_the_image(tiny_clean_scene, data_dir):
    scene_dir, _ = tiny_clean_scene
    left, _ = truth_pair(scene_dir)
    elsewhere = load_model(data_dir / "pleiades_ventoux" / "right_image.tif")
    with pytest.raises(GeometryError, match="do not overlap"):
        plan_dense.fn(left, elsewhere, None, SRTM, (0.0, 3000.0), "auto", CFG)
    with pytest.raises(InputError, match="outside the left image"):
        check_roi((700, 10, 100, 100), (600, 600))
    assert check_roi((-10, 500, 100, 200), (600, 600)) == (0, 500, 90, 600)


@pytest.mark.parametrize(("roi", "tile_px", "grid"), [
    ((10, 20, 2510, 1020), 1000, (2, 1)),  # 2.5 tiles across: rounded to 2
    ((0, 0, 600, 600), 300, (2, 2)),
    ((5, 7, 1642, 1107), 500, (3, 2)),  # uneven sizes: 545-546 by 550 px
    ((3, 4, 120, 90), 1000, (1, 1)),  # smaller than a tile
])
def test_tiles_cover_the_roi_once(roi, tile_px, grid):
    """Every pixel of the ROI is in exactly one tile, none outside it; as many tiles as the
    ROI holds rounded, of equal sizes to a pixel (painted, not summed: an overlap and a gap
    of the same size would sum to the right area)."""
    boxes = tile_boxes(roi, tile_px)
    assert len(boxes) == grid[0] * grid[1]
    c0, r0, c1, r1 = roi
    count = np.zeros((r1 + 5, c1 + 5), dtype=int)
    for b0, a0, b1, a1 in boxes:
        assert b0 < b1 and a0 < a1
        count[a0:a1, b0:b1] += 1
    inside = np.zeros_like(count, dtype=bool)
    inside[r0:r1, c0:c1] = True
    assert (count[inside] == 1).all() and (count[~inside] == 0).all()
    widths = {b1 - b0 for b0, _, b1, _ in boxes}
    heights = {a1 - a0 for _, a0, _, a1 in boxes}
    assert max(widths) - min(widths) <= 1 and max(heights) - min(heights) <= 1
    assert len({b0 for b0, _, _, _ in boxes}) == grid[0]  # columns x rows as expected
    assert len({a0 for _, a0, _, _ in boxes}) == grid[1]


def test_tiles_in_processes_give_what_threads_give(tiny_clean_scene, tmp_path):
    scene_dir, _ = tiny_clean_scene
    left, right = truth_pair(scene_dir)
    plan = plan_dense.fn(left, right, (0, 100, 600, 300), SRTM, (0.0, 3000.0), "auto", CFG)
    assert len(plan.tiles) == 2
    runs = []
    for processes in (False, True):
        cfg = DenseConfig(tile_px=300, progress=False, processes=processes, num_workers=2)
        runs.append(match_tiles.fn(plan, left, right, tmp_path / str(processes), cfg))
    assert [s.to_dict() for s in runs[0]] == [s.to_dict() for s in runs[1]]


def test_saved_matches_are_triangulated_again_with_other_models(tiny_clean_scene, tmp_path):
    """The final DSM reuses the matching: the same models give back the same points; other
    models (the right one's roll changed by 0.1 mrad) give the exact intersection of the same
    correspondences through them."""
    from core.intersection import triangulate
    from core.matching.dense_tile import core_pixels
    from core.matching.rectify import TileRectification
    from tasks.dense.blocks import tile_points_path
    from tasks.dense.dem import retriangulate_tiles
    from tasks.io.crs import Projection

    scene_dir, _ = tiny_clean_scene
    left, right = truth_pair(scene_dir)
    plan = plan_dense.fn(left, right, (0, 100, 600, 300), SRTM, (0.0, 3000.0), "auto", CFG)
    stats = match_tiles.fn(plan, left, right, tmp_path / "a", CFG)
    same = retriangulate_tiles.fn(plan, stats, tmp_path / "a", tmp_path / "b", left.model,
                                  right.model, CFG)
    for s in stats:
        with np.load(tile_points_path(tmp_path / "a", s.index)) as a, \
                np.load(tile_points_path(tmp_path / "b", s.index)) as b:
            assert np.array_equal(a["status"], b["status"])
            for k in ("dx", "dy", "h"):
                assert np.allclose(a[k], b[k], atol=2e-3, equal_nan=True)
    assert np.allclose([s.bounds_m for s in same], [s.bounds_m for s in stats], atol=0.01)
    moved = right.model.with_params(right.model.params + np.r_[1e-4, np.zeros(5)])
    other = retriangulate_tiles.fn(plan, stats, tmp_path / "a", tmp_path / "c", left.model,
                                   moved, CFG)
    to_xy = Projection(plan.epsg).to_xy
    rng = np.random.default_rng(0)
    for s in other:
        with np.load(tile_points_path(tmp_path / "a", s.index)) as a, \
                np.load(tile_points_path(tmp_path / "c", s.index)) as c:
            rect = TileRectification.from_dict(json.loads(str(a["rect"])))
            uu, vv, core = core_pixels(rect, tuple(a["window"]), tuple(a["core"]))
            ok = np.flatnonzero(a["status"] == 0)
            pick = rng.choice(ok, 200, replace=False)
            u, v, d = uu[core][pick], vv[core][pick], a["d"][pick].astype(float)
            lc, lr = rect.rect_to_left(u, v)
            rc, rr = rect.rect_to_right(u - d, v)
            t = triangulate([left.model, moved], [lc, rc], [lr, rr], (-500.0, 4000.0))
            x, y = to_xy(t.lon_deg, t.lat_deg)
            assert np.allclose(c["dx"][pick] + plan.origin_m[0], x, atol=0.05)
            assert np.allclose(c["dy"][pick] + plan.origin_m[1], y, atol=0.05)
            assert np.allclose(c["h"][pick], t.h_m, atol=0.05)
            # and the points did move: the roll change is ~60 m on the ground
            assert np.median(np.abs(c["h"][pick] - a["h"][pick])) > 5.0


def test_the_egm96_twin_is_the_ellipsoidal_dem_less_the_geoid(tiny_clean_scene, tmp_path):
    """``grid_dem_cog(egm96_out=...)``: one triangulation, the EGM96 DEM made from the
    ellipsoidal grid cell by cell. Against an oracle independent of core.geoid and of the
    GTX reader (PROJ's inverse UTM and vgridshift on the bundled grid, at each cell's centre)
    within 0.2 mm (float32 heights); against the DEM the points triangulated with the geoid
    make (the former way: N per point, fitted by each tile's polynomials, then gridded)
    within 5 mm, with the same mask. A geoid of the wrong sign, at swapped coordinates or at
    cell corners fails the first."""
    import pyproj

    from tasks.dense.dem import retriangulate_tiles
    from tasks.io.geoid import EGM96_GTX

    scene_dir, _ = tiny_clean_scene
    left, right = truth_pair(scene_dir)
    plan = plan_dense.fn(left, right, (0, 0, 600, 600), SRTM, (0.0, 3000.0), "auto", CFG)
    stats = match_tiles.fn(plan, left, right, tmp_path / "m", CFG)
    ell = retriangulate_tiles.fn(plan, stats, tmp_path / "m", tmp_path / "e", left.model,
                                 right.model, CFG)
    grid_dem_cog.fn(plan, ell, tmp_path / "e", tmp_path / "dsm.tif", CFG,
                    egm96_out=tmp_path / "dsm_egm96.tif")
    egm = replace(CFG, vertical="egm96")
    old = retriangulate_tiles.fn(plan, stats, tmp_path / "m", tmp_path / "g", left.model,
                                 right.model, egm)
    grid_dem_cog.fn(plan, old, tmp_path / "g", tmp_path / "old_egm96.tif", egm)

    def read(name: str) -> tuple[np.ndarray, ...]:
        with rasterio.open(tmp_path / name) as src:
            return src.read(1), src.transform, src.crs, src.tags()

    h, t, crs, _ = read("dsm.tif")
    big_h, t2, crs2, tags = read("dsm_egm96.tif")
    former, _, crs3, _ = read("old_egm96.tif")
    assert t2 == t and crs.to_epsg() == plan.epsg and crs2 == crs3 and "5773" in crs2.to_wkt()
    assert "EGM96" in tags["vertical_datum"]
    for name in ("dsm_egm96_mask.tif", "old_egm96_mask.tif"):
        assert np.array_equal(read(name)[0], read("dsm_mask.tif")[0])
    ok = np.isfinite(h)
    assert ok.sum() > 0.5 * h.size and np.array_equal(ok, np.isfinite(big_h))
    assert np.array_equal(ok, np.isfinite(former))
    rows, cols = np.nonzero(ok)
    zone = plan.epsg % 100
    proj = pyproj.Transformer.from_pipeline(
        f"+proj=pipeline +step +inv +proj=utm +zone={zone} +ellps=WGS84 "
        f"+step +proj=vgridshift +grids={EGM96_GTX} +multiplier=-1")
    _, _, oracle = proj.transform(t.c + (cols + 0.5) * t.a, t.f + (rows + 0.5) * t.e,
                                  h[ok].astype(np.float64))
    assert np.abs(big_h[ok] - oracle).max() < 2e-4
    assert np.ptp(h[ok] - big_h[ok]) > 0.05  # the geoid varies over the scene
    assert np.abs(big_h[ok] - former[ok]).max() < 5e-3
    summary = json.loads((tmp_path / "dsm_egm96.json").read_text())
    assert summary["vertical"] == "egm96"
    assert summary["h_max_m"] == pytest.approx(float(big_h[ok].max()), abs=1e-3)
