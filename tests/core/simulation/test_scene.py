"""Scene definitions: truth models with jitter/lens, delivered metadata with known errors."""

import json

import numpy as np
import pytest

from core.geodesy import geodetic_to_ecef
from core.sensors.orbit import Attitude
from core.sensors.pushbroom import PushbroomModel
from core.simulation.scene import (
    PRESETS,
    ErrorConfig,
    delivered_model,
    truth_model,
)

CENTRE = (5.3, 44.2, 600.0)


@pytest.fixture(scope="module")
def tiny_truth():
    cfg = ErrorConfig(lens=True, jitter=True)
    rng = np.random.default_rng(1)
    return truth_model(PRESETS["tiny"].images[0], PRESETS["tiny"], CENTRE, cfg, rng)


def test_truth_with_jitter_and_lens_round_trips(tiny_truth):
    m = tiny_truth
    assert len(m.attitude.jitter) == 4 and m.distortion.k3 != 0
    r, c = np.mgrid[0:600:37, 0:600:41].astype(float)
    h = np.full(c.shape, 900.0)
    lon, lat = m.localize(c, r, h)
    c2, r2 = m.project(lon, lat, h)
    assert np.hypot(c2 - c, r2 - r).max() < 1e-3
    again = PushbroomModel.from_json(m.to_json())
    np.testing.assert_array_equal(again.localize(c, r, h)[0], lon)


def test_jitter_is_not_absorbed_by_a_quadratic(tiny_truth):
    att = tiny_truth.attitude
    t = tiny_truth.line_time_s(np.arange(0, 600, 0.5))
    smooth = Attitude(att.t_ref_s, att.roll_rad, att.pitch_rad, att.yaw_rad)
    jit = att.angles(t) - smooth.angles(t)
    for axis in (0, 1):
        coef = np.polyfit(t - att.t_ref_s, jit[axis], 2)
        resid = jit[axis] - np.polyval(coef, t - att.t_ref_s)
        assert resid.std() > 0.5 * jit[axis].std() > 0


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_delivered_error_at_centre_is_within_100_300_m(tiny_truth, seed):
    rng = np.random.default_rng(seed)
    delivered, inj = delivered_model(tiny_truth, PRESETS["tiny"], ErrorConfig(), rng, 600.0)
    assert 100.0 <= inj.centre_error_m <= 300.0
    # independently: where the delivered model sees the true centre ground point, in pixels
    # of the true model's ground sampling (40 m), without centre_displacement_m
    c0 = (tiny_truth.n_cols - 1) / 2
    lon, lat = tiny_truth.localize(c0, c0, 600.0)
    cd, rd = delivered.project(lon, lat, 600.0)
    lon_d, lat_d = tiny_truth.localize(cd, rd, 600.0)  # the ground the delivered pixel maps to
    g = np.array(geodetic_to_ecef(lon, lat, 600.0)).ravel()
    g_d = np.array(geodetic_to_ecef(lon_d, lat_d, 600.0)).ravel()
    assert np.linalg.norm(g - g_d) == pytest.approx(inj.centre_error_m, rel=0.02)
    # the delivered metadata know neither the jitter nor the lens
    assert delivered.attitude.jitter == () and delivered.distortion.k3 == 0.0
    assert abs(inj.roll_rate_rad_s) + abs(inj.pitch_rate_rad_s) > 0


def test_attitude_jitter_rejects_bad_terms():
    from core.errors import InputError

    with pytest.raises(InputError, match="jitter"):
        Attitude(0.0, jitter=((5, 1e-6, 10.0, 0.0),))
    with pytest.raises(InputError, match="jitter"):
        Attitude.from_dict({"t_ref_s": 0.0, "roll_rad": [0.0], "pitch_rad": [0.0],
                            "yaw_rad": [0.0], "jitter": [[0, 1.0]]})


def test_lens_distortion_reaches_the_stated_shift_at_the_edge():
    preset = PRESETS["tiny"]
    spec = preset.images[0]
    cfg = ErrorConfig(lens=True, lens_edge_px=1.5)
    with_lens = truth_model(spec, preset, CENTRE, cfg, np.random.default_rng(3))
    from dataclasses import replace

    from core.sensors.linear_array import LensDistortion

    without = replace(with_lens, distortion=LensDistortion())
    lon, lat = without.localize(np.array([0.0, 299.5, 599.0]), np.array([300.0] * 3), 600.0)
    c, _ = with_lens.project(lon, lat, np.full(3, 600.0))
    shift = c - np.array([0.0, 299.5, 599.0])
    assert abs(shift[1]) < 0.05  # no distortion at the centre
    # radial: opposite shifts at the two edges, lens_edge_px each; decentering: a common
    # shift of at most 3 x 0.1 x lens_edge_px (p (r^2 + 2 x^2) at the edge)
    radial = 0.5 * (shift[2] - shift[0])
    common = 0.5 * (shift[2] + shift[0])
    assert abs(abs(radial) - 1.5) < 0.05
    assert abs(common) <= 0.45 + 0.05
    # and projection stays well posed well beyond the edges
    lon2, lat2 = with_lens.localize(np.array([-300.0, 900.0]), np.array([300.0, 300.0]), 600.0)
    c2, _ = with_lens.project(lon2, lat2, np.full(2, 600.0))
    np.testing.assert_allclose(c2, [-300.0, 900.0], atol=1e-6)


def _base_to_height(preset_name: str) -> tuple[float, float]:
    """B/H of a preset's pair at the scene centre, and the base's along-track share."""
    preset = PRESETS[preset_name]
    rng = np.random.default_rng(0)
    ms = [truth_model(s, preset, CENTRE, ErrorConfig(), rng) for s in preset.images]
    g = np.array(geodetic_to_ecef(*CENTRE)).ravel()
    pos, vel = [], []
    for m in ms:
        _, r = m.project(CENTRE[0], CENTRE[1], CENTRE[2])
        p, v = m.orbit.interpolate(np.atleast_1d(m.line_time_s(r)))
        pos.append(p[0])
        vel.append(v[0])
    base = pos[1] - pos[0]
    height = np.mean([np.dot(p - g, g / np.linalg.norm(g)) for p in pos])
    along = abs(np.dot(base, vel[0] / np.linalg.norm(vel[0]))) / np.linalg.norm(base)
    return float(np.linalg.norm(base) / height), float(along)


def test_hrs_preset_is_an_along_track_pair_with_b_over_h_near_08():
    bh, along = _base_to_height("hrs")
    assert 0.7 < bh < 0.9
    assert along > 0.99


def test_spot_preset_is_an_across_track_pair():
    bh, along = _base_to_height("spot")
    assert 0.6 < bh < 1.1  # +25.5 / -20 deg incidence from two orbits
    assert along < 0.5


def _swath_m(preset_name: str) -> float:
    """Ground distance between the first and the last detector of the centre line of the
    preset's first image, at the centre's height."""
    preset = PRESETS[preset_name]
    m = truth_model(preset.images[0], preset, CENTRE, ErrorConfig(), np.random.default_rng(0))
    row = 0.5 * (m.n_rows - 1)
    lon, lat = m.localize(np.array([0.0, m.n_cols - 1.0]), np.array([row, row]), CENTRE[2])
    a, b = (np.array(geodetic_to_ecef(lon[i], lat[i], CENTRE[2])).ravel() for i in (0, 1))
    return float(np.linalg.norm(b - a))


def test_hrg_preset_is_spot5_hrg_like_four_times_spot_on_the_same_ground():
    hrg, spot = PRESETS["hrg"], PRESETS["spot"]
    assert (hrg.n_cols, hrg.n_rows, hrg.gsd_m) == (12000, 12000, 5.0)
    assert hrg.n_cols * hrg.n_rows == 4 * spot.n_cols * spot.n_rows
    assert (hrg.spot_mission, hrg.spot_instrument) == (5, "HRG")
    assert all(abs(s.incidence_deg) <= 27.0 for s in hrg.images)  # HRG steering range
    assert hrg.images[0].date != hrg.images[1].date
    # 12000 detectors of 5 m: a 60 km swath, the ground of the spot preset
    swath = _swath_m("hrg")
    assert 58_000.0 < swath < 66_000.0
    assert abs(swath / _swath_m("spot") - 1.0) < 0.01
    bh, along = _base_to_height("hrg")
    assert 0.6 < bh < 1.1 and along < 0.5  # across track, two orbits, as spot


def test_scene_def_json_keeps_its_documented_layout_and_round_trips():
    from core.geodesy import BBox
    from core.points import GeoPoint
    from core.sensors.linear_array import LensDistortion
    from core.simulation.scene import InjectedErrors, SceneDef, TruthGrid

    inj = InjectedErrors(1e-5, -2e-5, 3e-6, 1e-7, 0.0, -1e-7, 123.4,
                         ((0, 1e-6, 5.5, 0.25),), LensDistortion(k3=0.01, p1=1e-4))
    scene = SceneDef(
        preset="tiny", seed=3, dem_path="/d/N44E005.hgt",
        dem_window=BBox(4.9995833, 43.9995833, 5.5279167, 44.40125), relief_factor=1.0,
        H_ref_m=602.0, centre=GeoPoint(5.25, 44.2, 858.9), epsg=32631,
        grid=TruthGrid(664280.0, 4911760.0, 20.0, 1550, 1519), water_level_m=127.5, bits=8,
        date_change=0.1, errors=ErrorConfig(lens=True), image_names=("left", "right"),
        dsm_range_m=(127.5, 1952.9), injected={"left": inj, "right": inj},
    )
    d = json.loads(scene.to_json())
    assert list(d) == ["preset", "seed", "dem_path", "dem_window", "relief_factor", "H_ref_m",
                       "centre", "epsg", "grid", "water_level_m", "bits", "date_change",
                       "errors", "image_names", "dsm_range_m", "injected", "dem_vertical",
                       "dem_vertical_source"]
    assert d["grid"] == [664280.0, 4911760.0, 20.0, 1550, 1519]
    assert d["centre"] == [5.25, 44.2, 858.9]
    assert d["errors"]["centre_error_m"] == [100.0, 300.0]
    assert d["injected"]["left"]["distortion"] == {"k1": 0.0, "k3": 0.01, "p1": 1e-4, "p2": 0.0}
    assert d["injected"]["left"]["jitter"] == [[0, 1e-6, 5.5, 0.25]]
    back = SceneDef.from_json(scene.to_json())
    assert back == scene and back.to_json() == scene.to_json()
    from core.errors import InputError

    with pytest.raises(InputError, match="malformed"):
        SceneDef.from_json(json.dumps({k: v for k, v in d.items() if k != "grid"}))


def test_truth_grid_covers_the_points_with_the_margin_on_the_lattice():
    from core.simulation.scene import TruthGrid

    rng = np.random.default_rng(5)
    x, y = rng.uniform(650_003.3, 661_007.7, 500), rng.uniform(4_900_001.1, 4_912_345.6, 500)
    g = TruthGrid.covering(x, y, 20.0, 200.0)
    xmin, ymin, xmax, ymax = g.bounds_m()
    assert xmin % 20.0 == 0 and ymax % 20.0 == 0
    assert xmin <= x.min() - 200.0 < xmin + 20.0 and ymax - 20.0 < y.max() + 200.0 <= ymax
    assert xmax >= x.max() + 200.0 and ymin <= y.min() - 200.0
    xx, yy = g.cell_centres(0, 2, 0, 3)
    assert xx[0].tolist() == [xmin + 10.0, xmin + 30.0, xmin + 50.0]
    assert yy[:, 0].tolist() == [ymax - 10.0, ymax - 30.0]
    a, b, c, d_, e, f = g.geotransform()
    assert (a, b, c, d_, e, f) == (20.0, 0.0, xmin, 0.0, -20.0, ymax)


def test_srtm_like_reference_has_the_stated_errors():
    """Correlated noise of the stated size and length, voids only on steep slopes, and the
    misregistration drawn within its bound."""
    from core.simulation.reference import ReferenceErrors, srtm_like

    g = np.arange(0.0, 30_000.0, 90.0)
    x, y = np.meshgrid(g, g)
    slope = np.where(x > 25_000.0, 40.0, 10.0)
    err = ReferenceErrors(noise_m=4.5, correlation_m=300.0)
    h = srtm_like(np.zeros_like(x), x, y, slope, 5, err)
    flat = h[:, : int(25_000 / 90)]
    assert np.isfinite(flat).all() and 3.0 < flat.std() < 6.0
    # correlated: neighbours (90 m apart) much alike, 3 km apart nearly independent
    near = np.corrcoef(flat[:, :-1].ravel(), flat[:, 1:].ravel())[0, 1]
    far = np.corrcoef(flat[:, :-33].ravel(), flat[:, 33:].ravel())[0, 1]
    assert near > 0.7 and abs(far) < 0.3
    steep = np.isnan(h[:, int(25_000 / 90) + 1:])
    assert 0.3 < steep.mean() < 0.7
    for seed in range(5):
        d = ReferenceErrors.drawn(seed)
        assert np.hypot(d.shift_east_m, d.shift_north_m) <= 5.0
