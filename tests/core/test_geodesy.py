import numpy as np
import pyproj
import pytest

from core.geodesy import (
    ecef_to_geodetic,
    enu_rotation,
    enu_to_geodetic,
    geodetic_to_ecef,
    geodetic_to_enu,
)

N = 100_000


@pytest.fixture(scope="module")
def points():
    rng = np.random.default_rng(42)
    lon = rng.uniform(-180, 180, N)
    lat = np.degrees(np.arcsin(rng.uniform(-1, 1, N)))
    h = rng.uniform(-500, 1_000_000, N)
    # the hard places: poles, antimeridian, equator, extreme heights
    lon[:8] = [180, -180, 179.9999999, -179.9999999, 0, 90, -90, 0]
    lat[:8] = [0, 45, -60, 89.9999999, 90, -90, 0, 0]
    h[:8] = [-500, 1e6, 0, 400e3, -500, 1e6, 0, 8848]
    return lon, lat, h


@pytest.fixture(scope="module")
def proj():
    return pyproj.Transformer.from_crs("EPSG:4979", "EPSG:4978", always_xy=True)


def test_forward_matches_pyproj(points, proj):
    lon, lat, h = points
    x, y, z = geodetic_to_ecef(lon, lat, h)
    px, py, pz = proj.transform(lon, lat, h)
    err = np.sqrt((x - px) ** 2 + (y - py) ** 2 + (z - pz) ** 2)
    assert err.max() < 1e-4


def test_inverse_is_exact_through_pyproj_forward(points, proj):
    """Our ECEF -> geodetic, sent back through PROJ's (closed-form, exact) forward, lands
    on the same ECEF point within 0.1 mm everywhere, 1,000 km heights included."""
    lon, lat, h = points
    px, py, pz = proj.transform(lon, lat, h)
    lon2, lat2, h2 = ecef_to_geodetic(px, py, pz)
    qx, qy, qz = proj.transform(lon2, lat2, h2)
    err = np.sqrt((qx - px) ** 2 + (qy - py) ** 2 + (qz - pz) ** 2)
    assert err.max() < 1e-4
    assert np.abs(h2 - h).max() < 1e-4


def test_inverse_matches_pyproj_inverse_near_the_surface(points, proj):
    """PROJ's own inverse is a single Bowring pass: sub-0.1 mm only near the surface
    (it is ~8 mm off at 1,000 km), so compare directly below 10 km."""
    lon, lat, h = points
    low = h < 10_000
    px, py, pz = proj.transform(lon[low], lat[low], h[low])
    lon2, lat2, h2 = ecef_to_geodetic(px, py, pz)
    plon, plat, ph = proj.transform(px, py, pz, direction="INVERSE")
    a = 6378137.0
    dlon = (lon2 - plon + 180) % 360 - 180
    dlon_m = np.radians(dlon) * a * np.cos(np.radians(lat[low]))
    assert np.abs(h2 - ph).max() < 1e-4
    assert np.abs(np.radians(lat2 - plat) * a).max() < 1e-4
    assert np.abs(dlon_m).max() < 1e-4


def test_round_trip_is_exact(points):
    lon, lat, h = points
    lon2, lat2, h2 = ecef_to_geodetic(*geodetic_to_ecef(lon, lat, h))
    x, y, z = geodetic_to_ecef(lon, lat, h)
    x2, y2, z2 = geodetic_to_ecef(lon2, lat2, h2)
    assert np.sqrt((x - x2) ** 2 + (y - y2) ** 2 + (z - z2) ** 2).max() < 1e-6
    assert np.abs(h - h2).max() < 1e-6


def test_poles_and_centre_axis():
    _, lat, h = ecef_to_geodetic(0.0, 0.0, 6356752.314245 + 100.0)
    assert lat == pytest.approx(90.0, abs=1e-12)
    assert h == pytest.approx(100.0, abs=1e-6)
    _, lat, h = ecef_to_geodetic(0.0, 0.0, -6356752.314245)
    assert lat == pytest.approx(-90.0, abs=1e-12) and h == pytest.approx(0.0, abs=1e-6)


def test_enu_frame_is_orthonormal_and_up_is_normal():
    r = enu_rotation(5.3, 44.2)
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-15)
    # moving up 100 m along the ellipsoid normal keeps lon/lat and adds 100 m to h
    lon, lat, h = enu_to_geodetic(0.0, 0.0, 100.0, (5.3, 44.2, 300.0))
    assert (lon, lat) == pytest.approx((5.3, 44.2), abs=1e-12)
    assert h == pytest.approx(400.0, abs=1e-6)


def test_enu_round_trip_against_pyproj_topocentric():
    origin = (5.27, 44.17, 1900.0)
    rng = np.random.default_rng(1)
    lon = origin[0] + rng.uniform(-0.5, 0.5, 1000)
    lat = origin[1] + rng.uniform(-0.5, 0.5, 1000)
    h = rng.uniform(0, 3000, 1000)
    e, n, u = geodetic_to_enu(lon, lat, h, origin)
    topo = pyproj.Transformer.from_pipeline(
        f"+proj=pipeline +step +proj=cart +ellps=WGS84 +step +proj=topocentric +ellps=WGS84 "
        f"+lon_0={origin[0]} +lat_0={origin[1]} +h_0={origin[2]}"
    )
    pe, pn, pu = topo.transform(lon, lat, h)
    np.testing.assert_allclose(np.c_[e, n, u], np.c_[pe, pn, pu], atol=1e-6)
    lon2, lat2, h2 = enu_to_geodetic(e, n, u, origin)
    np.testing.assert_allclose(lon2, lon, atol=1e-11)
    np.testing.assert_allclose(lat2, lat, atol=1e-11)
    np.testing.assert_allclose(h2, h, atol=1e-6)
