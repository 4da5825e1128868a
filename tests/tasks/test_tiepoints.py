"""Tie points of whole pairs (tasks.relative.tiepoints): a simulated tiny pair scored against its truth,
and the real Pleiades pairs."""

from __future__ import annotations

import json
import os
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import rasterio
from pyproj import Transformer
from rasterio.errors import NotGeoreferencedWarning
from rasterio.transform import from_origin
from rasterio.warp import Resampling, calculate_default_transform, reproject

from core.dem import GeoDEM
from core.errors import CoverageError, GeometryError, InputError
from core.geodesy import BBox
from core.matching.tiepoint_results import TiePointResult, TiePoints
from core.matching.tiepoints import TiePointConfig
from core.sensors.base import localize_on_dem
from core.sensors.pushbroom import PushbroomModel
from core.sensors.pushbroom_synthetic import SyntheticSpec, synthetic_pushbroom
from core.simulation.landcover import LandCover
from tasks.io.geoid import BUNDLED_SRTM_DIR
from tasks.io.reference import build_reference, locate_tiles
from tasks.io.sensors import load_model
from tasks.relative.tiepoints import find_tie_points, resumed_tie_points, tie_measure

DATA = Path(__file__).resolve().parents[1] / "data"
SHARED = Path(os.environ.get("GCPFREE_SHARED_DATA", "/work/shared/data"))
SRTM = BUNDLED_SRTM_DIR / "N44E005.hgt"
# tiny: 600x600 px at 40 m, so 1 km cells (25 px) give enough cells (about 550)
TINY_CFG = TiePointConfig(cell_m=1000.0, points_per_tile=8000)


@pytest.fixture(scope="session")
def reference_cog(tmp_path_factory) -> Path:
    """The bundled SRTM tile over the Ventoux area, ellipsoidal (prepare-reference's tasks)."""
    out = tmp_path_factory.mktemp("reference") / "ref.tif"
    box = BBox(5.0, 44.0, 5.55, 44.45)
    build_reference.fn(locate_tiles.fn(BUNDLED_SRTM_DIR, box), box, out)
    return out


def truth_dem(scene: Path) -> GeoDEM:
    """The truth DSM (UTM) resampled bilinearly to lon/lat for localize_on_dem."""
    with rasterio.open(scene / "truth" / "dsm.tif") as src:
        t, w, h = calculate_default_transform(src.crs, "EPSG:4326", src.width, src.height,
                                              *src.bounds)
        z = np.full((h, w), np.nan, np.float64)
        reproject(src.read(1).astype(np.float64), z, src_transform=src.transform,
                  src_crs=src.crs, dst_transform=t, dst_crs="EPSG:4326",
                  resampling=Resampling.bilinear, src_nodata=np.nan, dst_nodata=np.nan)
    return GeoDEM.from_transform(z, tuple(t)[:6])


def true_right(scene: Path, col: np.ndarray, row: np.ndarray) -> tuple[np.ndarray, ...]:
    """Where the truth puts left pixels in the right image (ray cast on the truth DSM), and
    the unit epipolar direction there."""
    tl, tr = (PushbroomModel.from_json((scene / "truth" / f"{n}_truth.json").read_text())
              for n in ("left", "right"))
    lon, lat, h = localize_on_dem(tl, col, row, truth_dem(scene))
    c, r = tr.project(lon, lat, h)
    c2, r2 = tr.project(*tl.localize(col, row, h + 50.0), h + 50.0)
    e = np.stack([c2 - c, r2 - r])
    return c, r, e / np.linalg.norm(e, axis=0)


def water_share(scene: Path) -> float:
    """Share of the left image's pixels (a 40 x 40 grid) that see water (truth land cover)."""
    tl = PushbroomModel.from_json((scene / "truth" / "left_truth.json").read_text())
    cc, rr = np.meshgrid(np.linspace(0, tl.n_cols - 1, 40), np.linspace(0, tl.n_rows - 1, 40))
    lon, lat, _ = localize_on_dem(tl, cc.ravel(), rr.ravel(), truth_dem(scene))
    with rasterio.open(scene / "truth" / "landcover.tif") as src:
        x, y = Transformer.from_crs("EPSG:4326", src.crs, always_xy=True).transform(lon, lat)
        values = np.array([v[0] for v in src.sample(zip(x, y, strict=True))])
    return float(np.mean(values == LandCover.WATER))


def search(scene: Path, reference: Path | GeoDEM, cfg: TiePointConfig = TINY_CFG,
           **kw: object) -> TiePointResult:
    """Tie points of a simulated pair with the models of its SPOT metadata (left.DIM...)."""
    left, right = load_model(scene / "left.tif"), load_model(scene / "right.tif")
    assert left.source.suffix == ".DIM"  # the SPOT metadata beside the image
    return find_tie_points.fn(scene / "left.tif", scene / "right.tif", left.model, right.model,
                              reference, cfg, **kw)


@pytest.fixture(scope="module")
def clean(tiny_clean_scene, reference_cog) -> tuple[Path, TiePointResult]:
    """The session's clean tiny pair (lens distortion unknown to the metadata)."""
    scene = tiny_clean_scene[0]
    return scene, search(scene, reference_cog, out=scene / "tiepoints.json")


def errors_against_truth(scene: Path, tp: TiePoints) -> tuple[np.ndarray, ...]:
    """(across, along, 2-D) errors of the tie points' right positions against the truth, in
    right pixels, split on the epipolar line; points whose truth is undefined are dropped."""
    c, r, epi = true_right(scene, tp.left_col, tp.left_row)
    ok = np.isfinite(c)
    assert ok.mean() > 0.98
    d = np.stack([tp.right_col - c, tp.right_row - r])[:, ok]
    epi = epi[:, ok]
    return epi[0] * d[1] - epi[1] * d[0], np.sum(d * epi, axis=0), np.hypot(*d)


def test_tiny_tie_points_cover_the_textured_cells(clean):
    """Every land cover but water is textured; this scene has almost no water (checked on the
    truth land cover under the left image), so the share of all overlap cells is a lower bound
    of the share of textured cells. Measured: 526 tie points in 94 % of the 559 overlap cells
    of 1 km (97 % of the 540 holding an interest point), median correlation 0.96."""
    scene, result = clean
    assert water_share(scene) < 0.02
    rep, tp = result.report, result.tie_points
    assert rep.n_cells > 450 and rep.coverage >= 0.8 and rep.coverage_textured >= 0.8
    assert len(tp) == rep.n_points >= rep.n_cells_with_point  # a few in border slivers
    assert np.all(tp.ok) and np.all(tp.correlation >= TINY_CFG.correlation_floor)
    assert len(np.unique(tp.cell_id)) == len(tp)
    assert rep.correlation_p50 > 0.9
    saved = TiePointResult.from_dict(json.loads((scene / "tiepoints.json").read_text()))
    np.testing.assert_array_equal(saved.tie_points.right_col, tp.right_col)


def test_tiny_tie_points_agree_with_the_true_correspondence(clean):
    """Against the truth (left pixel ray-cast on the truth DSM, projected by the true right
    model). Across the epipolar lines (what relative orientation uses) measured RMS 0.10 px.
    Along them the error is a height error: the 15x15 template (600 m at 40 m) sees relief,
    canopy and roofs whose parallax differs from the centre pixel's, so area matching measures
    a template average (measured RMS 0.34 px, 2-D median 0.23 px; against the truth averaged
    over the template the 2-D median is about 40 % lower); 1 % of the points exceed 1 px (at
    most 1.6 px) where the true disparity within the template is far from planar. On synthetic
    images the matcher is within 0.01-0.04 px."""
    across, along, err = errors_against_truth(clean[0], clean[1].tie_points)
    assert np.sqrt(np.mean(across**2)) < 0.2
    assert np.sqrt(np.mean(along[np.abs(along) < 1] ** 2)) < 0.45
    assert np.median(err) < 0.35
    assert np.mean(err < 1.0) > 0.97


def test_tiny_pair_changed_between_dates(tiny_scene, reference_cog):
    """The session's harder pair: attitude jitter and 10 % of the ground changed between the
    dates in blobs about the size of a template at 40 m, so fewer cells get a point; those
    found are still right across the epipolar lines. Measured: 345 tie points in 62 % of 550
    cells (532 candidates under 0.7 correlation, 224 failed the back-match), across-epipolar
    RMS 0.19 px, 98 % within 1 px of the truth."""
    scene = tiny_scene[0]
    result = search(scene, reference_cog)
    assert result.report.coverage >= 0.5
    across, _, err = errors_against_truth(scene, result.tie_points)
    assert np.sqrt(np.mean(across[np.abs(across) < 1] ** 2)) < 0.3
    assert np.mean(err < 1.0) > 0.9


def test_tiling_does_not_change_the_matches(clean):
    """Smaller blocks (4 instead of 1): every point found both ways is matched identically."""
    scene, result = clean
    small = search(scene, _ellipsoidal_srtm(), replace(TINY_CFG, tile_px=300), num_workers=1)
    a, b = result.tie_points, small.tie_points
    key_a = {(c, r): i for i, (c, r) in enumerate(zip(a.left_col, a.left_row, strict=True))}
    common = [(key_a[(c, r)], j) for j, (c, r) in enumerate(zip(b.left_col, b.left_row,
                                                                strict=True)) if (c, r) in key_a]
    assert len(common) > 0.5 * len(a)
    i, j = np.array(common).T
    np.testing.assert_allclose(b.right_col[j], a.right_col[i], atol=2e-3)
    np.testing.assert_allclose(b.right_row[j], a.right_row[i], atol=2e-3)
    assert small.report.coverage >= 0.8


def _ellipsoidal_srtm() -> GeoDEM:
    """The bundled SRTM tile as a GeoDEM of ellipsoidal heights (h = H + N, EGM96)."""
    from tasks.io.geoid import load_geoid

    with rasterio.open(SRTM) as src:
        H = src.read(1).astype(np.float64)
        H[H == src.nodata] = np.nan
        dem = GeoDEM.from_transform(H, tuple(src.transform)[:6])
    ii, jj = np.mgrid[0:H.shape[0], 0:H.shape[1]]
    lon = dem.lon0_deg + jj * dem.dlon_deg
    lat = dem.lat0_deg + ii * dem.dlat_deg
    h = load_geoid().orthometric_to_ellipsoidal(lon, lat, H)
    return GeoDEM(h, dem.lon0_deg, dem.lat0_deg, dem.dlon_deg, dem.dlat_deg)


# ---------------------------------------------------------------------------- real pairs


def test_ventoux_pair_gives_well_correlated_tie_points():
    """Pleiades crops (0.7 m) with their own RPCs, SRTM heights; the RPCs are good to ~10 m
    so the search radius is 15 m. Measured: 35 tie points in 83 % of 42 cells of 25 m (the
    crops overlap on ~120 m only), all with correlation > 0.8 (median 0.97)."""
    v = DATA / "pleiades_ventoux"
    left, right = load_model(v / "left_image.tif"), load_model(v / "right_image.tif")
    # the 25 m cells as given: the overlap holds 42 of them, fewer than the 8 x 8 cells the
    # default (min_cells_per_side) would cut it into
    cfg = TiePointConfig(search_radius_m=15.0, cell_m=25.0, min_cells_per_side=0)
    res = find_tie_points.fn(v / "left_image.tif", v / "right_image.tif", left.model,
                             right.model, _ellipsoidal_srtm(), cfg)
    tp = res.tie_points
    assert len(tp) >= 25 and res.report.coverage >= 0.7
    assert np.mean(tp.correlation > 0.8) >= 0.9


def _rpc_height_range(*models) -> tuple[float, float]:
    return (min(m.alt_off - m.alt_scale for m in models),
            max(m.alt_off + m.alt_scale for m in models))


@pytest.mark.slow
def test_reunion_pair_with_the_rpc_height_range():
    """No reference DEM here: the heights span the RPCs' validity range (-20..2610 m). The
    default 2 km cell is larger than the 1024 px crop (0.5 m Pleiades, so ~512 m): the overlap
    is cut into 8 x 8 cells of ~64 m. Measured: 64 tie points, 100 % of 64 cells of 64.7 m,
    median correlation 0.95."""
    v = DATA / "pleiades_reunion"
    left, right = load_model(v / "img_01.tif"), load_model(v / "img_02.tif")
    cfg = TiePointConfig(search_radius_m=15.0)
    res = find_tie_points.fn(v / "img_01.tif", v / "img_02.tif", left.model, right.model, None,
                             cfg, h_range_m=_rpc_height_range(left.model, right.model))
    assert res.report.cell_m == pytest.approx(1024 * 0.5 / 8, rel=0.03)
    assert 49 <= res.report.n_cells <= 81
    assert len(res.tie_points) >= 40 and res.report.coverage >= 0.8
    assert res.report.correlation_p50 > 0.8


@pytest.mark.skipif(not (SHARED / "pleiades_gizeh" / "img1.tif").is_file(),
                    reason="the shared Gizeh pair is not on this machine")
def test_gizeh_pair_with_the_rpc_height_range():
    """Measured: 82 tie points, 100 % of 73 cells of 50 m, median correlation 0.99."""
    v = SHARED / "pleiades_gizeh"
    left, right = load_model(v / "img1.tif"), load_model(v / "img2.tif")
    cfg = TiePointConfig(search_radius_m=15.0, cell_m=50.0)
    res = find_tie_points.fn(v / "img1.tif", v / "img2.tif", left.model, right.model, None, cfg,
                             h_range_m=_rpc_height_range(left.model, right.model))
    assert len(res.tie_points) >= 50 and res.report.coverage >= 0.8
    assert res.report.correlation_p50 > 0.8


def test_the_tie_measure_is_read_from_the_metadata_suns():
    """``auto`` takes the suns the metadata state (``LoadedModel.sun``: a SPOT ``.DIM``'s,
    as real SPOT 2 DIMAP files give them, or the one a gcpfree model file carries); without
    them, or when the user names a measure, no guess is made."""
    from types import SimpleNamespace

    from tasks.io.sensors import LoadedModel

    def loaded(az, el, sun_deg=None):
        spot = None if az is None else SimpleNamespace(sun_azimuth_deg=az, sun_elevation_deg=el)
        return LoadedModel(None, "pushbroom", Path("x.DIM"), None, (1, 1), spot,
                           sun_deg=sun_deg)  # type: ignore[arg-type]

    def auto(a, b):
        return tie_measure("auto", a.sun, b.sun)

    assert auto(loaded(140.0, 63.0), loaded(158.0, 50.0))[0] == "orientation"
    assert auto(loaded(140.0, 63.0), loaded(140.2, 63.1))[0] == "ncc"
    assert auto(loaded(140.0, None), loaded(158.0, 50.0))[0] == "ncc"
    assert auto(loaded(None, None, (140.0, 63.0)), loaded(None, None, (158.0, 50.0)))[0] \
        == "orientation"
    assert auto(loaded(None, None), loaded(None, None)) == (
        "ncc", "the suns are not in both images' metadata")
    assert tie_measure("orientation", None, None) == ("orientation", "as asked")
    assert tie_measure("ncc", (140.0, 63.0), (158.0, 50.0)) == ("ncc", "as asked")


# ---------------------------------------------------------------------------- bad input


@pytest.fixture(scope="module")
def small_pair(tmp_path_factory) -> tuple[Path, Path]:
    d = tmp_path_factory.mktemp("pair")
    rng = np.random.default_rng(0)
    paths = []
    for name in ("a", "b"):
        p = d / f"{name}.tif"
        with warnings.catch_warnings():  # raw sensor geometry: no georeference
            warnings.simplefilter("ignore", NotGeoreferencedWarning)
            with rasterio.open(p, "w", driver="GTiff", width=200, height=200, count=1,
                               dtype="uint8") as dst:
                dst.write(rng.integers(1, 255, (200, 200), dtype=np.uint8), 1)
        paths.append(p)
    return paths[0], paths[1]


def _model(lon: float, lat: float) -> PushbroomModel:
    return synthetic_pushbroom(SyntheticSpec(lon, lat, n_cols=200, n_rows=200, gsd_m=20.0))


def test_a_height_source_is_required(small_pair):
    m = _model(5.25, 44.2)
    with pytest.raises(InputError, match="height range"):
        find_tie_points.fn(*small_pair, m, m, None, TiePointConfig())


def test_images_that_do_not_overlap_are_refused(small_pair):
    with pytest.raises(GeometryError, match="do not overlap"):
        find_tie_points.fn(*small_pair, _model(5.25, 44.2), _model(5.6, 44.2), None,
                           TiePointConfig(), h_range_m=(0.0, 500.0))


def test_a_reference_that_misses_the_scene_or_is_projected_is_refused(small_pair, tmp_path):
    far = tmp_path / "far.tif"
    utm = tmp_path / "utm.tif"
    for path, crs, t in ((far, "EPSG:4326", from_origin(20.0, 10.0, 0.001, 0.001)),
                         (utm, "EPSG:32631", from_origin(600000, 4900000, 30, 30))):
        with rasterio.open(path, "w", driver="GTiff", width=50, height=50, count=1,
                           dtype="float32", crs=crs, transform=t, nodata=np.nan) as dst:
            dst.write(np.full((50, 50), 500.0, np.float32), 1)
            dst.update_tags(vertical_datum="WGS84 ellipsoid")
    m = _model(5.25, 44.2)
    with pytest.raises(CoverageError, match="does not cover"):
        find_tie_points.fn(*small_pair, m, m, far, TiePointConfig())
    with pytest.raises(InputError, match="EPSG:4326"):
        find_tie_points.fn(*small_pair, m, m, utm, TiePointConfig())


def test_tie_points_are_read_back_on_a_rerun_of_the_same_inputs_only(tmp_path, prefect_harness):
    """``resumed_tie_points`` (the N-image flows' tie points, ``gcpfree block`` and
    ``dsm --images``): the first call matches and keeps them beside the outputs, a rerun with
    the same images, models, reference and settings reads them back whole; other settings, a
    touched image or a damaged file match again."""
    v = DATA / "pleiades_ventoux"
    left, right = load_model(v / "left_image.tif"), load_model(v / "right_image.tif")
    cfg = TiePointConfig(search_radius_m=15.0, cell_m=25.0, min_cells_per_side=0)
    dem, cache = _ellipsoidal_srtm(), tmp_path / "ties.json"
    first, resumed = resumed_tie_points(left, right, dem, cfg, cache, reference_path=SRTM)
    assert not resumed and cache.is_file() and len(first.tie_points) >= 25
    again, resumed = resumed_tie_points(left, right, dem, cfg, cache, reference_path=SRTM)
    assert resumed
    for name in ("left_col", "left_row", "right_col", "right_row", "correlation", "h_m"):
        np.testing.assert_array_equal(getattr(again.tie_points, name),
                                      getattr(first.tie_points, name))
    assert again.report.to_dict() == first.report.to_dict()
    other, resumed = resumed_tie_points(left, right, dem, replace(cfg, cell_m=30.0), cache,
                                        reference_path=SRTM)
    assert not resumed and other.report.cell_m == pytest.approx(30.0)
    cache.write_text(cache.read_text()[:100])  # a writer killed mid-file (not atomic)
    redone, resumed = resumed_tie_points(left, right, dem, replace(cfg, cell_m=30.0), cache,
                                         reference_path=SRTM)
    assert not resumed and len(redone.tie_points) == len(other.tie_points)
    copy = tmp_path / "left_image.tif"  # the same pixels elsewhere: another image's key
    copy.write_bytes((v / "left_image.tif").read_bytes())
    moved, resumed = resumed_tie_points(replace(left, image=copy), right, dem,
                                        replace(cfg, cell_m=30.0), cache,
                                        reference_path=SRTM)
    assert not resumed and len(moved.tie_points) == len(other.tie_points)
