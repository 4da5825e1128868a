"""The attitude's along-track profile estimated from GCPs and tie points: a smooth pitch and
roll wave the biases and rates cannot follow is found (harmonics chosen by BIC) and the check
points' rows come back; a straight attitude gets no harmonics."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np

from core.orientation.along_track import estimate_along_track
from core.orientation.selfcal import _with_terms
from tests.core.orientation.test_absolute import check, gcps
from tests.core.orientation.test_ties import ties_of


def wavy(model, pitch_rad, roll_rad, freq_hz, phase):
    """The model whose attitude also waves: sinusoids of pitch and roll over the scene (the
    low-frequency departures SPOT 1-4 DIMAP angular speeds show: 4-12 microradians)."""
    jitter = ((1, pitch_rad, freq_hz, phase), (0, roll_rad, 1.3 * freq_hz, phase + 1.0))
    return replace(model, attitude=replace(model.attitude, jitter=jitter))


def test_an_attitude_wave_is_found_and_the_rows_come_back(pair):
    """Pitch waves of 8 and 6 microradians (0.8 and 0.6 px) at 0.35 Hz (1.6 cycles over the
    4.5 s scene), roll at 0.45 Hz: without harmonics the check points' rows keep 0.4-0.5 px;
    with the harmonics BIC chooses they fall under half of that."""
    delivered, truth = pair
    true = (wavy(truth[0], 8e-6, 3e-6, 0.35, 0.3), wavy(truth[1], 6e-6, 2e-6, 0.35, 2.0))
    obs, _ = gcps(true, n=150, sxy=2.0, sh=2.0, seed=3)
    ties = ties_of(true, n=300)
    at = estimate_along_track(delivered, obs, ("left", "right"), ties=ties)
    assert at.chosen > 0, at.bic
    before = check(at.results[0].models, true)
    after = check(at.result.models, true)
    for b, a in zip(before, after, strict=True):
        assert b.rms_row_px > 0.25, b
        assert a.rms_row_px < 0.5 * b.rms_row_px, (b, a)
    d = at.to_dict()
    json.dumps(d)
    assert set(d["row_profile_with"]) == {"left", "right"}
    assert len(d["row_profile_with"]["left"]["mean_row_residual_px"]) == 10


def test_a_straight_attitude_gets_no_harmonics(pair):
    delivered, truth = pair
    obs, _ = gcps(truth, n=150, sxy=2.0, sh=2.0, seed=3)
    at = estimate_along_track(delivered, obs, ("left", "right"), ties=ties_of(truth, n=300))
    assert at.chosen == 0, at.bic


def test_crops_keep_the_harmonics_time_span(pair):
    """A crop of a model with harmonics projects as the whole model does (the harmonics' time
    span is the model's, not the crop's)."""
    delivered, _ = pair
    m = _with_terms(delivered[0], ("pitch_h2", "roll_h5"))
    m = m.with_params(np.concatenate([m.params[:-2], [3e-6, -2e-6]]))
    crop = m.with_image_window(300.0, 700.0, 2000, 1500)
    lon, lat = m.localize(np.array([500.0, 1800.0]), np.array([900.0, 2000.0]),
                          np.array([800.0, 900.0]))
    c, r = m.project(lon, lat, np.array([800.0, 900.0]))
    cc, rr = crop.project(lon, lat, np.array([800.0, 900.0]))
    assert np.allclose(cc + 300.0, c, atol=1e-6) and np.allclose(rr + 700.0, r, atol=1e-6)
