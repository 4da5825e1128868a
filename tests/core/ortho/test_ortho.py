"""Ortho kernel: the model interpolated on the sparse lattice agrees with the exact chain (cell
-> lon/lat -> DEM height -> model) within 0.01 px, computed here independently (pyproj, scipy's
linear interpolator, the model's own ``project``) on rough DEMs with kinks, lon/lat and
projected, ellipsoidal and EGM96; the resampling kernels against scipy and exact polynomials;
the occlusion mask against the shadow of a wall seen at a known incidence."""

from __future__ import annotations

import math

import numpy as np
import pyproj
import pytest
from scipy.interpolate import RegularGridInterpolator
from scipy.ndimage import map_coordinates

from core.dem import GeoDEM, SurfaceGrid
from core.errors import InputError
from core.geoid import GeoidGrid
from core.matching.grid import GridSpec
from core.ortho.ortho import (
    OrthoConfig,
    SourceWindow,
    TileDEM,
    resample,
    source_window,
    tile_geometry,
    to_dtype,
)
from core.sensors.pushbroom_synthetic import SyntheticSpec, synthetic_pushbroom
from core.sensors.rpc import RPCModel
from tasks.io.geoid import load_geoid
from tests.conftest import DATA

LON0, LAT0 = 5.25, 44.2
EPSG = 32631
TO_LONLAT = pyproj.Transformer.from_crs(EPSG, 4326, always_xy=True).transform
TO_XY = pyproj.Transformer.from_crs(4326, EPSG, always_xy=True).transform


def pushbroom(incidence_deg: float = 25.0):
    return synthetic_pushbroom(SyntheticSpec(LON0, LAT0, 500.0, n_cols=3000, n_rows=3000,
                                             gsd_m=10.0, incidence_deg=incidence_deg))


def ventoux_rpc() -> RPCModel:
    return RPCModel.from_geom((DATA / "pleiades_ventoux" / "left_image.geom").read_text())


def rough(shape: tuple[int, int], seed: int, relief_m: float) -> np.ndarray:
    """Random heights with cliffs: every cell independent plus steps (kinks everywhere)."""
    rng = np.random.default_rng(seed)
    z = rng.uniform(0, relief_m, shape)
    z[:, shape[1] // 2:] += relief_m  # a cliff
    return z + 300.0


def tile_around(lon: float, lat: float, res_m: float, n: int) -> GridSpec:
    x, y = TO_XY(lon, lat)
    return GridSpec(x - 0.5 * n * res_m, y + 0.5 * n * res_m, res_m, n, n)


def cell_centres(cells: GridSpec) -> tuple[np.ndarray, np.ndarray]:
    i, j = np.mgrid[0:cells.n_rows, 0:cells.n_cols]
    return cells.x0_m + (j + 0.5) * cells.res_m, cells.y0_m - (i + 0.5) * cells.res_m


def exact_geographic(model, dem: GeoDEM, cells: GridSpec):
    lon, lat = TO_LONLAT(*cell_centres(cells))
    lats = dem.lat0_deg + dem.dlat_deg * np.arange(dem.h_m.shape[0])
    lons = dem.lon0_deg + dem.dlon_deg * np.arange(dem.h_m.shape[1])
    interp = RegularGridInterpolator((lats[::-1], lons), dem.h_m[::-1], method="linear")
    h = interp(np.stack([lat, lon], axis=-1))
    return model.project(lon, lat, h)


@pytest.mark.parametrize("which", ["pushbroom", "rpc"])
def test_lattice_agrees_with_exact_projection_on_a_rough_lonlat_dem(which):
    if which == "pushbroom":
        model, lon, lat, res, spacing = pushbroom(), LON0, LAT0, 10.0, 1 / 1200
    else:
        model = ventoux_rpc()
        lon, lat = (float(v[0]) for v in model.localize(np.array([5250.0]),
                                                        np.array([5250.0]), np.array([900.0])))
        res, spacing = 0.5, 1 / 36000  # 3 m DEM cells under a 0.5 m ortho
    cells = tile_around(lon, lat, res, 300)
    n = 80 if which == "pushbroom" else 150
    dem = GeoDEM(rough((n, n), 1, 150.0), lon - 0.5 * n * spacing, lat + 0.5 * n * spacing,
                 spacing, -spacing)
    geo = tile_geometry(model, cells, TileDEM(dem), TO_LONLAT, OrthoConfig(step_px=64))
    col, row = exact_geographic(model, dem, cells)
    err = np.hypot(geo.col - col, geo.row - row)
    assert np.isfinite(err).all()
    assert err.max() < 0.01
    assert geo.max_error_px <= 0.01
    assert geo.n_evaluations < 0.5 * cells.n_rows * cells.n_cols  # sparse, not per cell


def test_lattice_agrees_on_a_projected_egm96_dsm_with_a_steep_geoid():
    model = pushbroom(-20.0)
    cells = tile_around(LON0, LAT0, 10.0, 256)
    x0, y0 = cells.x0_m - 100, cells.y0_m + 100
    z = rough((700, 700), 2, 60.0)
    grid = SurfaceGrid(z, x0, y0, 4.0, -4.0)
    # EGM96's 15' nodes with 20 times its undulations over the Alps (N 47..53 m here)
    glat, glon = np.arange(43.0, 45.5, 0.25), np.arange(4.0, 6.5, 0.25)
    egm96 = load_geoid()
    n_m = 20.0 * egm96.undulation_m(*np.meshgrid(glon, glat))
    geoid = GeoidGrid(n_m, 43.0, 4.0, 0.25, 0.25)
    geo = tile_geometry(model, cells, TileDEM(grid, TO_XY, geoid), TO_LONLAT)
    x, y = cell_centres(cells)
    lon, lat = TO_LONLAT(x, y)
    ys = y0 - 4.0 * np.arange(z.shape[0])
    xs = x0 + 4.0 * np.arange(z.shape[1])
    h = RegularGridInterpolator((ys[::-1], xs), z[::-1])(np.stack([y, x], -1))
    h += RegularGridInterpolator((glat, glon), n_m)(np.stack([lat, lon], -1))
    col, row = model.project(lon, lat, h)
    assert np.abs(geo.h_m - h).max() < 0.01  # N interpolated between lattice nodes
    assert np.hypot(geo.col - col, geo.row - row).max() < 0.01


def test_cells_off_the_dem_are_nan():
    model = pushbroom()
    cells = tile_around(LON0, LAT0, 10.0, 128)
    spacing = 1 / 1200
    dem = GeoDEM(np.full((20, 20), 500.0), LON0, LAT0 + 10 * spacing, spacing, -spacing)
    geo = tile_geometry(model, cells, TileDEM(dem), TO_LONLAT)
    lon, lat = TO_LONLAT(*cell_centres(cells))
    inside = (lon > LON0 + spacing) & (lat < LAT0 + 9 * spacing)
    assert np.isfinite(geo.col[inside]).all()
    outside = (lon < LON0 - spacing) | (lat > LAT0 + 11 * spacing)
    assert np.isnan(geo.col[outside]).all()


# ---------------------------------------------------------------------------- resampling


def test_bilinear_matches_scipy_and_cubic_is_exact_on_quadratics():
    rng = np.random.default_rng(0)
    i, j = np.mgrid[0:40, 0:50].astype(np.float64)
    image = rng.uniform(0, 100, (40, 50))
    win = SourceWindow(0, 0, 50, 40)
    col, row = rng.uniform(2, 47, (30, 30)), rng.uniform(2, 37, (30, 30))
    got = resample(image, win, col, row, (50, 40), "bilinear")
    np.testing.assert_allclose(got, map_coordinates(image, [row, col], order=1), atol=1e-9)
    quad = 0.3 * i ** 2 - 0.2 * i * j + 0.1 * j ** 2 + 2 * j - 5
    got = resample(quad, win, col, row, (50, 40), "cubic")
    np.testing.assert_allclose(got, 0.3 * row ** 2 - 0.2 * row * col + 0.1 * col ** 2
                               + 2 * col - 5, atol=1e-8)
    got = resample(image, win, col, row, (50, 40), "nearest")
    np.testing.assert_array_equal(got, image[np.floor(row + 0.5).astype(int),
                                             np.floor(col + 0.5).astype(int)])


def test_outside_the_footprint_and_next_to_nodata_is_nan():
    image = np.full((20, 20), 50, np.uint16)
    image[10, 10] = 0
    win = SourceWindow(0, 0, 20, 20)
    col = np.array([[-0.6, -0.4, 19.4, 19.6, 10.2, 5.0]])
    row = np.array([[5.0, 5.0, 5.0, 5.0, 10.3, 5.0]])
    got = resample(image, win, col, row, (20, 20), "bilinear", nodata=0)
    assert np.isnan(got[0, [0, 3, 4]]).all()
    np.testing.assert_allclose(got[0, [1, 2, 5]], 50.0)


def test_a_decimated_window_keeps_the_geometry_of_a_ramp():
    i, j = np.mgrid[0:200, 0:300].astype(np.float64)
    ramp = 3.0 * j - 2.0 * i + 7
    rng = np.random.default_rng(2)
    # output cells 4 pixels apart: the window is read averaged 4 x 4
    col = 20 + 4.0 * np.arange(60)[None, :] + rng.uniform(0, 1, (40, 60))
    row = 20 + 4.0 * np.arange(40)[:, None] + rng.uniform(0, 1, (40, 60))
    win = source_window(col, row, (300, 200), "bilinear")
    assert win.factor == 4
    c0, r0, c1, r1 = win.bounds
    pixels = ramp[r0:r1, c0:c1].reshape(win.n_rows, 4, win.n_cols, 4).mean(axis=(1, 3))
    got = resample(pixels, win, col, row, (300, 200), "bilinear")
    np.testing.assert_allclose(got, 3.0 * col - 2.0 * row + 7, atol=1e-9)


def test_to_dtype_rounds_clips_and_keeps_valid_values_off_nodata():
    v = np.array([np.nan, -3.0, 0.2, 0.6, 254.6, 300.0])
    np.testing.assert_array_equal(to_dtype(v, "uint8", 0), [0, 1, 1, 1, 255, 255])
    out = to_dtype(v, "float32", None)
    assert out.dtype == np.float32 and np.isnan(out[0])


def test_bad_settings_are_one_line():
    with pytest.raises(InputError, match="resampling"):
        OrthoConfig(resampling="lanczos")
    with pytest.raises(InputError, match="tolerance"):
        OrthoConfig(tol_px=0)


# ---------------------------------------------------------------------------- occlusion


def test_a_wall_hides_the_ground_behind_it_by_its_shadow_length():
    """Flat ground with a 200 m wall running north-south, seen from the west at 25 degrees:
    the ground east of the wall is hidden over 200 tan(incidence) metres."""
    model = pushbroom(25.0)
    cells = tile_around(LON0, LAT0, 5.0, 200)
    x0, y0 = cells.x0_m - 50.0, cells.y0_m + 50.0
    z = np.full((220, 220), 500.0)
    wall_x = cells.x0_m + 400.0  # wall cells [wall_x, wall_x + 20 m)
    xs = x0 + 5.0 * np.arange(220)
    z[:, (xs >= wall_x) & (xs < wall_x + 20.0)] = 700.0
    dem = TileDEM(SurfaceGrid(z, x0, y0, 5.0, -5.0), TO_XY)
    geo = tile_geometry(model, cells, dem, TO_LONLAT, OrthoConfig(occlusion=True))
    x, _ = cell_centres(cells)
    lon, lat = TO_LONLAT(x, _)
    # incidence at the cells from the model: ground displacement per metre of height
    c, r = model.project(lon, lat, np.full(lon.shape, 500.0))
    lon2, lat2 = model.localize(c, r, np.full(lon.shape, 600.0))
    x2, _y2 = TO_XY(lon2, lat2)
    tan_inc = float(np.median(np.abs(x2 - x) / 100.0))
    assert math.isclose(tan_inc, math.tan(math.radians(25.0)), abs_tol=0.03)
    shadow = 200.0 * tan_inc
    east = x - (wall_x + 20.0)
    hidden = geo.occluded
    assert hidden[(east > 10.0) & (east < shadow - 10.0)].all()
    assert not hidden[east > shadow + 10.0].any()
    assert not hidden[x < wall_x - 10.0].any()
