"""Rigorous pushbroom model: round trips, geometry of attitude errors, Jacobians, JSON."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from core.dem import GeoDEM
from core.errors import ConvergenceError, GeometryError, InputError
from core.geodesy import ecef_to_geodetic, enu_rotation, geodetic_to_ecef
from core.sensors.base import SensorModel
from core.sensors.linear_array import LensDistortion, LookAngleTable
from core.sensors.orbit import Attitude, Orbit, SampledAttitude, circular_orbit_ecef
from core.sensors.pushbroom import DEFAULT_ADJUST, PARAM_NAMES, PushbroomModel
from core.sensors.pushbroom_synthetic import SyntheticSpec, synthetic_pushbroom

LON0, LAT0 = 5.0, 44.0
N = 6000
HEIGHTS = (-400.0, 0.0, 1500.0, 4800.0)

CONFIGS: dict[str, dict] = {
    "spot_25deg": {"incidence_deg": 25.0},
    "spot_-25deg_ascending": {"incidence_deg": -25.0, "ascending": True},
    "hrs_fore_20deg": {"pitch_deg": 20.0, "incidence_deg": 3.0},
    "hrs_aft_20deg": {"pitch_deg": -20.0},
    "lens_and_ccd": {
        "incidence_deg": 25.0,
        "ccd_rotation_rad": 0.01,
        "along_track_offset_m": 0.002,
        "distortion": LensDistortion(k1=2e-4, k3=0.05, p1=3e-5, p2=-2e-5),
    },
}


def with_sampled_attitude(m: PushbroomModel, seed: int = 3) -> PushbroomModel:
    """The same scene with its attitude given as samples every 0.125 s (as SPOT metadata do):
    the polynomial plus a random walk of 1e-6 rad steps, interpolated linearly. The samples
    are not aligned with the lines (at a sample the attitude rate jumps: no derivative)."""
    rng = np.random.default_rng(seed)
    t = np.arange(m.t0_s - 2.0371, m.line_time_s(m.n_rows - 1) + 2.0, 0.125)
    walk = np.cumsum(rng.normal(0.0, 1e-6, (3, t.size)), axis=1)
    roll, pitch, yaw = m.attitude.angles(t) + walk
    return replace(m, attitude=SampledAttitude(t, roll, pitch, yaw, t_ref_s=m.attitude.t_ref_s))


@pytest.fixture(scope="module")
def models() -> dict[str, PushbroomModel]:
    out = {
        name: synthetic_pushbroom(SyntheticSpec(LON0, LAT0, n_cols=N, n_rows=N, gsd_m=10.0, **kw))
        for name, kw in CONFIGS.items()
    }
    out["sampled_attitude"] = with_sampled_attitude(out["spot_25deg"])
    return out


NAMES = [*CONFIGS, "sampled_attitude"]


@pytest.fixture(scope="module")
def spot(models: dict[str, PushbroomModel]) -> PushbroomModel:
    return models["spot_25deg"]


def _grid(n: int = 13) -> tuple[np.ndarray, np.ndarray]:
    c, r = np.meshgrid(np.linspace(0, N - 1, n), np.linspace(0, N - 1, n))
    return c.ravel(), r.ravel()


def _ground_distance_m(lon_a, lat_a, lon_b, lat_b, h) -> np.ndarray:
    a = np.stack(geodetic_to_ecef(lon_a, lat_a, h))
    b = np.stack(geodetic_to_ecef(lon_b, lat_b, h))
    return np.linalg.norm(a - b, axis=0)


# -- the synthetic constructor ------------------------------------------------------------------
def test_synthetic_centre_pixel_sees_the_target_at_the_asked_geometry(spot: PushbroomModel):
    c, r = spot.project(LON0, LAT0, 0.0)
    assert abs(c - 2999.5) < 1e-6 and abs(r - 2999.5) < 1e-6
    _, across, rng = spot.viewing_geometry(2999.5, 2999.5, 0.0)
    assert abs(across - 25.0) < 1e-8
    assert 850e3 < rng < 1000e3
    lon, lat = spot.localize([2999.0, 3000.0, 2999.5, 2999.5], [2999.5, 2999.5, 2999.0, 3000.0], 0)
    gsd = _ground_distance_m(lon[[0, 2]], lat[[0, 2]], lon[[1, 3]], lat[[1, 3]], 0.0)
    np.testing.assert_allclose(gsd, 10.0, rtol=1e-6)


@pytest.mark.parametrize("ascending", [False, True])
@pytest.mark.parametrize("incidence", [25.0, -25.0])
def test_positive_incidence_means_satellite_west_of_scene(ascending: bool, incidence: float):
    m = synthetic_pushbroom(SyntheticSpec(LON0, LAT0, n_cols=1000, n_rows=1000,
                                          incidence_deg=incidence, ascending=ascending))
    pos, _ = m.orbit.interpolate([m.line_time_s(499.5)])
    sat_lon, _, _ = ecef_to_geodetic(*pos[0])
    assert np.sign(LON0 - sat_lon) == np.sign(incidence)
    _, across, _ = m.viewing_geometry(499.5, 499.5, 0.0)
    assert abs(across - incidence) < 1e-8


def test_descending_scene_is_not_mirrored(spot: PushbroomModel):
    lon, lat = spot.localize([0, N - 1, 2999.5, 2999.5], [2999.5, 2999.5, 0, N - 1], 0.0)
    assert lon[1] > lon[0]  # columns go east
    assert lat[3] < lat[2]  # rows go south


def test_synthetic_refuses_bad_requests():
    with pytest.raises(InputError, match="centre_lat_deg"):
        synthetic_pushbroom(SyntheticSpec(0.0, 85.0))
    with pytest.raises(InputError, match="incidence_deg"):
        synthetic_pushbroom(SyntheticSpec(0.0, 10.0, incidence_deg=70.0))
    with pytest.raises(InputError, match="n_state_vectors"):
        synthetic_pushbroom(SyntheticSpec(0.0, 10.0, n_state_vectors=4))


def test_orbit_interpolation_matches_the_keplerian_orbit(spot: PushbroomModel):
    o = spot.orbit
    t = np.linspace(o.times_s[3], o.times_s[-4], 101) + 7.3
    t = t[t < o.times_s[-4]]
    pos, vel = o.interpolate(t)
    # rebuild the exact orbit from the two state vectors around the centre (same plane and phase)
    exact_p, exact_v = _exact_orbit_like(spot, t)
    assert np.max(np.linalg.norm(pos - exact_p, axis=1)) < 1e-3  # 1 mm
    assert np.max(np.linalg.norm(vel - exact_v, axis=1)) < 1e-5


def _exact_orbit_like(m: PushbroomModel, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Recover the circular orbit's elements from the centre state vector and evaluate it."""
    from core.sensors.orbit import OMEGA_EARTH_RAD_S

    k = m.orbit.times_s.size // 2
    tc, p, v = m.orbit.times_s[k], m.orbit.positions_m[k], m.orbit.velocities_m_s[k]
    v_in = v + OMEGA_EARTH_RAD_S * np.array([-p[1], p[0], 0.0])  # inertial = ECEF at tc
    hvec = np.cross(p, v_in)
    inc = np.arccos(hvec[2] / np.linalg.norm(hvec))
    node = np.cross([0.0, 0.0, 1.0], hvec)
    raan = np.arctan2(node[1], node[0])
    u0 = np.arctan2(p[2] / np.sin(inc), p[0] * np.cos(raan) + p[1] * np.sin(raan))
    return circular_orbit_ecef(t, radius_m=float(np.linalg.norm(p)), inclination_rad=inc,
                               raan_rad=raan, arg_lat0_rad=u0, t_c_s=tc)


# -- round trips ----------------------------------------------------------------------------------
@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("h", HEIGHTS)
def test_localize_then_project_round_trip(models: dict[str, PushbroomModel], name: str, h: float):
    m = models[name]
    col, row = _grid()
    lon, lat = m.localize(col, row, h)
    c2, r2 = m.project(lon, lat, h)
    assert np.max(np.abs(c2 - col)) < 1e-6
    assert np.max(np.abs(r2 - row)) < 1e-6


@pytest.mark.parametrize("name", NAMES)
def test_project_then_localize_round_trip(models: dict[str, PushbroomModel], name: str):
    m = models[name]
    rng = np.random.default_rng(1)
    col, row = rng.uniform(-50, N + 50, 2000), rng.uniform(-50, N + 50, 2000)
    lon, lat = m.localize(col, row, rng.uniform(-400, 4800, 2000))
    h = rng.uniform(-400, 4800, 2000)  # ground points near, not on, those lines of sight
    c, r = m.project(lon, lat, h)
    lon2, lat2 = m.localize(c, r, h)
    assert np.max(_ground_distance_m(lon, lat, lon2, lat2, h)) < 1e-5  # 10 micrometres


def test_localize_is_exact_at_the_height(spot: PushbroomModel):
    col, row = _grid(5)
    for h in (-400.0, 4800.0):
        lon, lat = spot.localize(col, row, h)
        g = np.stack(geodetic_to_ecef(lon, lat, h), axis=1)
        pos, _ = spot.orbit.interpolate(spot.line_time_s(row))
        lon_far, lat_far = spot.localize(col, row, h + 1000.0)
        g_far = np.stack(geodetic_to_ecef(lon_far, lat_far, h + 1000.0), axis=1)
        # the three points are collinear (the ray) to well under a millimetre
        a, b = g - pos, g_far - pos
        off = np.linalg.norm(np.cross(a, b), axis=1) / np.linalg.norm(b, axis=1)
        assert np.max(off) < 1e-4
        assert np.max(np.abs(ecef_to_geodetic(*g.T)[2] - h)) < 1e-6


def test_look_angle_table_camera_equals_parametric(models: dict[str, PushbroomModel]):
    m = models["lens_and_ccd"]
    table = PushbroomModel(
        orbit=m.orbit, attitude=m.attitude, camera=LookAngleTable.from_camera(m.camera),
        n_rows=m.n_rows, t0_s=m.t0_s, line_period_s=m.line_period_s, distortion=m.distortion,
    )
    col = np.array([0.0, 17.0, 3000.0, 5999.0])
    row = np.array([0.0, 100.0, 3000.0, 5999.0])
    lon_a, lat_a = m.localize(col, row, 200.0)
    lon_b, lat_b = table.localize(col, row, 200.0)
    assert np.max(_ground_distance_m(lon_a, lat_a, lon_b, lat_b, 200.0)) < 1e-6
    c, r = table.project(lon_a, lat_a, 200.0)
    assert np.max(np.abs(c - col)) < 1e-6 and np.max(np.abs(r - row)) < 1e-6


def test_localize_on_dem_meets_a_sloping_plane(spot: PushbroomModel):
    lon = np.linspace(4.0, 6.0, 201)
    lat = np.linspace(45.0, 43.0, 201)
    plane = 800.0 + 1500.0 * (lon[None, :] - 5.0) + 0.0 * lat[:, None]
    dem = GeoDEM(plane, lon0_deg=4.0, lat0_deg=45.0, dlon_deg=0.01, dlat_deg=-0.01)
    col, row = _grid(5)
    lon_g, lat_g, h_g = spot.localize_on_dem(col, row, dem)
    np.testing.assert_allclose(h_g, 800.0 + 1500.0 * (lon_g - 5.0), atol=2e-3)
    lon_h, lat_h = spot.localize(col, row, h_g)
    np.testing.assert_allclose(lon_g, lon_h, atol=1e-9)
    np.testing.assert_allclose(lat_g, lat_h, atol=1e-9)


def test_errors_of_geometry_and_convergence(spot: PushbroomModel):
    with pytest.raises(GeometryError, match="miss the Earth"):
        spot.localize(1e6, 0.0, 0.0)
    with pytest.raises(ConvergenceError, match="did not converge"):
        spot.project(LON0, LAT0 + 0.1, 0.0, max_iter=1)
    c, r = spot.project([np.nan, LON0], LAT0, [0.0, 0.0])  # voids propagate, others solve
    assert np.isnan(c[0]) and np.isnan(r[0]) and abs(c[1] - 2999.5) < 1e-6
    lon, lat = spot.localize([0.0, 1.0], [0.0, 1.0], [np.nan, 0.0])
    assert np.isnan(lon[0]) and np.isnan(lat[0]) and np.isfinite(lon[1])


# -- attitude errors and Jacobians ----------------------------------------------------------------
def test_roll_bias_moves_the_ground_point_as_geometry_predicts(spot: PushbroomModel):
    """A roll d turns the ray about the along-track axis a: at slant range R the ray moves
    w = R d (a x u) perpendicular to itself. Sliding along the ray u back to the ground plane
    (normal n) gives the ground shift w - (w.n / u.n) u; with w in the plane of u and n (pure
    across-track view) its length is R d / cos(incidence)."""
    d = 2e-5
    col, row = np.array([0.0, 2999.5, 5999.0]), np.array([2999.5, 2999.5, 2999.5])
    lon0, lat0 = spot.localize(col, row, 0.0)
    p = np.zeros(len(DEFAULT_ADJUST))
    p[DEFAULT_ADJUST.index("roll_bias")] = d
    lon1, lat1 = spot.with_params(p).localize(col, row, 0.0)
    shift = _ground_distance_m(lon0, lat0, lon1, lat1, 0.0)
    inc, _, rng = spot.viewing_geometry(col, row, 0.0)
    # second-order terms are ~ d tan(incidence) ~ 1e-5 relative
    np.testing.assert_allclose(shift, rng * d / np.cos(np.radians(inc)), rtol=3e-5)
    # the tangent-plane formula as vectors, against a central difference (+-d), which cancels
    # the second-order terms: agreement to 1e-6 relative
    lon2, lat2 = spot.with_params(-p).localize(col, row, 0.0)
    g_plus = np.stack(geodetic_to_ecef(lon1, lat1, 0.0), axis=1)
    g_minus = np.stack(geodetic_to_ecef(lon2, lat2, 0.0), axis=1)
    pos, vel = spot.orbit.interpolate(spot.line_time_s(row))
    for i in range(col.size):
        g = np.array(geodetic_to_ecef(lon0[i], lat0[i], 0.0))
        u = (g - pos[i]) / np.linalg.norm(g - pos[i])
        z = -pos[i] / np.linalg.norm(pos[i])
        y = np.cross(z, vel[i])
        a = np.cross(y / np.linalg.norm(y), z)  # along-track axis of the orbital frame
        n = enu_rotation(lon0[i], lat0[i])[2]
        w = rng[i] * d * np.cross(a, u)
        predicted = w - (w @ n) / (u @ n) * u
        measured = 0.5 * (g_plus[i] - g_minus[i])
        assert np.linalg.norm(measured - predicted) < 1e-6 * np.linalg.norm(predicted)


def test_bias_and_drift_shift_rows_and_columns_consistently(spot: PushbroomModel):
    ifov = spot.camera.ifov_rad
    p = np.zeros(6)
    p[DEFAULT_ADJUST.index("pitch_bias")] = 3 * ifov  # ~3 lines forward
    p[DEFAULT_ADJUST.index("roll_rate")] = ifov / 4.0  # ~1 px per 4 s
    moved = spot.with_params(p)
    lon, lat = spot.localize([2999.5], [2999.5], 0.0)
    c, r = moved.project(lon, lat, 0.0)
    assert 2.0 < abs(r[0] - 2999.5) < 5.0  # a pitch moves along track
    assert abs(c[0] - 2999.5) < 0.05  # the drift is zero at the reference time


@pytest.mark.parametrize("name", ["spot_25deg", "hrs_fore_20deg", "lens_and_ccd",
                                  "sampled_attitude"])
def test_analytic_and_numeric_jacobians_agree(models: dict[str, PushbroomModel], name: str):
    m = models[name].with_adjust(PARAM_NAMES)
    m = m.with_params(np.linspace(-1.0, 1.0, len(PARAM_NAMES)) * 1e-6)  # away from zero
    col, row = _grid(5)
    lon, lat = m.localize(col, row, 700.0)
    a = m.jacobian(lon, lat, 700.0)
    n = m.jacobian(lon, lat, 700.0, method="numeric")
    assert a.shape == (col.size, 2, len(PARAM_NAMES))
    scale = np.max(np.abs(n), axis=(0, 1))  # per parameter
    rel = np.max(np.abs(a - n), axis=(0, 1)) / scale
    assert np.all(rel < 1e-6), dict(zip(PARAM_NAMES, rel, strict=True))


def test_jacobian_predicts_the_effect_of_a_small_change(spot: PushbroomModel):
    col, row = _grid(4)
    lon, lat = spot.localize(col, row, 0.0)
    jac = spot.jacobian(lon, lat, 0.0)
    dp = np.array([1, -2, 3, 0.5, -0.5, 1]) * 1e-7
    c1, r1 = spot.with_params(dp).project(lon, lat, 0.0)
    pred = np.stack([col, row], axis=1) + jac @ dp
    assert np.max(np.abs(np.stack([c1, r1], axis=1) - pred)) < 1e-4


# -- parameters and the protocol --------------------------------------------------------------------
def test_params_protocol(spot: PushbroomModel):
    assert isinstance(spot, SensorModel)
    assert spot.param_names == DEFAULT_ADJUST
    np.testing.assert_array_equal(spot.params, np.zeros(6))
    p = np.arange(6) * 1e-6
    m2 = spot.with_params(p)
    np.testing.assert_array_equal(m2.params, p)
    np.testing.assert_array_equal(spot.params, np.zeros(6))  # unchanged
    m3 = m2.with_adjust(("roll_bias", "k1"))
    np.testing.assert_array_equal(m3.params, [0.0, 0.0])
    assert m3.corrections.pitch_bias == 1e-6  # kept while not adjusted
    with pytest.raises(InputError, match="6 finite values"):
        spot.with_params([0.0, 1.0])
    with pytest.raises(InputError, match="unknown or repeated"):
        spot.with_adjust(("roll_bias", "spin"))


def test_the_harmonics_are_one_array_under_their_old_names(spot: PushbroomModel):
    """The adjustment's names are those of the 41 fields Corrections had before the harmonics
    became one (3, 8) array, in the same order; each harmonic name is its cell of the array,
    and a model file naming a harmonic reads into that cell and writes it back."""
    from core.sensors.corrections import N_HARMONICS, Corrections

    old = ("roll_bias", "pitch_bias", "yaw_bias", "roll_rate", "pitch_rate", "yaw_rate",
           "roll_quad", "pitch_quad", "yaw_quad", "orbit_along_m", "orbit_across_m",
           "orbit_radial_m", "focal_scale", "k1", "k3", "p1", "p2",
           *(f"{a}_h{k}" for a in ("roll", "pitch", "yaw") for k in range(1, 9)))
    assert PARAM_NAMES == old and N_HARMONICS == 8
    c = Corrections.from_values({"pitch_h2": 1e-6, "yaw_h8": -2e-6, "k1": 3e-5})
    expected = np.zeros((3, 8))
    expected[1, 1], expected[2, 7] = 1e-6, -2e-6
    np.testing.assert_array_equal(c.harmonics(), expected)
    assert c.value("pitch_h2") == 1e-6 and c.k1 == 3e-5 and c != Corrections()
    m = spot.with_adjust(("roll_bias", "yaw_h8", "pitch_h2")).with_params([1e-7, 4e-6, 5e-6])
    assert m.corrections.harmonic_rad[2, 7] == 4e-6 and m.corrections.value("pitch_h2") == 5e-6
    d = spot.to_dict()
    d["corrections"] = {"roll_h3": 7e-7}
    back = PushbroomModel.from_dict(d)
    assert back.corrections.harmonic_rad[0, 2] == 7e-7
    assert back.to_dict()["corrections"]["roll_h3"] == 7e-7
    assert "roll_h4" not in back.to_dict()["corrections"]  # zero harmonics are not written
    with pytest.raises(InputError, match=r"\(3, 8\)"):
        Corrections(harmonic_rad=np.zeros((3, 7)))


def test_orbit_and_attitude_validate_their_inputs():
    t = np.arange(8.0) * 30
    p = np.ones((8, 3)) * 7e6
    with pytest.raises(InputError, match="strictly increasing"):
        Orbit(t[::-1], p, p)
    with pytest.raises(InputError, match=r"\(8, 3\)"):
        Orbit(t, p[:5], p)
    with pytest.raises(InputError, match="roll_rad"):
        Attitude(0.0, roll_rad=(np.nan,))


# -- JSON ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["spot_25deg", "lens_and_ccd", "sampled_attitude"])
def test_json_round_trip_is_exact(models: dict[str, PushbroomModel], name: str):
    m = models[name].with_adjust(PARAM_NAMES).with_params(
        np.linspace(-1, 1, len(PARAM_NAMES)) * 1.234567e-6)
    text = m.to_json()
    back = PushbroomModel.from_json(text)
    assert back.to_json() == text
    np.testing.assert_array_equal(back.orbit.positions_m, m.orbit.positions_m)
    assert back.attitude == m.attitude and back.camera == m.camera
    assert back.corrections == m.corrections and back.adjust == m.adjust
    col, row = _grid(3)
    for a, b in zip(m.localize(col, row, 10.0), back.localize(col, row, 10.0), strict=True):
        np.testing.assert_array_equal(a, b)


def test_json_round_trip_of_a_table_camera(spot: PushbroomModel):
    from dataclasses import replace

    m = replace(spot, camera=LookAngleTable.from_camera(spot.camera))
    back = PushbroomModel.from_json(m.to_json(indent=1))
    np.testing.assert_array_equal(back.camera.psi_x_rad, m.camera.psi_x_rad)
    assert back.to_json() == m.to_json()


def _broken(d: dict, path: str, value: object = KeyError) -> str:
    d = json.loads(json.dumps(d))
    *parents, last = path.split(".")
    node = d
    for k in parents:
        node = node[k]
    if value is KeyError:
        del node[last]
    else:
        node[last] = value
    return json.dumps(d)


@pytest.mark.parametrize(
    ("path", "value"),
    [
        ("orbit.times_s", KeyError),
        ("orbit", KeyError),
        ("timing.line_period_s", "fast"),
        ("timing.t0_s", True),
        ("attitude.roll_rad", []),
        ("orbit.positions_m", [[1.0, 2.0], [3.0]]),
        ("camera.focal_length_m", None),
        ("camera.type", "fisheye"),
        ("image.n_rows", 12.5),
        ("distortion.k3", KeyError),
        ("adjust", "roll_bias"),
    ],
)
def test_bad_json_names_the_key(spot: PushbroomModel, path: str, value: object):
    text = _broken(spot.to_dict(), path, value)
    with pytest.raises(InputError, match=path.replace(".", r"\.")):
        PushbroomModel.from_json(text)


def test_bad_json_other_cases(spot: PushbroomModel):
    with pytest.raises(InputError, match="not valid JSON"):
        PushbroomModel.from_json("{")
    with pytest.raises(InputError, match="format"):
        PushbroomModel.from_json(_broken(spot.to_dict(), "format", "rpc"))
    with pytest.raises(InputError, match="image.n_cols"):
        PushbroomModel.from_json(_broken(spot.to_dict(), "image.n_cols", 12))
    with pytest.raises(InputError, match="corrections"):
        PushbroomModel.from_json(_broken(spot.to_dict(), "corrections", {"spin": 1.0}))
    with pytest.raises(InputError, match="unknown or repeated"):
        PushbroomModel.from_json(_broken(spot.to_dict(), "adjust", ["roll_bias", "spin"]))


# -- batches --------------------------------------------------------------------------------------
def test_project_solves_a_large_batch_at_once(spot: PushbroomModel):
    """100k points in one call (the vectorised Newton); timing lives in bench/perf/bench_pushbroom.py."""
    rng = np.random.default_rng(0)
    n = 100_000
    col, row, h = rng.uniform(0, N - 1, n), rng.uniform(0, N - 1, n), rng.uniform(-400, 4800, n)
    lon, lat = spot.localize(col, row, h)
    c, r = spot.project(lon, lat, h)
    assert np.max(np.abs(c - col)) < 1e-6 and np.max(np.abs(r - row)) < 1e-6
