"""Attitude jitter: not absorbed by a quadratic, zero mean, tile independent."""

from __future__ import annotations

import numpy as np
import pytest

from core.errors import InputError
from core.simulation.jitter import jitter_profile

AMP = np.array([2e-6, 3e-6, 1e-6])
FREQ = np.array([0.9, 2.3, 7.1])
SCENE = (0.0, 9.0)  # a 9 s SPOT scene


def test_quadratic_cannot_absorb_jitter() -> None:
    t = np.linspace(*SCENE, 6000)
    j = jitter_profile(t, 3, AMP, FREQ, scene_interval_s=SCENE)
    assert j.shape == (6000, 3)
    for axis in range(3):
        fit = np.polyval(np.polyfit(t, j[:, axis], 2), t)
        rms = np.sqrt(np.mean(j[:, axis] ** 2))
        assert np.sqrt(np.mean((j[:, axis] - fit) ** 2)) > 0.5 * rms
        # sum of sinusoids of random phase: RMS = amplitude * sqrt(K / 2)
        assert rms == pytest.approx(AMP[axis] * np.sqrt(1.5), rel=0.15)


def test_zero_mean_over_scene_exactly() -> None:
    t = np.linspace(*SCENE, 200_001)
    j = jitter_profile(t, 3, AMP[:, None] * np.ones((1, 3)), FREQ, scene_interval_s=SCENE)
    # trapezoid mean of the 1e-6 rad signal vanishes to discretisation error
    mean = np.trapezoid(j, t, axis=0) / (SCENE[1] - SCENE[0])
    assert np.all(np.abs(mean) < 1e-12)


def test_tiles_and_seeds() -> None:
    t = np.linspace(0, 9, 10_007)
    whole = jitter_profile(t, 1, AMP, FREQ, scene_interval_s=SCENE)
    parts = np.concatenate([jitter_profile(t[:77], 1, AMP, FREQ, scene_interval_s=SCENE),
                            jitter_profile(t[77:], 1, AMP, FREQ, scene_interval_s=SCENE)])
    assert whole.tobytes() == parts.tobytes()
    other = jitter_profile(t, 2, AMP, FREQ, scene_interval_s=SCENE)
    assert np.max(np.abs(other - whole)) > 1e-7
    # roll, pitch and yaw get their own phases
    assert abs(np.corrcoef(whole[:, 0], whole[:, 2])[0, 1]) < 0.9
    assert jitter_profile(2.0, 1, AMP, FREQ).shape == (3,)


def test_input_checks() -> None:
    with pytest.raises(InputError, match="frequencies_hz"):
        jitter_profile(np.zeros(3), 1, AMP, [0.0])
    with pytest.raises(InputError, match="amplitudes_rad"):
        jitter_profile(np.zeros(3), 1, np.zeros(2), FREQ)
    with pytest.raises(InputError, match="scene_interval_s"):
        jitter_profile(np.zeros(3), 1, AMP, FREQ, scene_interval_s=(1.0, 1.0))
