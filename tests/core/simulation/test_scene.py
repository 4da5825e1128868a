"""Scene definitions: truth models with jitter/lens, delivered metadata with known errors."""

import numpy as np
import pytest

from core.geodesy import geodetic_to_ecef
from core.sensors.orbit import Attitude
from core.sensors.pushbroom import PushbroomModel
from core.simulation.scene import (
    PRESETS,
    ErrorConfig,
    centre_displacement_m,
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
    assert inj.centre_error_m == pytest.approx(
        centre_displacement_m(tiny_truth, delivered, 600.0), rel=1e-9)
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
