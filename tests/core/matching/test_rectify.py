"""Per-tile affine rectification: residual y-parallax, disparity against height, plans, warps.

Truth is the simulator's SPOT pair geometry (true models, no image needed) and its own
projections: a ground point seen in both images must land on the same rectified row, and its
disparity must follow its height.
"""

import numpy as np
import pytest

from core.dem import GeoDEM
from core.errors import GeometryError, InputError
from core.matching.rectify import (
    RectifyConfig,
    TerrainSample,
    plan_tile,
    plan_tile_on_dem,
    predicted_disparity,
    rectify_tile,
    sample_terrain,
    warp_to_window,
)
from core.points import GeoPoint
from core.simulation.scene import PRESETS, ErrorConfig, scene_models

H0 = 600.0


@pytest.fixture(scope="module")
def spot_pair():
    models = scene_models(PRESETS["spot"], GeoPoint(5.25, 44.2, H0), ErrorConfig(), seed=1)
    return models["left"].truth, models["right"].truth


def random_ground(left, box, h_range, n, seed):
    rng = np.random.default_rng(seed)
    c0, r0, c1, r1 = box
    col = rng.uniform(c0, c1 - 1, n)
    row = rng.uniform(r0, r1 - 1, n)
    h = rng.uniform(*h_range, n)
    lon, lat = left.localize(col, row, h)
    return col, row, h, lon, lat


@pytest.mark.parametrize("box", [(0, 0, 1000, 1000), (2500, 4000, 3500, 5000),
                                 (5000, 5000, 6000, 6000)])
def test_a_1000_px_tile_leaves_under_a_tenth_of_a_pixel_of_y_parallax(spot_pair, box):
    left, right = spot_pair
    h_range = (H0 - 500.0, H0 + 500.0)
    rect = rectify_tile(left, right, box, h_range)
    assert rect.y_residual_max_px < 0.1
    # independent check: random ground points, projected by the models, share a row
    col, row, h, lon, lat = random_ground(left, box, h_range, 2000, seed=5)
    cr, rr = right.project(lon, lat, h)
    _, v_left = rect.left_to_rect(col, row)
    _, v_right = rect.right_to_rect(cr, rr)
    assert np.max(np.abs(v_left - v_right)) < 0.1


def test_the_whole_scene_is_not_affine(spot_pair):
    """Why tiles: one affine over the 6000 px scene leaves more than a pixel."""
    left, right = spot_pair
    rect = rectify_tile(left, right, (0, 0, 6000, 6000), (H0 - 500.0, H0 + 500.0))
    assert rect.y_residual_max_px > 0.5


def test_disparity_follows_height_with_the_pairs_base(spot_pair):
    left, right = spot_pair
    box = (2000, 2000, 3000, 3000)
    rect = rectify_tile(left, right, box, (H0 - 500.0, H0 + 500.0), h_ref_m=H0)
    col, row, h, _lon, _lat = random_ground(left, box, (H0 - 500.0, H0 + 500.0), 500, seed=2)
    # near zero at the reference height: the right image is resampled onto that surface by
    # an affine, which the changing incidence across 10 km bends by a pixel or two ...
    d0 = predicted_disparity(rect, left, right, col, row, np.full(col.shape, H0))
    assert np.max(np.abs(d0)) < 2.0
    # ... and growing in proportion to the height above it, the ratio varying by a few
    # percent over the tile
    d = predicted_disparity(rect, left, right, col, row, h)
    far = np.abs(h - H0) > 50.0
    ratio = (d - d0)[far] / (h[far] - H0)
    assert np.max(np.abs(ratio / rect.disparity_per_m - 1.0)) < 0.05
    # B/H about 0.84 at 10 m pixels: about 0.084 px of disparity per metre of height
    assert abs(rect.disparity_per_m) == pytest.approx(0.084, rel=0.1)


def test_maps_invert_and_left_keeps_its_scale(spot_pair):
    left, right = spot_pair
    rect = rectify_tile(left, right, (0, 0, 800, 600), (0.0, 1200.0))
    c = np.array([0.0, 799.0, 400.5])
    r = np.array([0.0, 599.0, 300.25])
    np.testing.assert_allclose(rect.rect_to_left(*rect.left_to_rect(c, r)), (c, r), atol=1e-9)
    np.testing.assert_allclose(rect.rect_to_right(*rect.right_to_rect(c, r)), (c, r), atol=1e-9)
    a = rect.left_affine[:, :2]
    np.testing.assert_allclose(a @ a.T, np.eye(2), atol=1e-12)  # a rotation


def test_plan_covers_the_predicted_disparities_with_the_margin(spot_pair):
    left, right = spot_pair
    core = (1000, 1000, 2000, 2000)
    h = np.full(100, H0)
    h[:50] = H0 + 300.0
    rng = np.random.default_rng(0)
    terrain = TerrainSample(rng.uniform(1000, 1999, 100), rng.uniform(1000, 1999, 100), h)
    plan = plan_tile(0, left, right, core, terrain, margin_m=50.0)
    assert plan.n_disp % 16 == 0
    # the terrain's own disparities, and 50 m either side, are inside 0 .. n_disp - 1
    for dh in (-50.0, 0.0, 50.0):
        d = predicted_disparity(plan.rect, left, right, terrain.col, terrain.row, h + dh)
        assert d.min() >= 0 and d.max() <= plan.n_disp - 1
    # the window pads the core by the search range and the context margin
    u0, _v0, w, _hgt = plan.window
    cu, _cv = plan.rect.left_to_rect(np.array([1000, 1999]), np.array([1000, 1999]))
    assert u0 + plan.n_disp <= cu.min() and cu.max() <= u0 + w - 1 - plan.n_disp
    narrow = plan.narrowed(10.0, 20.0)
    assert narrow.n_disp == 16 and narrow.window[2] == w - 2 * (plan.n_disp - 16)
    # the same ground point keeps its rectified right position minus the shift
    d_old = predicted_disparity(plan.rect, left, right, 1500.0, 1500.0, H0)
    d_new = predicted_disparity(narrow.rect, left, right, 1500.0, 1500.0, H0)
    assert d_new == pytest.approx(d_old - 10.0, abs=1e-9)


def test_plan_on_a_dem_and_no_overlap(spot_pair):
    left, right = spot_pair
    lon, lat = left.localize(np.array([0.0, 5999.0]), np.array([0.0, 5999.0]), np.full(2, H0))
    dem = GeoDEM(np.full((5, 5), H0), lon.min() - 0.05, lat.max() + 0.05,
                 (lon.max() - lon.min() + 0.1) / 4, -(lat.max() - lat.min() + 0.1) / 4)
    terrain = sample_terrain(left, (0, 0, 500, 500), dem, (0.0, 2000.0), step_px=100.0)
    np.testing.assert_allclose(terrain.h_m, H0, atol=0.5)
    plan = plan_tile_on_dem(3, left, right, (0, 0, 500, 500), (6000, 6000), dem, (0.0, 2000.0),
                            20.0)
    assert plan is not None and plan.index == 3 and plan.h_terrain_m == pytest.approx((H0, H0),
                                                                                      abs=0.5)
    # a right image of 10 x 10 px at its corner sees nothing of this tile
    assert plan_tile_on_dem(0, left, right, (5000, 5000, 5500, 5500), (10, 10), dem,
                            (0.0, 2000.0), 20.0) is None


def test_degenerate_inputs(spot_pair):
    left, right = spot_pair
    with pytest.raises(InputError, match="empty"):
        rectify_tile(left, right, (10, 10, 10, 20), (0.0, 100.0))
    with pytest.raises(GeometryError, match="parallel|degenerate"):
        rectify_tile(left, left, (0, 0, 100, 100), (0.0, 100.0))
    with pytest.raises(InputError):
        RectifyConfig(n_grid=2)


def test_warp_reproduces_a_linear_image_and_marks_what_it_cannot_see():
    """Bicubic resampling reproduces a linear ramp exactly, at the inverse-mapped positions."""
    rows, cols = np.mgrid[0:120, 0:150].astype(np.float64)
    image = (3.0 * cols + 2.0 * rows + 10.0).astype(np.float32)
    th = np.radians(7.0)
    affine = np.array([[np.cos(th), np.sin(th), -5.0], [-np.sin(th), np.cos(th), 4.0]])
    window = (0, 0, 140, 110)
    # the image window given starts at (20, 10) of a 150 x 120 image
    sub = image[10:, 20:]
    out, valid = warp_to_window(sub, (20, 10), affine, window, (150, 120))
    jj, ii = np.meshgrid(np.arange(140.0), np.arange(110.0))
    inv = np.linalg.inv(np.vstack([affine, [0, 0, 1]]))
    c = inv[0, 0] * jj + inv[0, 1] * ii + inv[0, 2]
    r = inv[1, 0] * jj + inv[1, 1] * ii + inv[1, 2]
    assert valid.sum() > 5000
    # within 0.003 px of position (the ramp rises 3.6 per pixel)
    np.testing.assert_allclose(out[valid], (3.0 * c + 2.0 * r + 10.0)[valid], atol=1e-2)
    assert not valid[(c < 23) | (r < 13)].any()  # 3 px inside the window given
    # a nodata pixel invalidates its neighbourhood
    holed = sub.copy()
    holed[50, 60] = 0.0
    _, valid2 = warp_to_window(holed, (20, 10), affine, window, (150, 120), nodata=0)
    near = np.hypot(c - 80, r - 60) < 1.0
    assert near.any() and not valid2[near].any() and valid2.sum() > valid.sum() - 60
