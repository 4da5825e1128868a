"""Tie points in the absolute orientation: their reduced equations against a bundle with the
ground unknowns in it, and self-calibration deciding on the tie points when the GCPs' noise
(a reference DEM's errors) hides the lens."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np

from core.orientation.absolute import AbsoluteConfig, absolute_orientation
from core.orientation.observations import Observations
from core.orientation.selfcal import LENS_TERMS, _with_terms, self_calibrate
from core.orientation.ties import TieObservations, refine_ground, tie_rows
from core.orientation.uncertainty import ground_jacobian
from core.sensors.linear_array import LensDistortion
from tests.core.orientation.test_absolute import M_LAT, M_LON, check, gcps, measured


def ties_of(truth, n=400, seed=3, n_px=3000, noise_px=0.1, start_m=20.0):
    """Tie points: true ground points measured in both images (+ matching noise), their
    starting ground ``start_m`` off (a relative orientation's intersection)."""
    rng = np.random.default_rng(seed)
    lon, lat, h, cols, rows = measured(truth, n, rng, n_px, noise_px)
    return TieObservations(np.stack(cols, 1), np.stack(rows, 1),
                           lon + rng.normal(0, start_m, n) / M_LON,
                           lat + rng.normal(0, start_m, n) / M_LAT, h + rng.normal(0, start_m, n))


def test_reduced_tie_equations_solve_as_the_bundle_with_ground_unknowns(pair):
    """One Gauss-Newton step of the parameters from the reduced equations (one per tie point)
    equals the step of the full bundle whose unknowns are the parameters and every tie point's
    ground position (solved directly by numpy's least squares), at the same linearisation."""
    delivered, truth = pair
    lens = [_with_terms(m, LENS_TERMS) for m in delivered]
    ties = ties_of(truth, n=25)
    offsets = np.concatenate([[0], np.cumsum([len(m.params) for m in lens])])
    g, _ = refine_ground(lens, ties, ties.ground(), iterations=8)
    t = tie_rows(lens, ties, g, offsets)
    assert t.a.shape == (25, offsets[-1]) and np.all(t.point == np.arange(25))
    g = t.ground
    n, p = ties.n, int(offsets[-1])
    big = np.zeros((4 * n, p + 3 * n))
    r = np.zeros(4 * n)
    for m, model in enumerate(lens):
        c, rr = model.project(g[0], g[1], g[2])
        jac = model.jacobian(g[0], g[1], g[2])
        gj = ground_jacobian(model, g[0], g[1], g[2])
        for k in range(n):
            rows = slice(4 * k + 2 * m, 4 * k + 2 * m + 2)
            big[rows, offsets[m]:offsets[m + 1]] = jac[k]
            big[rows, p + 3 * k:p + 3 * k + 3] = gj[k]
            r[rows] = [ties.col[k, m] - c[k], ties.row[k, m] - rr[k]]
    big, r = big / ties.sigma_px, r / ties.sigma_px
    # the parameters' scale, and a weak constraint on each (tie points fix no datum)
    scale = np.sqrt(np.sum(big[:, :p] ** 2, axis=0))
    ridge = np.zeros((p, p + 3 * n))
    ridge[np.arange(p), np.arange(p)] = 1e-3 * scale
    full = np.linalg.lstsq(np.vstack([big, ridge]), np.concatenate([r, np.zeros(p)]),
                           rcond=None)[0][:p]
    reduced = np.linalg.lstsq(np.vstack([t.a, ridge[:, :p]]),
                              np.concatenate([t.r, np.zeros(p)]), rcond=None)[0]
    effect_full, effect_reduced = big[:, :p] @ full, big[:, :p] @ reduced
    # the same step: measured 1e-4 px apart on steps of up to 80 px (the ground design and the
    # residuals are taken 1 cm apart, the intersections' tolerance)
    assert np.max(np.abs(effect_full - effect_reduced)) < 1e-3
    assert np.max(np.abs(effect_full)) > 10.0  # a real step, not two zeros


def test_tie_points_keep_the_lens_the_gcps_noise_hides(pair):
    """Both cameras bow (0.6-0.8 px at the line ends) and distort radially (0.8 px). GCPs with
    8 m of ground error under a-priori sigmas of 1 m (a reference DEM worse than it says):
    without tie points the left camera's terms fail both the Wald test and the column-drop gate
    (measured: Wald 8.9 against 16.3, column drop 0 %); with 400 tie points the parallax they
    carry (0.25 -> 0.11 px with the terms) keeps both cameras' terms, and the check points'
    rows come 30-40 % closer. On the same pair without distortion, nothing is kept."""
    delivered, truth = pair
    r_edge = float(np.hypot(*delivered[0].camera.detector_xy(np.array([0.0])))[0])
    px = r_edge / 1499.5
    lens = (LensDistortion(k3=0.8 * px / r_edge**3, p1=0.8 * px / r_edge**2),
            LensDistortion(k3=-0.8 * px / r_edge**3, p1=-0.6 * px / r_edge**2))
    distorted = tuple(replace(t, distortion=d) for t, d in zip(truth, lens, strict=True))
    obs, _ = gcps(distorted, n=80, sxy=8.0, sh=8.0, seed=7)
    obs = replace(obs, sigma_xy_m=np.full(80, 1.0), sigma_h_m=np.full(80, 1.0))
    names = ("left", "right")
    alone = self_calibrate(delivered, obs, names)
    assert "left" not in alone.significant
    ties = ties_of(distorted)
    joint = self_calibrate(delivered, obs, names, ties=ties)
    assert set(joint.significant) == {"left", "right"}
    assert joint.ties["evidence"] and joint.ties["drop"] > 0.4
    before = check(alone.result.models, distorted)
    after = check(joint.result.models, distorted)
    assert after[0].rms_row_px < 0.75 * before[0].rms_row_px
    assert after[1].rms_row_px < 0.9 * before[1].rms_row_px
    json.dumps(joint.to_dict())
    clean_obs, _ = gcps(truth, n=80, sxy=8.0, sh=8.0, seed=7)
    clean_obs = replace(clean_obs, sigma_xy_m=np.full(80, 1.0), sigma_h_m=np.full(80, 1.0))
    clean = self_calibrate(delivered, clean_obs, names, ties=ties_of(truth))
    assert not clean.applied and not clean.ties["evidence"]


def test_a_term_the_gcps_cannot_see_stays_held_by_its_prior(pair):
    """GCPs in a strip of 200 columns about the centre of a 3000-column line: the cubic radial
    term (k3 r^3) moves them by a ten-thousandth of what it does at the line ends, so they do
    not determine it. Without its prior the adjustment lets it reach 150-210 px at the line
    ends (measured, seeds 4 and 5) under a sigma of 400 px; with the prior (the lens terms'
    effect beyond the attitude's 2 px RMS over the image) it stays within 1.4 px there, under
    a sigma of 4 px (the prior's, at the line ends)."""
    delivered, truth = pair
    rng = np.random.default_rng(4)
    n = 60
    lc, lr = rng.uniform(1400, 1600, n), rng.uniform(50, 2950, n)
    h = 500.0 + 800.0 * rng.uniform(size=n)
    lon, lat = truth[0].localize(lc, lr, h)
    cols, rows = zip(*(m.project(lon, lat, h) for m in truth), strict=True)
    obs = Observations(lon, lat, h, np.stack(cols, 1) + rng.normal(0, 0.2, (n, 2)),
                       np.stack(rows, 1) + rng.normal(0, 0.2, (n, 2)), np.full(n, 1.0),
                       np.full(n, 1.0))
    lens = [_with_terms(m, LENS_TERMS) for m in delivered]
    ends_h = np.array([900.0, 900.0])

    def k3_at_line_ends(res):
        m = res.models[0]
        j = m.param_names.index("k3")
        lon_e, lat_e = m.localize(np.array([0.0, 2999.0]), np.array([1500.0, 1500.0]), ends_h)
        effect = float(np.max(np.abs(m.jacobian(lon_e, lat_e, ends_h)[:, :, j])))
        return m.params[j] * effect, res.sigmas()[0][j] * effect

    held = absolute_orientation(lens, obs, ("left", "right"), AbsoluteConfig())
    free = absolute_orientation(lens, obs, ("left", "right"), AbsoluteConfig(prior_terms=()))
    assert held.converged
    value, sigma = k3_at_line_ends(held)
    assert abs(value) < 4.0 and 2.0 < sigma < 6.0, (value, sigma)
    value, sigma = k3_at_line_ends(free)
    assert abs(value) > 20.0 and sigma > 100.0, (value, sigma)


def test_tie_points_seen_in_some_images_give_the_equations_of_those_images(pair):
    """A block: three images, tie points seen in two of them (NaN in the third, where a
    projection need not even exist) or in all three. The equations of a point seen in two
    images are the pair's own (the third image's parameters untouched); a point seen in all
    three has 2 x 3 - 3 = 3."""
    delivered, truth = pair
    third = truth[1].with_params(truth[1].params * 0.5)  # a third view of the same ground
    models = (*delivered, delivered[1].with_params(delivered[1].params * 0.5))
    offsets = np.concatenate([[0], np.cumsum([len(m.params) for m in models])])
    rng = np.random.default_rng(5)
    lon, lat, h, cols, rows = measured((*truth, third), 30, rng, 3000, 0.1)
    col, row = np.stack(cols, 1), np.stack(rows, 1)
    col[:20, 2] = row[:20, 2] = np.nan  # 20 points seen by images 0 and 1 only
    ties = TieObservations(col, row, lon, lat, h)
    assert ties.n == 30 and not ties.complete and ties.n_equations == 20 * 1 + 10 * 3
    t = tie_rows(models, ties, ties.ground(), offsets)
    assert t.a.shape == (50, offsets[-1])
    two = TieObservations(col[:20, :2], row[:20, :2], lon[:20], lat[:20], h[:20])
    pair_rows = tie_rows(models[:2], two, two.ground(), offsets[:3])
    mine = np.isin(t.point, np.arange(20))
    assert np.allclose(t.a[mine][:, :offsets[2]], pair_rows.a, atol=1e-9)
    assert np.all(t.a[mine][:, offsets[2]:] == 0.0)
    assert np.allclose(t.r[mine], pair_rows.r, atol=1e-9)
    assert np.bincount(t.point).tolist() == [1] * 20 + [3] * 10
