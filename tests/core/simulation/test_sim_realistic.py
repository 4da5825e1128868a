"""Realistic errors of the simulator (``--errors realistic``): each error drawn, recorded, and
recorded as it is in the geometry the scene is rendered with."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from core.errors import InputError
from core.points import GeoPoint
from core.sensors.dimap import dimap_xml, parse_dimap
from core.sensors.linear_array import LookAngleTable
from core.sensors.orbit import orbital_frame
from core.sensors.spot import integrated_attitude, spot_pushbroom, spot_scene_from_model
from core.simulation.realistic import (
    BOW_MAX_PX,
    LOOK_SCALE_MAX,
    ORBIT_BIAS_MAX_M,
    SEGMENT_OFFSET_MAX_PX,
    SPEED_QUANTUM_RAD_S,
    TIME_TAG_MAX_S,
    attitude_profile,
    calibrated_camera,
    metadata_scene,
    quantise_speeds,
    with_ephemeris_error,
    with_profile,
)
from core.simulation.scene import (
    PRESETS,
    ErrorConfig,
    InjectedErrors,
    error_config,
    scene_models,
)

SHARED = Path(__file__).resolve().parents[4] / "shared" / "data" / "spot_dimap"
CENTRE = GeoPoint(5.25, 44.2, 600.0)


@pytest.fixture(scope="module")
def simple_and_realistic():
    """The spot preset's models (seed 5), simple and realistic."""
    preset = PRESETS["spot"]
    return (scene_models(preset, CENTRE, ErrorConfig(), 5),
            scene_models(preset, CENTRE, ErrorConfig(realistic=True), 5))


def _profile_on_window(seed: int):
    rng = np.random.default_rng(seed)
    t_c, t_ref = 100.0, 99.0
    terms, line, peak = attitude_profile(rng, t_c, t_ref)
    t = np.linspace(t_c - 4.5, t_c + 4.5, 2001)
    a = np.zeros((3, t.size))
    for axis, amp, f, ph in terms:
        a[axis] += amp * np.sin(2 * np.pi * f * (t - t_ref) + ph)
    a -= line[:, :1] + line[:, 1:] * (t - t_ref)
    return t, a, peak, terms


@pytest.mark.parametrize("seed", range(6))
def test_profile_has_the_measured_amplitudes_and_is_not_a_polynomial(seed):
    t, a, peak, terms = _profile_on_window(seed)
    # the line is removed: what is left departs from a straight line by the drawn peak
    g = np.stack([np.ones(t.size), t - t.mean()], axis=1)
    resid = a - (g @ np.linalg.lstsq(g, a.T, rcond=None)[0]).T
    assert np.allclose(np.abs(resid).max(axis=1), peak, rtol=2e-3)
    assert 4e-6 <= peak[1] <= 12e-6 and all(1e-6 <= peak[i] <= 3e-6 for i in (0, 2))
    # not a polynomial: a quadratic leaves a good part of it (real files: 1-14 urad)
    g2 = np.stack([np.ones(t.size), t - t.mean(), (t - t.mean()) ** 2], axis=1)
    quad = a - (g2 @ np.linalg.lstsq(g2, a.T, rcond=None)[0]).T
    assert np.all(np.abs(quad).max(axis=1) > 0.1 * peak)
    freqs = np.array([f for _, _, f, _ in terms])
    assert freqs.min() > 0.02 and freqs.max() < 1.5  # low frequency: not jitter


def test_profile_in_attitude_keeps_bias_and_rate():
    from core.sensors.orbit import Attitude

    t, a, _, terms = _profile_on_window(3)
    rng = np.random.default_rng(3)
    terms2, line, _ = attitude_profile(rng, 100.0, 99.0)
    att = with_profile(Attitude(99.0, (1e-3, 2e-6), (-2e-3,), (0.0, 1e-7)), terms2, line)
    got = att.angles(t) - np.array([[1e-3], [-2e-3], [0.0]]) \
        - np.array([[2e-6], [0.0], [1e-7]]) * (t - 99.0)
    assert np.allclose(got, a, atol=1e-12)


def test_same_seed_same_errors_and_simple_draws_kept(simple_and_realistic):
    simple, real = simple_and_realistic
    again = scene_models(PRESETS["spot"], CENTRE, ErrorConfig(realistic=True), 5)
    for n in ("left", "right"):
        assert real[n].truth.to_json() == again[n].truth.to_json()
        assert real[n].delivered.to_json() == again[n].delivered.to_json()
        s, r = simple[n].injected, real[n].injected
        # the realistic errors come from their own stream: the simple ones are unchanged
        assert (s.roll_bias_rad, s.pitch_rate_rad_s) == (r.roll_bias_rad, r.pitch_rate_rad_s)
        assert s.realistic is None and r.realistic is not None
        back = InjectedErrors.from_dict(r.to_dict())
        assert back.to_dict() == r.to_dict()
        rec = r.realistic
        assert all(abs(b) <= m for b, m in zip(rec.orbit_bias_m, ORBIT_BIAS_MAX_M, strict=True))
        assert abs(rec.time_tag_s) <= TIME_TAG_MAX_S and abs(rec.look_scale) <= LOOK_SCALE_MAX
        assert abs(rec.bow_px) <= BOW_MAX_PX and len(rec.segment_offsets_px) == 4
        assert np.abs(rec.segment_offsets_px).max() <= SEGMENT_OFFSET_MAX_PX
        assert "realistic" not in s.to_dict()  # simple scenes keep their scene.json layout
    assert real["left"].injected.realistic != real["right"].injected.realistic


def test_error_modes_per_preset():
    assert error_config("spot").realistic and error_config("hrs").realistic
    assert not error_config("tiny").realistic  # the test suite's scenes stay simple
    assert error_config("tiny", "realistic", lens=True).realistic
    assert not error_config("spot", "simple").realistic
    with pytest.raises(InputError, match="--errors"):
        error_config("spot", "harsh")


def test_ephemeris_errors_in_the_delivered_geometry(simple_and_realistic):
    """The recorded orbit bias and time tag are what separates the delivered geometry from
    the one without them (the delivered orbit positions as the chain reads them)."""
    simple, real = simple_and_realistic
    for n in ("left", "right"):
        rec = real[n].injected.realistic
        before, after = simple[n].delivered, real[n].delivered
        o = before.orbit
        d = after.orbit.positions_m - o.positions_m
        local = np.einsum("mji,mj->mi", orbital_frame(o.positions_m, o.velocities_m_s), d)
        expect = np.array([rec.orbit_bias_m[0], rec.orbit_bias_m[1], -rec.orbit_bias_m[2]])
        assert np.allclose(local, expect, atol=1e-6)
        assert after.t0_s - before.t0_s == pytest.approx(rec.time_tag_s, abs=1e-6)


def test_time_tag_moves_the_ground_by_the_satellite_speed():
    m = scene_models(PRESETS["tiny"], CENTRE, ErrorConfig(), 2)["left"].delivered
    moved = with_ephemeris_error(m, (0.0, 0.0, 0.0), 1e-3)
    lon, lat = m.localize(300.0, 300.0, 600.0)
    _, row = moved.project(lon, lat, 600.0)
    # a line dated 1 ms late is a line period's worth of ground: 1e-3 / line period rows
    assert float(300.0 - row) == pytest.approx(1e-3 / m.line_period_s, rel=0.02)


def test_true_camera_has_the_recorded_calibration(simple_and_realistic):
    """Scale, bow and segment offsets recovered by least squares from the true camera the
    scene is rendered with, against the nominal one, equal the recorded ones."""
    simple, real = simple_and_realistic
    for n in ("left", "right"):
        rec = real[n].injected.realistic
        nominal = LookAngleTable.from_camera(simple[n].truth.camera)
        true = real[n].truth.camera
        ifov, k = nominal.ifov_rad, nominal.n_cols
        cols = np.arange(k, dtype=np.float64)
        c = 0.5 * (k - 1)
        u = (cols - c) / c
        seg = (cols * 4 // k).astype(int)
        onehot = (seg[:, None] == np.arange(4)[None, :]).astype(float)
        psi_c = np.interp(c, cols, nominal.psi_x_rad)
        # across: scale * (psi - psi_c) + segment offsets
        g = np.column_stack([nominal.psi_x_rad - psi_c, onehot * ifov])
        sol = np.linalg.lstsq(g, true.psi_x_rad - nominal.psi_x_rad, rcond=None)[0]
        assert sol[0] == pytest.approx(rec.look_scale, abs=1e-9)
        assert np.allclose(sol[1:], [o[0] for o in rec.segment_offsets_px], atol=1e-6)
        g = np.column_stack([u**2 * ifov, onehot * ifov])
        sol = np.linalg.lstsq(g, true.psi_y_rad - nominal.psi_y_rad, rcond=None)[0]
        assert sol[0] == pytest.approx(rec.bow_px, abs=1e-6)
        assert np.allclose(sol[1:], [o[1] for o in rec.segment_offsets_px], atol=1e-6)


def test_calibrated_camera_effects_in_pixels():
    table = LookAngleTable.from_camera(
        scene_models(PRESETS["tiny"], CENTRE, ErrorConfig(), 1)["left"].truth.camera)
    ifov = table.ifov_rad
    scaled = calibrated_camera(table, 1e-4, 0.0, ())
    end = (scaled.psi_x_rad[-1] - table.psi_x_rad[-1]) / ifov
    assert end == pytest.approx(1e-4 * 0.5 * (table.n_cols - 1), rel=1e-3)  # 0.03 px on 600
    bowed = calibrated_camera(table, 0.0, 0.2, ())
    d = (bowed.psi_y_rad - table.psi_y_rad) / ifov
    assert d[0] == pytest.approx(0.2) and d[-1] == pytest.approx(0.2)
    assert abs(d[table.n_cols // 2]) < 1e-5
    seg = calibrated_camera(table, 0.0, 0.0, ((0.0, 0.0), (0.1, -0.05)))
    d = (seg.psi_x_rad - table.psi_x_rad) / ifov
    assert np.allclose(d[:300], 0.0) and np.allclose(d[300:], 0.1)


# ------------------------------------------------------------------------- measured speeds


def test_delivered_speeds_integrated_by_the_reader_reproduce_the_attitude(simple_and_realistic):
    """The delivered metadata state the attitude's angular speeds quantised as real files do;
    the chain's own SPOT reader integrates them back to the true sampled attitude within the
    quantisation's integrated error (bounded by sum q/2 dt) and not better (the quantisation is
    a real measurement error, not rounding noise)."""
    simple, real = simple_and_realistic
    m = simple["left"].delivered
    rng = np.random.default_rng(0)
    t_c = m.t0_s + 0.5 * (m.n_rows - 1) * m.line_period_s
    terms, line, _ = attitude_profile(rng, t_c, m.attitude.t_ref_s)
    ideal = replace(m, attitude=with_profile(m.attitude, terms, line))
    exact = spot_scene_from_model(ideal, mission_index=2)
    quant = quantise_speeds(exact)
    q = SPEED_QUANTUM_RAD_S
    for k in ("roll", "pitch", "yaw"):
        w = getattr(quant.aocs_speeds, k)
        assert np.allclose(w / q, np.round(w / q), atol=1e-9, rtol=0)
    a_exact = integrated_attitude(exact.aocs_angles, exact.aocs_speeds)
    a_quant = integrated_attitude(quant.aocs_angles, quant.aocs_speeds)
    dt = np.diff(a_exact.times_s)
    bound = np.concatenate([[0.0], np.cumsum(0.5 * q * dt)])
    for k in ("roll", "pitch", "yaw"):
        err = getattr(a_quant, k) - getattr(a_exact, k)
        assert np.all(np.abs(err) <= bound + 1e-15)
        # not better: the error reaches at least a sample's quantum worth
        assert np.abs(err).max() > 0.1 * q * float(dt.mean())
    # and the delivered model of a realistic scene is exactly what the reader makes of them
    d = real["left"].delivered
    scene = metadata_scene(d, 2, "HRV")
    back = spot_pushbroom(parse_dimap(dimap_xml(scene)))
    lon, lat = d.localize(np.array([0.0, 3000.0, 5999.0]), np.array([0.0, 3000.0, 5999.0]),
                          np.full(3, 600.0))
    c, r = back.project(lon, lat, np.full(3, 600.0))
    assert np.allclose(c, [0.0, 3000.0, 5999.0], atol=1e-3)
    assert np.allclose(r, [0.0, 3000.0, 5999.0], atol=1e-3)


@pytest.mark.skipif(not SHARED.is_dir(), reason="../shared/data/spot_dimap is absent")
def test_delivered_speeds_look_like_a_real_spot2_file(simple_and_realistic):
    """Checked against the real SPOT2.DIM (not copied here): its Angular_Speeds come every
    0.123-0.127 s and every value is an integer multiple of 2e-5 deg/s = 3.4907e-7 rad/s (18-34
    distinct values per axis over 9 s); ours come every 0.125 s on the same quantum, with
    speeds of the same size (a few quanta)."""
    real = parse_dimap((SHARED / "SPOT2.DIM").read_text(), "SPOT2.DIM").aocs_speeds
    ours = metadata_scene(simple_and_realistic[1]["left"].delivered, 2, "HRV").aocs_speeds
    q = SPEED_QUANTUM_RAD_S
    for s in (real, ours):
        dt = np.diff(s.times_s)
        assert 0.122 <= dt.min() and dt.max() <= 0.128
        assert s.times_s[-1] - s.times_s[0] > 8.5  # a 9 s scene
        for k in ("roll", "pitch", "yaw"):
            w = getattr(s, k)
            assert np.allclose(w / q, np.round(w / q), atol=1e-6, rtol=0)
    # the profile's speeds are of the real file's size (pitch up to ~10 quanta), not 0 or 100
    for k in ("pitch",):
        n_real = np.abs(getattr(real, k) - np.median(getattr(real, k))).max() / q
        n_ours = np.abs(getattr(ours, k) - np.median(getattr(ours, k))).max() / q
        assert 0.2 * n_real <= n_ours <= 5 * n_real
