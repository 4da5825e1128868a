"""Variance components and predicted accuracies against Monte-Carlo truth: noise of known sigma
per group, unequal between groups, a-priori sigmas wrong; the estimated components recover the
true ones within their sampling error and the predicted spread of derived quantities matches
the spread the draws show."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import sparse

from core.errors import InputError
from core.orientation.absolute import AbsoluteConfig, absolute_orientation
from core.orientation.observations import Observations
from core.orientation.uncertainty import (
    PredictedAccuracy,
    components_differ,
    ground_jacobian,
    neighbour_covariance,
    predicted_rms_px,
    solve_with_components,
)
from tests.core.orientation.test_absolute import check, models

TRUE_SIGMA = (0.5, 2.0)  # per group
N_PER_GROUP = 20
U = 6


def design(seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    n = 2 * N_PER_GROUP
    a = np.column_stack([np.ones(n), rng.uniform(-1, 1, (n, U - 1))])
    return a, np.repeat([0, 1], N_PER_GROUP)


def test_components_recover_the_true_sigmas_and_predict_the_spread():
    """400 draws of a 6-parameter problem, 20 observations per group with sigmas 0.5 and 2
    while the a-priori sigmas say 1 for both. Each group keeps about 17 of the 34 redundancies,
    so one estimate of a factor scatters by sqrt(2/17) = 34 %: the mean over the draws is
    within 5 % of the truth (its sampling sigma 1.7 %), and with ``n_g`` in place of ``r_g``
    it would be 18 % off. The parameters' covariance predicts the spread of a derived quantity
    ``y = c' x`` (and of the fitted value at points outside the data) within 10 %, where the
    equal a-priori weights scaled by one sigma0 state twice that spread."""
    a, g = design()
    x_true = np.arange(1.0, U + 1.0)
    c = np.array([1.0, 2.0, -1.0, 0.5, 0.0, 3.0])
    rng = np.random.default_rng(1)
    factors, red, err, var, naive = [], [], [], [], []
    sig = np.array(TRUE_SIGMA)[g]
    for _ in range(400):
        y = a @ x_true + rng.normal(0.0, sig)
        sol = solve_with_components(a, y, np.ones(len(y)), g, ("a", "b"))
        assert sol.components.converged
        factors.append(sol.components.factors)
        red.append(sol.components.redundancy)
        err.append(c @ sol.dx - c @ x_true)
        var.append(c @ sol.covariance @ c)
        # the old way: equal a-priori weights, covariance scaled by sigma0^2
        n_inv = np.linalg.inv(a.T @ a)
        v = y - a @ (n_inv @ a.T @ y)
        naive.append(c @ n_inv @ c * (v @ v) / (len(y) - U))
    factors, red = np.array(factors), np.array(red)
    truth = np.array(TRUE_SIGMA) ** 2
    assert np.allclose(red.sum(axis=1), 2 * N_PER_GROUP - U)
    assert np.all(np.abs(factors.mean(axis=0) / truth - 1.0) < 0.05), factors.mean(axis=0)
    # each estimate scatters as its redundancy says (chi-square): within 20 %
    spread = factors.std(axis=0) / truth
    expected = np.sqrt(2.0 / red.mean(axis=0))
    assert np.all(np.abs(spread / expected - 1.0) < 0.2), (spread, expected)
    measured = float(np.std(err))
    assert measured / np.sqrt(np.mean(var)) == pytest.approx(1.0, abs=0.1)
    # equal weights and one sigma0 state twice the spread the calibrated weights achieve
    assert measured / np.sqrt(np.mean(naive)) < 0.6


def test_alike_groups_are_not_split():
    a, g = design(3)
    rng = np.random.default_rng(2)
    split, factors = 0, []
    for _ in range(100):  # sigma 0.7 in both groups, 0.5 a priori: factors 1.96
        y = a @ np.ones(U) + rng.normal(0.0, 0.7, len(g))
        sol = solve_with_components(a, y, np.full(len(g), 0.25), g, ("a", "b"))
        split += components_differ(sol.components, 0, 1, alpha=0.01)
        factors.append(sol.components.factors)
    assert np.mean(factors, axis=0) == pytest.approx([1.96, 1.96], rel=0.1)
    assert split <= 4  # 1 % of false splits expected, 4 allowed
    y = a @ np.ones(U) + rng.normal(0.0, np.array(TRUE_SIGMA)[g])
    sol = solve_with_components(a, y, np.ones(len(g)), g, ("a", "b"))
    assert components_differ(sol.components, 0, 1)  # sigma 0.5 against 2: a factor of 16


def test_predicted_rms_adds_its_terms():
    jac = np.zeros((4, 2, 2))
    jac[:, 0, 0], jac[:, 1, 1] = 2.0, 1.0
    cov = np.diag([0.01, 0.04])
    assert predicted_rms_px(jac, cov) == pytest.approx((0.2, 0.2))
    ground = np.zeros((4, 2, 3))
    ground[:, 0, 0] = ground[:, 1, 1] = 0.1  # 10 m pixels
    p = PredictedAccuracy.at(jac, cov, ground, (3.0, 4.0, 5.0), (0.0, 0.0), noise_px=0.1)
    assert p.reference_rms_col_px == pytest.approx(0.3)
    assert p.reference_rms_row_px == pytest.approx(0.4)
    assert p.predicted_rms_col_px == pytest.approx(np.sqrt(0.04 + 0.09 + 0.01))
    assert p.predicted_rms_row_px == pytest.approx(np.sqrt(0.04 + 0.16 + 0.01))
    with pytest.raises(InputError):
        predicted_rms_px(jac, np.eye(3))


def test_neighbour_covariance_finds_a_smooth_error_and_not_noise():
    """A lens-like error 0.4 px RMS smooth across the image under 0.2 px of noise at 40 GCPs:
    found within 25 %; the noise alone gives nothing in at least 45 of 50 draws."""
    rng = np.random.default_rng(0)
    found, spurious = [], 0
    for _ in range(50):
        c, r = rng.uniform(0, 600, 40), rng.uniform(0, 600, 40)
        smooth = 0.4 * np.sqrt(2.0) * np.sin(2 * np.pi * c / 600.0)
        noise = rng.normal(0.0, 0.2, 40)
        found.append(neighbour_covariance(c, r, smooth - np.mean(smooth) + noise))
        spurious += neighbour_covariance(c, r, noise) > 0
    assert np.sqrt(np.mean(found)) == pytest.approx(0.4, rel=0.25)
    assert spurious <= 5


def test_ground_jacobian_is_the_models_pixel_size():
    left, _ = models()
    lon, lat = left.localize(np.array([1500.0]), np.array([1500.0]), np.array([800.0]))
    g = ground_jacobian(left, lon, lat, np.array([800.0]))
    # 10 m pixels: a metre is a tenth of a pixel along the image's axes
    assert np.hypot(g[0, 0, 0], g[0, 0, 1]) == pytest.approx(0.1, rel=0.15)
    assert np.hypot(g[0, 1, 0], g[0, 1, 1]) == pytest.approx(0.1, rel=0.15)
    assert abs(g[0, 0, 2]) == pytest.approx(np.tan(np.radians(25.5)) / 10.0, rel=0.2)


def test_absolute_orientation_calibrates_its_gcp_sigmas_and_predicts_its_check_points():
    """The synthetic pushbroom pair, GCPs with exact ground and matching noise 0.5 px in
    columns, 0.15 px in rows, against an a-priori 0.3 px for both. The components find the
    two sigmas (within 15 %, redundancy about 70 each) and split them; the check points'
    RMS (exact check points, reference error 0) pooled over 10 draws is the predicted within
    15 %."""
    delivered = models()
    truth = (delivered[0].with_params([1.2e-4, -0.8e-4, 0.5e-4, 1e-6, -2e-6, 0.0]),
             delivered[1].with_params([-0.9e-4, 1.5e-4, -0.7e-4, -2e-6, 1e-6, 0.0]))
    n, sc, sr = 40, 0.5, 0.15
    measured, predicted, factors = [], [], []
    for seed in range(10):
        rng = np.random.default_rng(seed)
        lc, lr = rng.uniform(50, 2950, n), rng.uniform(50, 2950, n)
        h = 500.0 + 800.0 * rng.uniform(size=n)
        lon, lat = truth[0].localize(lc, lr, h)
        cols = [t.project(lon, lat, h)[0] + rng.normal(0, sc, n) for t in truth]
        rows = [t.project(lon, lat, h)[1] + rng.normal(0, sr, n) for t in truth]
        obs = Observations(lon, lat, h, np.stack(cols, 1), np.stack(rows, 1),
                           np.full(n, 0.01), np.full(n, 0.01))
        res = absolute_orientation(delivered, obs, ("left", "right"),
                                   AbsoluteConfig(matching_sigma_px=0.3))
        comps = res.components
        # the reference's frame is a group of its own, a prior (fixed factor 1)
        assert comps is not None and comps.names == ("gcp_col", "gcp_row", "frame"), comps
        assert comps.factor_of("frame") == 1.0
        factors.append(comps.factors * 0.3**2)
        stats = check(res.models, truth)
        g = np.random.default_rng(5)
        c0, r0 = g.uniform(0, 2999, 300), g.uniform(0, 2999, 300)
        hh = 400.0 + 1000.0 * g.uniform(size=300)
        lo, la = truth[0].localize(c0, r0, hh)
        for k, s in enumerate(stats):
            p = res.predict(k, lo, la, hh)  # exact check points: the part relative to the frame
            measured.append((s.rms_col_px**2, s.rms_row_px**2))
            predicted.append((p.predicted_relative_rms_col_px**2,
                              p.predicted_relative_rms_row_px**2))
    sig = np.sqrt(np.mean(factors, axis=0)[:2])
    assert sig == pytest.approx([sc, sr], rel=0.15)
    ratio = np.sqrt(np.mean(measured, axis=0) / np.mean(predicted, axis=0))
    assert ratio == pytest.approx([1.0, 1.0], abs=0.15), ratio


def test_a_blocks_sparse_normals_give_what_dense_ones_give(monkeypatch):
    """A block-like design (40 images of 6 parameters, each row on two images' parameters: 240
    columns, under 5 % non-zero) is solved on a CSR matrix; the same system forced dense (the
    threshold out of reach) gives the same corrections, residuals, covariance and components."""
    import core.orientation.uncertainty as unc

    rng = np.random.default_rng(3)
    n_img, p, n_rows = 40, 6, 4000
    a = np.zeros((n_rows, n_img * p))
    for i in range(n_rows):
        k = rng.integers(0, n_img - 1)
        for m in (k, k + 1):  # a tie between neighbours
            a[i, m * p:(m + 1) * p] = rng.normal(0.0, 1.0, p)
    a = np.vstack([a, np.eye(n_img * p)[:p]])  # the first image held by a prior
    g = np.r_[rng.integers(0, 2, n_rows), np.full(p, 2)]
    q = np.r_[np.where(g[:n_rows] == 0, 0.25, 4.0), np.ones(p)]
    y = a @ rng.normal(0.0, 1.0, a.shape[1]) + rng.normal(0.0, np.sqrt(q) * [0.7])
    assert sparse.issparse(unc.sparse_when_worth_it(a))
    got = solve_with_components(a, y, q, g, ("a", "b", "prior"), fixed=("prior",))
    monkeypatch.setattr(unc, "SPARSE_MIN_PARAMS", 10**9)
    assert not sparse.issparse(unc.sparse_when_worth_it(a))
    dense = solve_with_components(a, y, q, g, ("a", "b", "prior"), fixed=("prior",))
    np.testing.assert_allclose(got.dx, dense.dx, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(got.v, dense.v, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(got.covariance, dense.covariance, rtol=1e-8, atol=1e-14)
    np.testing.assert_allclose(got.components.factors, dense.components.factors, rtol=1e-9)
    # and the factors are the truth's: 0.7^2 of the stated variances in both groups
    np.testing.assert_allclose(got.components.factors[:2], 0.49, rtol=0.1)
