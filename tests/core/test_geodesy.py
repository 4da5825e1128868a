import numpy as np
import pyproj
import pytest

from core.errors import InputError
from core.geodesy import (
    BBox,
    ecef_to_geodetic,
    enu_rotation,
    enu_to_geodetic,
    geodetic_to_ecef,
    geodetic_to_enu,
    incidence_angles,
    metres_per_degree,
    utm_epsg,
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


def test_enu_rotation_is_vectorised_and_orthonormal():
    lon = np.array([[5.3, -120.0], [179.9, 0.0]])
    lat = np.array([[44.2, -33.0], [89.0, 0.0]])
    r = enu_rotation(lon, lat)
    assert r.shape == (2, 2, 3, 3)
    for i in range(2):
        for j in range(2):
            np.testing.assert_array_equal(r[i, j], enu_rotation(lon[i, j], lat[i, j]))
            np.testing.assert_allclose(r[i, j] @ r[i, j].T, np.eye(3), atol=1e-15)
    # Up is the ellipsoid normal: it points along the ECEF difference of two heights
    a = np.array(geodetic_to_ecef(5.3, 44.2, 0.0))
    b = np.array(geodetic_to_ecef(5.3, 44.2, 1000.0))
    np.testing.assert_allclose(enu_rotation(5.3, 44.2)[2], (b - a) / 1000.0, atol=1e-12)


@pytest.mark.parametrize("lat", [0.0, 23.0, 44.2, -61.0, 79.0])
def test_metres_per_degree_is_exact(lat: float):
    """Against PROJ's geodesics over 0.001 degree: the local scale, to 1e-6 (a parallel is not
    a geodesic, but over 0.001 degree the two differ by less than that)."""
    geod = pyproj.Geod(ellps="WGS84")
    m_lon, m_lat = metres_per_degree(lat)
    _, _, d_lon = geod.inv(10.0, lat, 10.001, lat)
    _, _, d_lat = geod.inv(10.0, lat - 0.0005, 10.0, lat + 0.0005)
    assert float(m_lon) * 1e-3 == pytest.approx(d_lon, rel=1e-6)
    assert float(m_lat) * 1e-3 == pytest.approx(d_lat, rel=1e-6)


@pytest.mark.parametrize(("lon", "lat"), [(5.25, 44.2), (-70.6, -33.4), (179.9, 10.0),
                                          (-180.0, -5.0), (2.99, 0.0), (3.01, -0.01)])
def test_utm_epsg_agrees_with_proj(lon: float, lat: float):
    from pyproj.aoi import AreaOfInterest
    from pyproj.database import query_utm_crs_info

    infos = query_utm_crs_info(datum_name="WGS 84",
                               area_of_interest=AreaOfInterest(lon, lat, lon, lat))
    codes = {int(i.code) for i in infos if i.name.startswith("WGS 84 / UTM zone")}
    assert utm_epsg(lon, lat) in codes


def test_incidence_angles_sign_and_value():
    """A satellite 800 km up, displaced west of the point by the angle that gives 20 deg
    incidence on a sphere-like check, flying north: positive across-track incidence."""
    lon, lat = 5.0, 44.0
    g = np.array(geodetic_to_ecef(lon, lat, 0.0))
    r = enu_rotation(lon, lat)
    east, north, up = r
    d = 800e3 * np.tan(np.radians(20.0))
    sat = g + 800e3 * up - d * east  # west of the point, 800 km above its tangent plane
    vel = 7e3 * north
    inc, across, rng = incidence_angles(sat[None], vel[None], g[None], np.array([lon]),
                                        np.array([lat]))
    assert np.degrees(inc[0]) == pytest.approx(20.0, abs=1e-9)
    assert np.degrees(across[0]) == pytest.approx(20.0, abs=1e-9)
    assert rng[0] == pytest.approx(np.hypot(800e3, d))
    east_sat = g + 800e3 * up + d * east
    _, across_e, _ = incidence_angles(east_sat[None], vel[None], g[None], np.array([lon]),
                                      np.array([lat]))
    assert np.degrees(across_e[0]) == pytest.approx(-20.0, abs=1e-9)


def test_bbox_checks_and_contains():
    box = BBox(5.0, 44.0, 6.0, 45.0)
    assert box.contains(BBox(5.2, 44.1, 5.9, 44.9)) and not box.contains(BBox(4.9, 44.1, 5.5, 44.5))
    assert box.expanded(0.5) == BBox(4.5, 43.5, 6.5, 45.5)
    with pytest.raises(InputError, match="LON_MIN < LON_MAX"):
        BBox(6.0, 44.0, 5.0, 45.0)
