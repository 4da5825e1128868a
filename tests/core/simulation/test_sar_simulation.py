"""core.simulation.sar and sar_render: the SAR simulator's geometry and rendering against the
zero-Doppler model of core.sensors.sar (an independent Newton on Lagrange-interpolated state
vectors), the delivered model against the truth by exactly the drawn errors, determinism, and
layover and shadow where a steep synthetic ridge puts them."""

from __future__ import annotations

from dataclasses import replace
from functools import cache

import numpy as np
import pytest

from core.geodesy import enu_rotation, geodetic_to_ecef, metres_per_degree
from core.sensors.orbit import orbital_frame
from core.sensors.sar import SPEED_OF_LIGHT_M_S, grid_check
from core.simulation import sar as S
from core.simulation import sar_render as SR
from core.simulation.landcover import LandCover

CLON, CLAT, CH = 5.25, 44.2, 500.0
M_LON, M_LAT = (float(v) for v in metres_per_degree(CLAT))
HALF_M = 3000.0
RES_M = 10.0


def to_lonlat(x, y):
    """A local plane around the centre: x east, y north (no grid convergence)."""
    return CLON + np.asarray(x) / M_LON, CLAT + np.asarray(y) / M_LAT


@cache
def models(name: str, seed: int = 3, scale: float = 1.0) -> S.SarModels:
    xs = np.array([-HALF_M, HALF_M, HALF_M, -HALF_M] * 2)
    ys = np.array([-HALF_M, -HALF_M, HALF_M, HALF_M] * 2)
    lon, lat = to_lonlat(xs, ys)
    h = np.array([400.0] * 4 + [900.0] * 4)
    return S.sar_models(S.mission(name), lon, lat, h, (CLON, CLAT, CH), CH, scale,
                        np.random.default_rng(seed))


def _ecef(lon, lat, h):
    return np.stack(geodetic_to_ecef(lon, lat, h), axis=-1)


@pytest.mark.parametrize("name", ["ers", "s1"])
def test_orbit_sees_the_centre_at_the_mission_incidence(name):
    m = S.mission(name)
    t = models(name).truth
    assert t.kind == m.kind and t.look_side == "right"
    g = _ecef(CLON, CLAT, CH)[None]
    tz, r = t.zero_doppler(g)
    s, _ = t.orbit.interpolate(tz)
    los = (s - g) / r[:, None]
    inc = np.degrees(np.arccos(los[0] @ enu_rotation(CLON, CLAT)[2]))
    # the orbit was solved on its own analytic states, checked here on the interpolated ones
    assert abs(inc - m.incidence_deg) < 1e-4
    alt = np.linalg.norm(s[0]) - 6371e3
    assert abs(alt - m.altitude_m) < 30e3  # radius a + altitude above a mean Earth radius
    # the image covers the ground asked for, the centre inside
    c, r0 = t.project(*to_lonlat(np.array([-HALF_M, HALF_M]), np.array([HALF_M, -HALF_M])),
                      np.array([400.0, 900.0]))
    assert np.all((c > 0) & (c < t.n_cols - 1) & (r0 > 0) & (r0 < t.n_rows - 1))


@pytest.mark.parametrize("name", ["ers", "s1"])
def test_fast_zero_doppler_agrees_with_the_model(name):
    t = models(name).truth
    fit = S.OrbitFit.of(t.orbit, t.first_line_time_s - 2, t.first_line_time_s
                        + t.n_rows * t.line_interval_s + 2)
    rng = np.random.default_rng(5)
    lon, lat = to_lonlat(rng.uniform(-HALF_M, HALF_M, 500), rng.uniform(-HALF_M, HALF_M, 500))
    h = rng.uniform(0, 2000, 500)
    tz, r, _ = fit.zero_doppler(_ecef(lon, lat, h), fit.t_mid)
    c1, r1 = t.image_of_times(tz + t.azimuth_offset_s,
                              2 * r / SPEED_OF_LIGHT_M_S + t.range_delay_s)
    c2, r2 = t.project(lon, lat, h)
    assert np.abs(c1 - c2).max() < 1e-6 and np.abs(r1 - r2).max() < 1e-6


@pytest.mark.parametrize("name", ["ers", "s1"])
def test_delivered_differs_from_truth_by_exactly_the_drawn_errors(name):
    ms = models(name)
    e, t, d = ms.errors, ms.truth, ms.delivered
    # the truth is the delivered model with the true orbit and the drawn timing errors
    assert (t.azimuth_offset_s, t.range_delay_s) == (e.azimuth_offset_s, e.range_delay_s)
    assert replace(t, orbit=d.orbit, azimuth_offset_s=0.0, range_delay_s=0.0).to_json() \
        == d.to_json()
    # the orbit moved by the drawn offset in the local orbital frame
    frame = orbital_frame(t.orbit.positions_m, t.orbit.velocities_m_s)
    moved = np.einsum("nji,nj->ni", frame, d.orbit.positions_m - t.orbit.positions_m)
    np.testing.assert_allclose(moved, np.tile([e.orbit_along_m, e.orbit_across_m,
                                               -e.orbit_radial_m], (moved.shape[0], 1)),
                               atol=1e-6)
    np.testing.assert_allclose(e.range_delay_s * SPEED_OF_LIGHT_M_S / 2,
                               e.range_troposphere_m + e.range_instrument_m, rtol=1e-12)
    # localising a pixel: with the true orbit the two differ by the timing errors only:
    # along track by the azimuth offset times the ground speed, across by the range delay
    # over sin(incidence)
    c, r, h = 0.5 * (t.n_cols - 1), 0.5 * (t.n_rows - 1), CH
    d_true_orbit = replace(d, orbit=t.orbit)
    p_t = _ecef(*t.localize(c, r, h), h).ravel()
    p_d = _ecef(*d_true_orbit.localize(c, r, h), h).ravel()
    tz, _ = t.zero_doppler(p_t[None])
    s, v = t.orbit.interpolate(tz)
    along = v[0] / np.linalg.norm(v[0])
    up = enu_rotation(*t.localize(c, r, h))[2]
    los = (s[0] - p_t) / np.linalg.norm(s[0] - p_t)
    across = np.cross(along, up)
    across /= np.linalg.norm(across)
    inc = np.arccos(los @ up)
    speed = float(t.along_track_speed_m_s(tz)[0]) * (6378e3 + h) / 6378e3
    expect_along = e.azimuth_offset_s * speed
    expect_ground_range = (e.range_troposphere_m + e.range_instrument_m) / np.sin(inc)
    diff = p_d - p_t
    assert abs(diff @ along - expect_along) < 0.01 * abs(expect_along) + 0.01
    assert abs(abs(diff @ across) - abs(expect_ground_range)) < 0.01 * abs(
        expect_ground_range) + 0.01
    # and the delivered orbit adds its own offset, no more
    p_dd = _ecef(*d.localize(c, r, h), h).ravel()
    orbit_m = np.linalg.norm([e.orbit_along_m, e.orbit_across_m, e.orbit_radial_m])
    assert np.linalg.norm(p_dd - p_d) < 1.5 * orbit_m + 1e-3


def test_mission_error_figures():
    """The drawn delivered geolocation is of the class the missions have: ~10 m (ERS-like),
    a few metres (Sentinel-1-like), over 40 draws."""
    err = {n: [models(n, seed=s).centre_error_m(CH) for s in range(40)] for n in ("ers", "s1")}
    assert 5.0 < np.median(err["ers"]) < 20.0
    assert 1.5 < np.median(err["s1"]) < 6.0


@pytest.mark.parametrize("name", ["ers", "s1"])
def test_geolocation_grid_is_consistent(name):
    d = models(name).delivered
    g = S.geolocation_grid(d, CH)
    chk = grid_check(d, g.lon_deg, g.lat_deg, g.h_m, g.pixel, g.line, g.azimuth_time_s,
                     g.slant_range_time_s)
    assert chk.n_points == 210
    assert chk.pixel_max_px < 1e-6 and chk.line_max_px < 1e-6 and chk.ground_max_m < 1e-3
    assert abs(np.median(g.incidence_deg) - S.mission(name).incidence_deg) < 1.5


def test_same_seed_same_models_and_speckle():
    a, b = models("s1", seed=9), S.sar_models(
        S.mission("s1"), *to_lonlat(np.array([-HALF_M, HALF_M]), np.array([-HALF_M, HALF_M])),
        np.array([400.0, 900.0]), (CLON, CLAT, CH), CH, 1.0, np.random.default_rng(9))
    assert a.errors == b.errors
    c = models("s1", seed=10)
    assert c.errors != a.errors
    img = np.full((50, 60), 0.1)
    s1 = SR.speckle_and_noise(img, 4.4, 0.006, np.random.default_rng(1))
    s2 = SR.speckle_and_noise(img, 4.4, 0.006, np.random.default_rng(1))
    assert s1.tobytes() == s2.tobytes()
    # gamma speckle of L looks: mean preserved, variance (mean^2) / L
    big = SR.speckle_and_noise(np.full((400, 400), 1.0), 4.4, 0.0, np.random.default_rng(2))
    assert abs(big.mean() - 1.0) < 0.01 and abs(big.var() * 4.4 - 1.0) < 0.05


def _block(dsm, classes):
    n_r, n_c = dsm.shape
    return SR.GroundBlock(dsm, classes, -HALF_M + RES_M / 2, HALF_M - RES_M / 2, RES_M,
                         1, n_r - 1, 1, n_c - 1)


@pytest.mark.parametrize("name", ["ers", "s1"])
def test_a_point_lands_where_the_true_model_projects_it(name):
    """One bright cell on a dark, flat world: the centroid of what the renderer splats is the
    true model's projection of the cell's centre (renderer and model are independent code)."""
    ms = models(name)
    t = ms.truth
    n = int(2 * HALF_M / RES_M)
    dsm = np.full((n, n), 650.0)
    cls = np.zeros((n, n), dtype=np.uint8)  # nodata: no backscatter
    i, j = 217, 344
    cls[i, j] = LandCover.URBAN
    fit = S.OrbitFit.of(t.orbit, t.first_line_time_s - 2,
                        t.first_line_time_s + t.n_rows * t.line_interval_s + 2)
    rb = SR.render_block(t, fit, _block(dsm, cls), to_lonlat, 1, ms.pixel_area_m2)
    w = rb.intensity
    rr, cc = np.mgrid[0:w.shape[0], 0:w.shape[1]]
    col = rb.col0 + (w * cc).sum() / w.sum()
    row = rb.row0 + (w * rr).sum() / w.sum()
    x, y = -HALF_M + (j + 0.5) * RES_M, HALF_M - (i + 0.5) * RES_M
    pc, pr = t.project(*to_lonlat(x, y), 650.0)
    assert abs(col - pc) < 1e-6 and abs(row - pr) < 1e-6
    # flat ground shows its sigma0: the cell's power over one pixel's area
    inc = np.radians(S.mission(name).incidence_deg)
    expect = SR.sigma0(np.array([inc]), np.array([LandCover.URBAN]))[0] * RES_M**2 \
        / ms.pixel_area_m2(np.array([inc]))[0]
    assert abs(w.sum() / expect - 1) < 0.05  # the incidence at the cell differs a little


@cache
def ridge(name: str):
    """A ridge across the look: flat at 500 m, a face rising away from the sensor at 60 deg
    (steeper than the incidence: layover), a plateau at 800 m, a face falling away at 80 deg
    (steeper than 90 - incidence: shadow, cast beyond its foot)."""
    ms = models(name)
    t = ms.truth
    n = int(2 * HALF_M / RES_M)
    x = -HALF_M + (np.arange(n) + 0.5) * RES_M
    X, Y = np.meshgrid(x, -x)
    g = _ecef(CLON, CLAT, CH)[None]
    tz, _ = t.zero_doppler(g)
    s, _ = t.orbit.interpolate(tz)
    enu = enu_rotation(CLON, CLAT)
    look = enu @ (s[0] - g[0])
    ue, un = look[:2] / np.hypot(*look[:2])
    u = -(X * ue + Y * un)  # horizontal distance away from the sensor
    w1 = 300.0 / np.tan(np.radians(60.0))
    w2 = 300.0 / np.tan(np.radians(80.0))
    z = 500.0 + np.interp(u, [-1e4, 0.0, w1, 1000.0, 1000.0 + w2, 1e4],
                          [0.0, 0.0, 300.0, 300.0, 0.0, 0.0])
    cls = np.full((n, n), LandCover.BARE_SOIL, dtype=np.uint8)
    fit = S.OrbitFit.of(t.orbit, t.first_line_time_s - 2,
                        t.first_line_time_s + t.n_rows * t.line_interval_s + 2)
    rb = SR.render_block(t, fit, _block(z, cls), to_lonlat, 1, ms.pixel_area_m2)
    inc = np.arccos(look[2] / np.linalg.norm(look))
    return ms, u[1:-1, 1:-1], rb, float(inc), w1, w2, (ue, un)


@pytest.mark.parametrize("name", ["ers", "s1"])
def test_layover_and_shadow_where_the_geometry_says(name):
    _, u, rb, inc, w1, w2, _ = ridge(name)
    shadow_end = 1000.0 + 300.0 * np.tan(inc)  # the ray grazing the ridge's top edge
    expect_layover = (u > 0) & (u < w1)
    expect_shadow = (u > 1000.0) & (u < shadow_end)
    sure = np.zeros(u.shape, dtype=bool)
    sure[40:-40, 40:-40] = True  # the march to a caster would leave the block nearer the edge
    for edge in (0.0, w1, 1000.0, 1000.0 + w2, shadow_end):
        sure &= np.abs(u - edge) > 1.5 * RES_M
    assert expect_layover[sure].sum() > 1000 and expect_shadow[sure].sum() > 1000
    np.testing.assert_array_equal(rb.layover[sure], expect_layover[sure])
    np.testing.assert_array_equal(rb.shadow[sure], expect_shadow[sure])


@pytest.mark.parametrize("name", ["ers", "s1"])
def test_layover_bright_and_shadow_dark_in_the_image(name):
    ms, _, rb, inc, w1, _, (ue, un) = ridge(name)
    t = ms.truth
    img = rb.intensity
    # a line of ground points across the ridge through the centre, in image coordinates
    def at(dist, h):
        return t.project(*to_lonlat(-dist * ue, -dist * un), h)
    c_top, r_mid = at(1000.0, 800.0)
    c_end, _ = at(1000.0 + 300.0 * np.tan(inc), 500.0)
    row = round(float(r_mid)) - rb.row0
    lo, hi = int(np.ceil(c_top)) + 2 - rb.col0, int(np.floor(c_end)) - 2 - rb.col0
    assert hi - lo > 5
    assert np.all(img[row, lo:hi] == 0.0)  # nothing is seen from there: radar shadow
    flat = np.median(img[row, :lo - 40])
    c0, _ = at(0.0, 500.0)
    c1, _ = at(w1, 800.0)
    a, b = sorted((int(c0) - rb.col0, int(c1) - rb.col0))
    # the face folds onto the ground before it (its top nearer in range than its foot) and
    # adds its power to that ground's: brighter than flat ground (by about the face's share,
    # 30-60 % with its 37 (ERS) or 22 (S1) deg local incidence)
    assert c1 < c0
    assert np.median(img[row, a + 1:b - 1]) > 1.25 * flat
