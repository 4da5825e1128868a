"""core.sensors.viewing against independent checks: the rigorous model's own viewing geometry
and satellite positions, the synthetic scenes' stated incidence and GSD, hand-made polygons."""

from datetime import UTC, datetime, timedelta

import numpy as np
import pytest

from core.dem import GeoDEM
from core.errors import CoverageError, GeometryError, InputError
from core.geodesy import enu_rotation, geodetic_to_ecef
from core.sensors.pushbroom import PushbroomModel
from core.sensors.pushbroom_synthetic import SyntheticSpec, synthetic_pushbroom
from core.sensors.viewing import (
    centre_rays_height_m,
    clip_convex,
    footprint_mean_height_m,
    image_corners_px,
    pair_geometry,
    point_geometry,
    polygon_centroid,
    scene_geometry,
    signed_area,
)

LON, LAT = 5.25, 44.2
N_PX, GSD_M = 600, 40.0


def spec(**kw) -> SyntheticSpec:
    base = dict(centre_lon_deg=LON, centre_lat_deg=LAT, n_cols=N_PX, n_rows=N_PX, gsd_m=GSD_M)
    return SyntheticSpec(**{**base, **kw})


@pytest.fixture(scope="module")
def views() -> dict[float, PushbroomModel]:
    return {inc: synthetic_pushbroom(spec(incidence_deg=inc)) for inc in (25.0, -20.0, 0.0)}


def grid(n: int = 5) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    c, r = np.meshgrid(np.linspace(0, N_PX - 1, n), np.linspace(0, N_PX - 1, n))
    h = np.linspace(-200.0, 3000.0, c.size).reshape(c.shape)
    return c, r, h


def satellite_direction(model: PushbroomModel, col, row, h) -> tuple[np.ndarray, np.ndarray]:
    """Ground point (n, 3) and unit vector to the satellite position at the line time (n, 3):
    from the orbit, not from lines of sight."""
    col, row, h = (np.ravel(a) for a in np.broadcast_arrays(col, row, h))
    lon, lat = model.localize(col, row, h)
    g = np.stack(geodetic_to_ecef(lon, lat, h), axis=-1)
    pos, _ = model.orbit.interpolate(model.line_time_s(row))
    s = pos - g
    return g, s / np.linalg.norm(s, axis=-1, keepdims=True)


# ------------------------------------------------------------------------- one image


@pytest.mark.parametrize("inc", [25.0, -20.0, 0.0])
def test_incidence_and_across_track_match_the_rigorous_model(views, inc):
    m = views[inc]
    c, r, h = grid()
    g = point_geometry(m, c, r, h)
    inc_ref, across_ref, _ = m.viewing_geometry(c, r, h)
    assert g.incidence_deg.shape == c.shape
    np.testing.assert_allclose(g.incidence_deg, inc_ref, atol=1e-6)
    # across track: ours takes the image rows as the track, the model the satellite velocity
    np.testing.assert_allclose(g.across_track_incidence_deg, across_ref, atol=0.01)
    centre = point_geometry(m, 0.5 * (N_PX - 1), 0.5 * (N_PX - 1), 0.0)
    assert float(centre.across_track_incidence_deg) == pytest.approx(inc, abs=1e-3)


@pytest.mark.parametrize("inc", [25.0, -20.0])
def test_azimuth_and_line_of_sight_point_at_the_satellite(views, inc):
    m = views[inc]
    c, r, h = grid()
    g = point_geometry(m, c, r, h)
    ground, to_sat = satellite_direction(m, c, r, h)
    np.testing.assert_allclose(g.los_ecef.reshape(-1, 3), to_sat, atol=1e-9)
    rot = enu_rotation(g.lon_deg.ravel(), g.lat_deg.ravel())
    e = np.einsum("nj,nj->n", rot[:, 0], to_sat)
    n = np.einsum("nj,nj->n", rot[:, 1], to_sat)
    az = np.degrees(np.arctan2(e, n)) % 360
    np.testing.assert_allclose(g.azimuth_deg.ravel(), az, atol=1e-6)
    # a descending sun-synchronous orbit heads south-south-west: a satellite west of the
    # scene (positive incidence) is seen towards the west-north-west, east: east-south-east
    assert (270 < az.min() < 300) if inc > 0 else (90 < az.min() < 120)


@pytest.mark.parametrize("inc", [25.0, 0.0])
def test_gsd_is_the_synthetic_scene_gsd_at_its_centre(views, inc):
    g = point_geometry(views[inc], 0.5 * (N_PX - 1), 0.5 * (N_PX - 1), 0.0)
    assert float(g.gsd_across_m) == pytest.approx(GSD_M, rel=1e-8)
    assert float(g.gsd_along_m) == pytest.approx(GSD_M, rel=1e-4)


def test_gsd_grows_towards_the_far_edge_of_an_oblique_view(views):
    """Looking east from the west (+25 deg), the last column is furthest: larger GSD, larger
    incidence; with 1/cos^2 growth of the across-track GSD with the view angle."""
    g = point_geometry(views[25.0], [0.0, N_PX - 1.0], [299.5, 299.5], 0.0)
    assert g.gsd_across_m[1] > GSD_M > g.gsd_across_m[0]
    assert g.incidence_deg[1] > 25.0 > g.incidence_deg[0]


def test_scene_corners_lie_on_the_corner_pixels_at_the_height(views):
    m = views[25.0]
    for h in (0.0, 1500.0):
        s = scene_geometry(m, N_PX, N_PX, h)
        assert [(k.col, k.row) for k in s.corners] == [(0, 0), (599, 0), (599, 599), (0, 599)]
        lon = np.array([k.lon_deg for k in s.corners])
        lat = np.array([k.lat_deg for k in s.corners])
        col, row = m.project(lon, lat, np.full(4, h))  # Newton on the model: another path
        np.testing.assert_allclose(col, [0, 599, 599, 0], atol=1e-6)
        np.testing.assert_allclose(row, [0, 0, 599, 599], atol=1e-6)
    s0 = scene_geometry(m, N_PX, N_PX, 0.0)
    assert (s0.centre_lon_deg, s0.centre_lat_deg) == pytest.approx((LON, LAT), abs=1e-9)
    # 600 px of ~40 m: about 24 x 24 km, larger across at 25 deg (the far side stretches)
    assert 560 < s0.area_km2 < 600


def test_acquisition_time_is_epoch_plus_centre_line_time(views):
    m = views[0.0]
    s = scene_geometry(m, N_PX, N_PX, 0.0)
    t = m.t0_s + 0.5 * (N_PX - 1) * m.line_period_s
    want = datetime(2024, 6, 1, 10, tzinfo=UTC) + timedelta(seconds=t)
    got = datetime.fromisoformat(s.acquisition_utc.replace("Z", "+00:00"))
    assert abs((got - want).total_seconds()) < 1e-5
    assert s.acquisition_utc.endswith("Z")


def test_mean_height_on_a_flat_and_on_a_partial_dem(views):
    m = views[25.0]
    lon = np.arange(4.5, 6.0, 0.01)
    lat = np.arange(45.0, 43.5, -0.01)
    flat = GeoDEM(np.full((lat.size, lon.size), 812.5), lon[0], lat[0], 0.01, -0.01)
    t = footprint_mean_height_m(m, N_PX, N_PX, flat)
    assert t.mean_h_m == pytest.approx(812.5) and t.covered_pct == 100.0 and t.n_samples == 441
    # a plane rising eastwards: the mean is its height at the footprint's mean longitude at
    # that height (the samples are uniform in the image, nearly uniform on the ground)
    plane = GeoDEM(1000.0 + 2000.0 * (lon[None, :] - LON) + 0 * lat[:, None], lon[0], lat[0],
                   0.01, -0.01)
    t = footprint_mean_height_m(m, N_PX, N_PX, plane)
    cc, rr = np.meshgrid(np.linspace(0, N_PX - 1, 21), np.linspace(0, N_PX - 1, 21))
    lo, _ = m.localize(cc.ravel(), rr.ravel(), np.full(cc.size, t.mean_h_m))
    assert t.mean_h_m == pytest.approx(1000.0 + 2000.0 * (lo.mean() - LON), abs=2.0)
    half = GeoDEM(np.full((lat.size, 76), 100.0), lon[0], lat[0], 0.01, -0.01)  # to lon 5.25
    t = footprint_mean_height_m(m, N_PX, N_PX, half)
    assert t.mean_h_m == pytest.approx(100.0) and 30 < t.covered_pct < 70
    far = GeoDEM(np.zeros((3, 3)), 20.0, 10.0, 0.01, -0.01)
    with pytest.raises(CoverageError, match="covers the scene"):
        footprint_mean_height_m(m, N_PX, N_PX, far)


def test_bad_arguments_raise_input_errors(views):
    with pytest.raises(InputError):
        image_corners_px(0, 10)
    with pytest.raises(InputError):
        point_geometry(views[0.0], 1.0, 1.0, 0.0, dh_m=0.0)


# ------------------------------------------------------------------------- polygons


def square(x0: float = 0.0, y0: float = 0.0, side: float = 10.0) -> np.ndarray:
    return np.array([[x0, y0], [x0 + side, y0], [x0 + side, y0 + side], [x0, y0 + side]])


def test_polygon_area_clip_and_centroid():
    a = square()
    assert signed_area(a) == 100.0 and signed_area(a[::-1]) == -100.0
    inter = clip_convex(a, square(3.0, 2.0))
    assert signed_area(inter) == pytest.approx(7 * 8)
    assert polygon_centroid(inter) == pytest.approx((6.5, 6.0))
    assert signed_area(clip_convex(a, a)) == pytest.approx(100.0)
    assert clip_convex(a, square(20.0, 0.0)).shape == (0, 2)
    inner = square(2.0, 2.0, 3.0)
    assert signed_area(clip_convex(inner, a)) == pytest.approx(9.0)
    # a triangle over a square: the classic Sutherland-Hodgman case, area by hand
    tri = np.array([[-5.0, -5.0], [15.0, -5.0], [5.0, 15.0]])
    assert signed_area(clip_convex(tri, a)) == pytest.approx(100.0 - 2 * 0.5 * 2.5 * 5.0)


# ------------------------------------------------------------------------- pairs


def test_convergence_of_two_across_track_views(views):
    """+25 and -20 deg across track over one point: about 45 deg between the lines of sight;
    exactly the angle between the directions to the two satellites at the common point."""
    m1, m2 = views[25.0], views[-20.0]
    p = pair_geometry(m1, (N_PX, N_PX), m2, (N_PX, N_PX), 0.0)
    _, s1 = satellite_direction(m1, p.col1, p.row1, 0.0)
    _, s2 = satellite_direction(m2, p.col2, p.row2, 0.0)
    want = np.degrees(np.arccos(np.clip(float(s1[0] @ s2[0]), -1, 1)))
    assert p.convergence_deg == pytest.approx(want, abs=1e-6)
    assert p.convergence_deg == pytest.approx(45.0, abs=0.3)
    assert p.b_over_h == pytest.approx(2 * np.tan(np.radians(want) / 2), rel=1e-9)
    # tan 25 + tan 20, the flat-Earth B/H of these views, is close (not equal: asymmetric)
    assert p.b_over_h == pytest.approx(np.tan(np.radians(25)) + np.tan(np.radians(20)), abs=0.01)
    assert p.incidence1_deg == pytest.approx(25.0, abs=0.1)
    assert p.incidence2_deg == pytest.approx(20.0, abs=0.1)
    assert 90 < p.overlap_pct < 100
    lon, lat = m1.localize(p.col1, p.row1, 0.0)
    assert (float(lon), float(lat)) == pytest.approx((p.lon_deg, p.lat_deg), abs=1e-9)


def test_convergence_of_fore_and_aft_views():
    """HRS-like +-20 deg pitch: the lines of sight converge by about 40 deg along track."""
    fore = synthetic_pushbroom(spec(pitch_deg=20.0))
    aft = synthetic_pushbroom(spec(pitch_deg=-20.0))
    p = pair_geometry(fore, (N_PX, N_PX), aft, (N_PX, N_PX), 0.0)
    _, s1 = satellite_direction(fore, p.col1, p.row1, 0.0)
    _, s2 = satellite_direction(aft, p.col2, p.row2, 0.0)
    assert p.convergence_deg == pytest.approx(
        np.degrees(np.arccos(float(s1[0] @ s2[0]))), abs=1e-6)
    assert 40.0 < p.convergence_deg < 48.0  # 20 deg off-nadir at the satellite is ~22.6 at ground


def test_identical_footprints_overlap_fully_with_no_convergence(views):
    m = views[25.0]
    p = pair_geometry(m, (N_PX, N_PX), m, (N_PX, N_PX), 300.0)
    assert p.overlap_pct == pytest.approx(100.0, abs=1e-9)
    assert p.convergence_deg == pytest.approx(0.0, abs=1e-6) and p.b_over_h < 1e-7
    assert (p.col1, p.row1) == pytest.approx((p.col2, p.row2))


def test_overlap_of_a_scene_shifted_by_a_quarter_of_its_width(views):
    """Two nadir views of the same camera, centred 150 px apart across track: 75 %."""
    m = views[0.0]
    lon, lat = m.localize(299.5 + 150.0, 299.5, 0.0)
    shifted = synthetic_pushbroom(spec(centre_lon_deg=float(lon), centre_lat_deg=float(lat)))
    p = pair_geometry(m, (N_PX, N_PX), shifted, (N_PX, N_PX), 0.0)
    assert p.overlap_pct == pytest.approx(75.0, abs=0.5)
    assert p.col1 == pytest.approx(299.5 + 75.0, abs=2.0)
    far = synthetic_pushbroom(spec(centre_lon_deg=LON + 1.0))
    with pytest.raises(GeometryError, match="do not overlap"):
        pair_geometry(m, (N_PX, N_PX), far, (N_PX, N_PX), 0.0)


def test_centre_rays_meet_at_the_height_both_centres_see():
    a = synthetic_pushbroom(spec(incidence_deg=15.0, centre_h_m=800.0))
    b = synthetic_pushbroom(spec(incidence_deg=-10.0, centre_h_m=800.0))
    h, miss = centre_rays_height_m(a, (N_PX, N_PX), b, (N_PX, N_PX), 0.0)
    assert h == pytest.approx(800.0, abs=1e-3) and miss < 1e-3
    with pytest.raises(GeometryError, match="parallel"):
        centre_rays_height_m(a, (N_PX, N_PX), a, (N_PX, N_PX), 0.0)


# ------------------------------------------------------------------------- headings


@pytest.mark.parametrize("ascending", [False, True])
def test_along_track_heading_is_the_geodesic_azimuth_between_consecutive_rows(ascending):
    """Against PROJ's geodesic azimuth (pyproj.Geod.inv) between the ground points of rows
    r -+ 0.5: a descending SPOT-like pass at 44 N heads south-south-west of south (about 192
    deg: 180 + asin(cos i / cos lat) = 192.1 with the inclination 98.7, Earth rotation aside),
    an ascending one north-north-west."""
    from pyproj import Geod

    from core.sensors.viewing import along_track_heading_deg

    m = synthetic_pushbroom(spec(incidence_deg=15.0, ascending=ascending))
    c, r, h = grid()
    got = along_track_heading_deg(m, c, r, h)
    lon0, lat0 = m.localize(c.ravel(), r.ravel() - 0.5, h.ravel())
    lon1, lat1 = m.localize(c.ravel(), r.ravel() + 0.5, h.ravel())
    want, _, _ = Geod(ellps="WGS84").inv(lon0, lat0, lon1, lat1)
    assert got.shape == c.shape
    assert np.abs(((got.ravel() - want) + 180.0) % 360.0 - 180.0).max() < 0.05
    centre = float(along_track_heading_deg(m, 299.5, 299.5, 0.0))
    if ascending:
        assert 330.0 < centre < 360.0
    else:
        assert 185.0 < centre < 200.0


def test_bearing_difference_wraps_around_north():
    from core.sensors.viewing import bearing_difference_deg

    got = bearing_difference_deg([350.0, 10.0, 190.0, 0.0, 90.0], [10.0, 350.0, 10.0, 180.0, 90.0])
    assert got.tolist() == pytest.approx([20.0, 20.0, 180.0, 180.0, 0.0])
