"""Triangulation of rectified matches (tile polynomials against exact ray intersection) and the
gridding of ground points into a DEM (median per cell, hole filling, mask)."""

import numpy as np
import pytest

from core.errors import GeometryError, InputError
from core.geodesy import geodetic_to_enu
from core.matching.dense import PixelStatus
from core.matching.grid import (
    MASK_MISMATCH,
    MASK_OCCLUDED,
    MASK_VALID,
    GridSpec,
    fill_small_holes,
    grid_dem,
    median_per_cell,
    remove_offset_and_tilt,
)
from core.matching.rectify import TerrainSample, plan_tile
from core.matching.triangulate import fit_disparity_to_ground, triangulate_matches
from core.points import GeoPoint
from core.robust import nmad
from core.simulation.scene import PRESETS, ErrorConfig, scene_models

H0 = 600.0
ORIGIN = (5.25, 44.2, 0.0)


def to_enu(lon, lat):
    """A local projection for the tests: east and north metres at the scene centre."""
    e, n, _ = geodetic_to_enu(lon, lat, np.zeros(np.shape(lon)), ORIGIN)
    return e, n


@pytest.fixture(scope="module")
def tile():
    models = scene_models(PRESETS["spot"], GeoPoint(5.25, 44.2, H0), ErrorConfig(), seed=1)
    left, right = models["left"].truth, models["right"].truth
    rng = np.random.default_rng(1)
    terrain = TerrainSample(rng.uniform(2000, 2999, 50), rng.uniform(2000, 2999, 50),
                            rng.uniform(H0 - 600.0, H0 + 600.0, 50))
    plan = plan_tile(0, left, right, (2000, 2000, 3000, 3000), terrain, margin_m=50.0)
    return left, right, plan


def test_tile_polynomials_match_exact_triangulation(tile):
    left, right, plan = tile
    g2g = fit_disparity_to_ground(plan.rect, left, right, plan.window, (0, plan.n_disp - 1),
                                  to_enu)
    assert g2g.degree == 3 and g2g.fit_max_m < 0.01
    rng = np.random.default_rng(7)
    u0, v0, w, h = plan.window
    u = rng.uniform(u0, u0 + w - 1, 3000)
    v = rng.uniform(v0, v0 + h - 1, 3000)
    d = rng.uniform(0, plan.n_disp - 1, 3000)
    exact = triangulate_matches(plan.rect, left, right, u, v, d, to_enu, (-1000.0, 3000.0))
    fast = g2g(u, v, d)
    for a, b in ((fast.x_m, exact.x_m), (fast.y_m, exact.y_m), (fast.h_m, exact.h_m)):
        assert np.max(np.abs(a - b)) < 0.01
    # the rays of rectified matches meet: the rectification's y-parallax is all that is missed
    assert np.max(exact.miss_m) < 0.1 * 10.0 + 0.5
    # an independent truth: a ground point's two projections triangulate back onto it
    lon, lat = left.localize(2500.0, 2600.0, 1000.0)
    cr, rr = right.project(lon, lat, 1000.0)
    ul, vl = plan.rect.left_to_rect(2500.0, 2600.0)
    ur, _ = plan.rect.right_to_rect(cr, rr)
    p = g2g(ul, vl, ul - ur)
    e, n = to_enu(lon, lat)
    assert p.h_m[0] == pytest.approx(1000.0, abs=0.3)  # within the y-residual's effect
    assert np.hypot(p.x_m[0] - e, p.y_m[0] - n) < 0.3


def test_a_lower_degree_is_raised_until_the_check_passes(tile):
    left, right, plan = tile
    g2g = fit_disparity_to_ground(plan.rect, left, right, plan.window, (0, plan.n_disp - 1),
                                  to_enu, degree=1, tol_m=0.01)
    assert g2g.degree >= 3 and g2g.fit_max_m < 0.01


def test_models_that_see_different_ground_are_refused(tile):
    left, _right, plan = tile
    far = scene_models(PRESETS["spot"], GeoPoint(-70.0, -30.0, H0), ErrorConfig(), seed=1)
    with pytest.raises(GeometryError):
        fit_disparity_to_ground(plan.rect, left, far["right"].truth, plan.window,
                                (0, plan.n_disp - 1), to_enu)


def test_median_per_cell_against_a_loop():
    rng = np.random.default_rng(3)
    x = rng.uniform(0, 50, 4000)
    y = rng.uniform(-40, 0, 4000)
    h = rng.normal(100, 5, 4000)
    h[::17] = np.nan
    z = median_per_cell(x, y, h, 0.0, 0.0, 5.0, (8, 10))
    for i in range(8):
        for j in range(10):
            sel = (np.floor(x / 5) == j) & (np.floor(-y / 5) == i) & np.isfinite(h)
            want = np.median(h[sel]) if sel.any() else np.nan
            np.testing.assert_allclose(z[i, j], want, rtol=1e-6)


def test_small_holes_are_filled_large_and_border_ones_are_not():
    z = np.ones((20, 20), np.float32) * 10.0
    z[5, 5:7] = np.nan  # 2 cells
    z[10:13, 10:13] = np.nan  # 9 cells
    z[0, 15] = np.nan  # touches the border
    out, filled = fill_small_holes(z, 5)
    assert out[5, 5] == pytest.approx(10.0) and filled[5, 5:7].all()
    assert np.isnan(out[10:13, 10:13]).all() and np.isnan(out[0, 15])
    assert filled.sum() == 2


def test_grid_dem_mask_says_why_a_cell_is_empty():
    # cells (0-2, 0-2): matched points (10 and 12 m); (0, 3): only mismatched pixels; (0, 4):
    # occluded ones; (0, 5) and the rest: nothing; (3, 0): outside the pair only. The matched
    # cells beside those outside the pair are the DEM's edge and blanked (see the next tests);
    # the array's own border is not outside (a caller pads it): (0-1, 0-1) stay.
    pts = [(c + 0.3, -r - 0.5, v, PixelStatus.VALID) for r in range(3) for c in range(3)
           for v in (10.0, 12.0)]
    pts += [(3.5, -0.5, np.nan, PixelStatus.MISMATCH), (3.4, -0.6, np.nan, PixelStatus.MISMATCH),
            (4.5, -0.5, np.nan, PixelStatus.OCCLUDED), (0.5, -3.5, np.nan, PixelStatus.OUTSIDE)]
    x, y, h, s = (np.array(c) for c in zip(*pts))
    cells = grid_dem(x, y, h, s.astype(np.uint8), 0.0, 0.0, 1.0, (4, 6), max_hole_cells=0)
    assert cells.z_m[1, 1] == pytest.approx(11.0) and cells.mask[1, 1] == MASK_VALID
    assert np.isfinite(cells.z_m).sum() == 4 and np.isfinite(cells.z_m[:2, :2]).all()
    assert cells.mask[0, 3:].tolist() == [MASK_MISMATCH, MASK_OCCLUDED, MASK_OCCLUDED]
    assert cells.mask[3, 0] == MASK_OCCLUDED
    assert cells.mask[0, 2] == MASK_OCCLUDED  # on the edge
    assert cells.overlap[0].tolist() == [True, True, True, True, True, False]
    assert not cells.overlap[3, 0]


def test_grid_spec_is_aligned_on_the_resolution():
    g = GridSpec.covering((1003.0, 2001.0, 1041.0, 2019.5), 2.0)
    assert (g.x0_m, g.y0_m, g.n_cols, g.n_rows) == (1002.0, 2020.0, 20, 10)
    assert g.geotransform() == (2.0, 0.0, 1002.0, 0.0, -2.0, 2020.0)
    assert g.bounds_of(0, 10, 0, 20) == (1002.0, 2000.0, 1042.0, 2020.0)
    with pytest.raises(InputError):
        GridSpec.covering((0, 0, 1, 1), 0.0)


def test_offset_and_tilt_are_recovered_and_removed():
    """A surface shifted by (12, -7) m, raised by 3 m and tilted, plus noise and blunders."""
    rng = np.random.default_rng(5)
    x, y = rng.uniform(-5000, 5000, (2, 20000))

    def surface(x, y):
        return 300.0 * np.sin(x / 1500.0) * np.cos(y / 2100.0) + 0.02 * x

    def slope(x, y):
        return (300.0 / 1500.0 * np.cos(x / 1500.0) * np.cos(y / 2100.0) + 0.02,
                -300.0 / 2100.0 * np.sin(x / 1500.0) * np.sin(y / 2100.0))

    dem = surface(x - 12.0, y + 7.0) + 3.0 + 1e-4 * x - 2e-4 * y + rng.normal(0, 0.5, x.size)
    dem[:300] += 80.0  # blunders
    gx, gy = slope(x, y)
    fit = remove_offset_and_tilt(dem - surface(x, y), x, y, gx, gy)
    assert fit.dx_m == pytest.approx(12.0, abs=0.3) and fit.dy_m == pytest.approx(-7.0, abs=0.3)
    assert fit.dz_m == pytest.approx(3.0 + 1e-4 * x.mean() - 2e-4 * y.mean(), abs=0.1)
    assert fit.tilt_x == pytest.approx(1e-4, abs=1e-5)
    r = fit.residual_m[300:]
    assert nmad(r) < 0.7
    with pytest.raises(InputError):
        remove_offset_and_tilt([1.0], [0.0], [0.0], [0.0], [0.0])


def test_a_tilted_plane_is_gridded_in_place_and_read_back_at_its_cell_centres():
    """Points on a plane, on an HRS-like pixel lattice (5 m along a track 15 degrees off north,
    10 m across), gridded in 20 m cells: each cell's height is the plane at the cell's centre
    (on average: the points' pattern in a cell varies), and the grid read back through its
    geotransform (:meth:`core.dem.SurfaceGrid.from_transform`, GDAL's area convention) gives
    the plane at any point: no part-cell shift between the gridding and its readers."""
    from core.dem import SurfaceGrid

    def plane(x, y):
        return 1000.0 + 0.3 * x - 0.2 * y

    a = np.radians(15.0)
    i, j = np.mgrid[0:900, 0:450].astype(np.float64)
    along, across = 5.0 * i, 10.0 * j
    x = 1000.3 + across * np.cos(a) + along * np.sin(a)
    y = 5000.7 - across * np.sin(a) + along * np.cos(a)
    h = plane(x, y)
    spec = GridSpec.covering((x.min(), y.min(), x.max(), y.max()), 20.0)
    status = np.zeros(x.size, np.uint8)
    cells = grid_dem(x, y, h, status, spec.x0_m, spec.y0_m, spec.res_m, spec.shape,
                     max_hole_cells=0, min_island_cells=0)
    jj, ii = np.meshgrid(np.arange(spec.n_cols), np.arange(spec.n_rows))
    xc, yc = spec.x0_m + (jj + 0.5) * spec.res_m, spec.y0_m - (ii + 0.5) * spec.res_m
    full = np.zeros(spec.shape, bool)  # cells well inside the lattice
    full[5:-5, 5:-5] = True
    ok = full & np.isfinite(cells.z_m) & (cells.mask == MASK_VALID)
    err = cells.z_m.astype(np.float64) - plane(xc, yc)
    assert ok.sum() > 1000
    # a shift of d metres along the gradient (0.36 m/m) would be 0.36 d m: d < 0.1 m here
    # (a corner taken for a centre, 10 m east and south, would be 5 m)
    assert abs(float(np.mean(err[ok]))) < 0.036
    grid = SurfaceGrid.from_transform(cells.z_m.astype(np.float64), spec.geotransform())
    inner = ok & np.roll(ok, -1, 0) & np.roll(ok, -1, 1) & np.roll(np.roll(ok, -1, 0), -1, 1)
    px, py = xc[inner] + 3.0, yc[inner] - 4.0  # between cell centres: bilinear reading
    back = grid.sample(px, py) - plane(px, py)
    assert np.isfinite(back).all() and abs(float(np.mean(back))) < 0.036


def test_the_dems_edge_cells_hold_the_height_of_their_centres_or_none():
    """The same plane and lattice: a cell that the points' edge cuts holds them on its inner
    side only, and their median is the plane there, not at the cell's centre (the surface
    moved outwards). Along the lattice's west and east edges, where the plane rises 0.3 m/m
    eastwards, the outermost cells kept are neither high nor low."""

    def plane(x, y):
        return 1000.0 + 0.3 * x - 0.2 * y

    a = np.radians(15.0)
    i, j = np.mgrid[0:900, 0:450].astype(np.float64)
    x = 1000.3 + 10.0 * j * np.cos(a) + 5.0 * i * np.sin(a)
    y = 5000.7 - 10.0 * j * np.sin(a) + 5.0 * i * np.cos(a)
    spec = GridSpec.covering((x.min(), y.min(), x.max(), y.max()), 20.0)
    cells = grid_dem(x, y, plane(x, y), np.zeros(x.size, np.uint8), spec.x0_m, spec.y0_m,
                     spec.res_m, spec.shape, max_hole_cells=0, min_island_cells=0)
    jj, ii = np.meshgrid(np.arange(spec.n_cols), np.arange(spec.n_rows))
    err = cells.z_m - plane(spec.x0_m + (jj + 0.5) * spec.res_m,
                            spec.y0_m - (ii + 0.5) * spec.res_m)
    ok = np.isfinite(cells.z_m)
    rows = np.flatnonzero(ok.sum(axis=1) > 10)[5:-5]  # away from the north and south corners
    west = np.array([err[r, np.flatnonzero(ok[r])[0]] for r in rows])
    east = np.array([err[r, np.flatnonzero(ok[r])[-1]] for r in rows])
    # a cell half covered holds the plane about 5 m inwards: 1.5 m high (west) or low (east)
    assert abs(float(np.mean(west))) < 0.3 and abs(float(np.mean(east))) < 0.3
    assert (cells.mask[~ok] != MASK_VALID).all()
