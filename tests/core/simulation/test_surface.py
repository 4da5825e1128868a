"""The truth surface: terrain = DEM + geoid + detail, slope, and the composed DSM/DTM/classes.

The DEM and geoid here are planes, so bilinear interpolation is exact and every expected
value is written out independently of the code under test (a local equirectangular frame
with an analytic inverse stands in for UTM).
"""

from __future__ import annotations

import numpy as np
import pytest

from core.dem import GeoDEM
from core.errors import InputError
from core.geoid import GeoidGrid
from core.simulation.landcover import LandCover, LandCoverConfig
from core.simulation.surface import SurfaceSpec, sample_surface, slope_deg, terrain_m

LON0, LAT0 = 5.2, 44.1
M_LAT = 111_132.0  # metres per degree of latitude near 44 N (frame of the test only)
M_LON = 111_132.0 * np.cos(np.radians(LAT0))
X0, Y0 = 650_000.0, 4_880_000.0


def to_lonlat(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return LON0 + (np.asarray(x) - X0) / M_LON, LAT0 + (np.asarray(y) - Y0) / M_LAT


def plane_dem(H0: float = 500.0, a_lon: float = 2000.0, a_lat: float = -800.0) -> GeoDEM:
    """H = H0 + a_lon (lon - LON0) + a_lat (lat - LAT0) on a 3" grid around the frame."""
    d = 1.0 / 1200.0
    lon = LON0 - 0.2 + np.arange(481) * d
    lat = LAT0 + 0.2 - np.arange(481) * d
    H = H0 + a_lon * (lon[None, :] - LON0) + a_lat * (lat[:, None] - LAT0)
    return GeoDEM(H, lon[0], lat[0], d, -d)


def flat_geoid(n_m: float = 50.0) -> GeoidGrid:
    return GeoidGrid(np.full((5, 5), n_m), 43.0, 4.0, 1.0, 1.0, name="flat")


def spec(detail_m: float = 0.0, water: float | None = None, **lc: object) -> SurfaceSpec:
    return SurfaceSpec(dem_H=plane_dem(), geoid=flat_geoid(), seed=9,
                       landcover=LandCoverConfig(water_level_m=water, **lc),
                       detail_amplitude_m=detail_m, detail_min_wavelength_m=40.0)


def grid(n: int = 200, step: float = 10.0) -> tuple[np.ndarray, np.ndarray]:
    g = np.arange(n) * step
    return np.meshgrid(X0 - 1000.0 + g, Y0 + 1000.0 - g)


def test_terrain_is_dem_plus_geoid_without_detail():
    x, y = grid()
    lon, lat = to_lonlat(x, y)
    t = terrain_m(spec(), x, y, lon, lat)
    expected = 500.0 + 2000.0 * (lon - LON0) - 800.0 * (lat - LAT0) + 50.0
    np.testing.assert_allclose(t, expected, atol=1e-9)


def test_detail_has_the_stated_amplitude_and_is_finer_than_the_dem():
    x, y = grid(400, 5.0)
    lon, lat = to_lonlat(x, y)
    s = spec(detail_m=3.0)
    detail = terrain_m(s, x, y, lon, lat) - terrain_m(spec(), x, y, lon, lat)
    assert 2.0 < detail.std() < 4.0
    assert abs(detail.mean()) < 1.0
    # no wavelength above the DEM cell (~66 m): 200 m block means are far smaller than the std
    blocks = detail[: 400 // 40 * 40, : 400 // 40 * 40].reshape(10, 40, 10, 40).mean(axis=(1, 3))
    assert blocks.std() < 0.5 * detail.std()


@pytest.mark.parametrize(("a_lon", "a_lat"), [(0.0, 0.0), (2000.0, -800.0), (-9000.0, 4000.0)])
def test_slope_of_a_plane(a_lon: float, a_lat: float):
    """Slope from the gradient in metres per metre; the ground scale is the approximate
    metres-per-degree of core.geodesy (within 1 %), so slopes agree to about 1 %."""
    s = SurfaceSpec(dem_H=plane_dem(500.0, a_lon, a_lat), geoid=flat_geoid(), seed=1,
                    landcover=LandCoverConfig(), detail_amplitude_m=0.0,
                    detail_min_wavelength_m=40.0)
    lon = np.array([LON0, LON0 + 0.05, LON0 - 0.1])
    lat = np.array([LAT0, LAT0 - 0.05, LAT0 + 0.1])
    gx = a_lon / (111_412.0 * np.cos(np.radians(lat)))  # true WGS84 scales near 44 N
    gy = a_lat / 111_132.0
    expected = np.degrees(np.arctan(np.hypot(gx, gy)))
    np.testing.assert_allclose(slope_deg(s, lon, lat), expected, rtol=1.1e-2, atol=1e-12)


def test_sample_surface_composes_the_rules():
    x, y = grid(300, 7.0)
    s = sample_surface(spec(water=560.0, urban_fraction=0.3,
                            urban_patch_wavelength_m=600.0), x, y, to_lonlat)
    cls = s.classes
    assert {LandCover.BARE_SOIL, LandCover.FOREST, LandCover.URBAN, LandCover.WATER} <= set(
        np.unique(cls).tolist())
    bare, forest = cls == LandCover.BARE_SOIL, cls == LandCover.FOREST
    water, urban = cls == LandCover.WATER, cls == LandCover.URBAN
    # bare soil: surface = bare earth = terrain; water: flat at the level, below it the terrain
    np.testing.assert_array_equal(s.dsm_m[bare], s.dtm_m[bare])
    np.testing.assert_array_equal(s.dtm_m[bare], s.terrain_m[bare])
    assert np.all(s.dtm_m[water] == 560.0) and np.all(s.terrain_m[water] < 560.0)
    # forest canopy 10-25 m over the ground; roofs 4-15 m over the terrain under their centre
    canopy = s.dsm_m[forest] - s.dtm_m[forest]
    assert canopy.min() >= 10.0 and canopy.max() <= 25.0
    roofs = urban & (s.building_m > 0)
    assert roofs.any()
    # the plane rises at most 0.026 m/m: <= 0.7 m over half a 50 m block
    height = s.dsm_m[roofs] - s.dtm_m[roofs]
    assert height.min() >= 4.0 - 0.7 and height.max() <= 15.0 + 0.7
    assert np.all(s.dsm_m[~roofs] >= s.dtm_m[~roofs])
    assert not s.dark_roof[~roofs].any()


def test_roofs_are_flat_per_building():
    x, y = grid(300, 2.0)
    s = sample_surface(spec(urban_fraction=0.9, forest_fraction=0.05,
                            urban_patch_wavelength_m=400.0), x, y, to_lonlat)
    from core.simulation.landcover import sample_buildings

    bld = sample_buildings(x, y, 9, LandCoverConfig(urban_fraction=0.9, forest_fraction=0.05,
                                                     urban_patch_wavelength_m=400.0))
    on = (s.building_m > 0) & (s.classes == LandCover.URBAN)
    keys = np.stack([bld.centre_x_m[on], bld.centre_y_m[on]], axis=1)
    heights = s.dsm_m[on]
    _, inv = np.unique(keys, axis=0, return_inverse=True)
    for k in np.unique(inv)[:30]:
        assert np.ptp(heights[inv.ravel() == k]) < 1e-9


def test_tiles_equal_the_whole():
    x, y = grid(120, 9.0)
    sp = spec(detail_m=2.0, water=540.0)
    whole = sample_surface(sp, x, y, to_lonlat)
    for sl in ((slice(0, 50), slice(0, 70)), (slice(50, 120), slice(70, 120))):
        part = sample_surface(sp, x[sl], y[sl], to_lonlat)
        assert part.dsm_m.tobytes() == whole.dsm_m[sl].tobytes()
        assert part.classes.tobytes() == whole.classes[sl].tobytes()


def test_spec_checks():
    with pytest.raises(InputError, match="detail amplitude"):
        SurfaceSpec(dem_H=plane_dem(), geoid=flat_geoid(), seed=1, landcover=LandCoverConfig(),
                    detail_amplitude_m=-1.0, detail_min_wavelength_m=40.0)
