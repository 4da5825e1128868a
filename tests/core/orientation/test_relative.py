"""Relative orientation on synthetic pairs with known truth: both sensor families, outliers,
observability, and the along-epipolar part set from a reference DEM."""

from __future__ import annotations

import json

import numpy as np
import pytest

from core.errors import InputError, InsufficientDataError
from core.orientation.relative import (
    RelativeConfig,
    epipolar_fit,
    fix_along_epipolar,
    image_correction,
    relative_orientation,
)
from core.sensors.pushbroom_synthetic import SyntheticSpec, synthetic_pushbroom
from core.sensors.rpcfit import fit_rpc

N_PX, GSD = 600, 40.0
OFFSET = RelativeConfig(corrections="offset")


def pair(incidences=(25.5, -20.0), pitches=(0.0, 0.0)):
    left, right = (synthetic_pushbroom(SyntheticSpec(
        5.25, 44.2, 800.0, n_cols=N_PX, n_rows=N_PX, gsd_m=GSD, incidence_deg=inc, pitch_deg=p,
        epoch_utc="2023-07-12T10:00:00Z")) for inc, p in zip(incidences, pitches, strict=True))
    return left, right


def tie_points(left, right_truth, n=300, noise_px=0.1, seed=0):
    """Left pixels over a hilly surface, their true right pixels (+ noise), true heights."""
    rng = np.random.default_rng(seed)
    lc, lr = rng.uniform(5, N_PX - 6, n), rng.uniform(5, N_PX - 6, n)
    h = 800.0 + 600.0 * np.sin(lc / 90.0) * np.cos(lr / 70.0)
    lon, lat = left.localize(lc, lr, h)
    rc, rr = right_truth.project(lon, lat, h)
    return lc, lr, rc + rng.normal(0, noise_px, n), rr + rng.normal(0, noise_px, n), h


def epipolar_direction(left, right, lc, lr, h):
    """The right pixels (n, 2) of the left pixels' ground at heights h, and the unit tangent
    and normal (n, 2) of their epipolar curves there, from the left ray at h and h + 50 m:
    projections only, nothing of the code under test."""
    lon, lat = left.localize(lc, lr, h)
    c, r = right.project(lon, lat, h)
    lon2, lat2 = left.localize(lc, lr, h + 50.0)
    c2, r2 = right.project(lon2, lat2, h + 50.0)
    t = np.stack([c2 - c, r2 - r], axis=1)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    return np.stack([c, r], axis=1), t, np.stack([-t[:, 1], t[:, 0]], axis=1)


def moved_px(left, before, after, lc, lr, h):
    """How ``after`` moves the projections of the ground points seen at left pixels (lc, lr)
    at heights h from where ``before`` projects them, split across and along the epipolar
    curve of (left, before) there."""
    p0, t, nrm = epipolar_direction(left, before, lc, lr, h)
    lon, lat = left.localize(lc, lr, h)
    d = np.stack(after.project(lon, lat, h), axis=1) - p0
    return np.einsum("ni,ni->n", d, nrm), np.einsum("ni,ni->n", d, t)


def grid_points(h=900.0, n=9):
    c, r = np.meshgrid(np.linspace(0, N_PX - 1, n), np.linspace(0, N_PX - 1, n))
    return c.ravel(), r.ravel(), np.full(c.size, h)


@pytest.fixture(scope="module")
def across():
    left, right = pair()
    truth = right.with_params(np.array([3e-5, -4e-5, 2e-5, 0.0, 0.0, 0.0]))
    return left, right, truth, tie_points(left, truth)


def test_parallax_is_the_distance_across_the_epipolar_curve(across):
    """Independently of the fit: a right point moved along the curve has no parallax, moved
    across it has exactly that parallax."""
    left, right, _, _ = across
    lc, lr, h = np.array([100.0, 400.0]), np.array([250.0, 50.0]), np.array([700.0, 1500.0])
    p, t, nrm = epipolar_direction(left, right, lc, lr, h)
    moved = p + 0.7 * nrm + 3 * t
    fit = epipolar_fit(left, right, lc, lr, moved[:, 0], moved[:, 1], 1000.0)
    np.testing.assert_allclose(np.abs(fit.parallax_px), 0.7, atol=2e-3)
    np.testing.assert_allclose(fit.along_px, 0.0, atol=1e-6)


def test_pushbroom_biases_recovered_across_the_epipolar_lines(across):
    left, right, truth, (lc, lr, rc, rr, _) = across
    res = relative_orientation(left, right, lc, lr, rc, rr, 900.0, OFFSET)
    assert res.converged and res.rejected.size <= 3
    assert res.parallax_rms_before_px > 0.8
    assert res.parallax_rms_after_px < 0.12  # the matching noise, 0.1 px
    # the adjusted right model projects the ground where the truth does across the epipolar
    # curves (truth's own move across them: 1.3 px), and where the delivered one does along
    got_across, got_along = moved_px(left, right, res.right_model, *grid_points())
    want_across, _ = moved_px(left, right, truth, *grid_points())
    assert np.abs(want_across).min() > 0.9
    assert np.abs(got_across - want_across).max() < 0.02  # measured 0.012
    assert np.abs(got_along).max() < 0.01  # held: the tie points cannot see it
    # across track, the roll moves points along the epipolar lines: it is the one unobservable
    (u,) = res.unobservable
    assert abs(u.direction["roll_bias"]) > 0.9 and u.observable_share < 1e-6
    assert res.point_angle.name == "pitch_bias" and res.point_angle.unit == "arcsec"
    assert res.point_angle.mean == pytest.approx(res.params_after[1] * 206264.806, abs=0.5)
    from core.orientation.relative import relative_from_dict

    back = relative_from_dict(json.loads(json.dumps(res.to_dict())), res.right_model,
                              res.parallax_px, res.inlier)
    assert json.dumps(back.to_dict()) == json.dumps(res.to_dict())


def test_outliers_are_all_rejected_and_change_nothing(across):
    """10 % of the tie points moved by 5-20 px: all rejected, result unchanged within 0.05 px."""
    left, right, _, (lc, lr, rc, rr, _) = across
    clean = relative_orientation(left, right, lc, lr, rc, rr, 900.0, OFFSET)
    rng = np.random.default_rng(3)
    bad = rng.choice(lc.size, lc.size // 10, replace=False)
    ang = rng.uniform(0, 2 * np.pi, bad.size)
    mag = rng.uniform(5, 20, bad.size)
    rc2, rr2 = rc.copy(), rr.copy()
    rc2[bad] += mag * np.cos(ang)
    rr2[bad] += mag * np.sin(ang)
    dirty = relative_orientation(left, right, lc, lr, rc2, rr2, 900.0, OFFSET)
    fit = epipolar_fit(left, right, lc[bad], lr[bad], rc2[bad], rr2[bad], 900.0)
    visible = np.abs(fit.parallax_px) > 1.0  # a move along the epipolar line is a height
    assert set(bad[visible]) <= set(dirty.rejected.tolist())
    a = np.stack(moved_px(left, clean.right_model, dirty.right_model, *grid_points()))
    assert np.abs(a).max() < 0.05  # the two adjusted models project alike over the image


def test_along_track_pair_cannot_see_pitch():
    left, right = pair((0.0, 0.0), (20.0, -20.0))
    truth = right.with_params(np.array([-2e-5, 3e-5, 1e-5, 0.0, 0.0, 0.0]))
    lc, lr, rc, rr, _ = tie_points(left, truth, seed=5)
    res = relative_orientation(left, right, lc, lr, rc, rr, 900.0, OFFSET)
    # pitch moves points along the epipolar lines (rows); fore/aft, roll and yaw both shift the
    # columns almost uniformly, so one combination of them barely moves the image at all
    span = np.array([[u.direction[n] for n in res.param_names] for u in res.unobservable])
    assert len(span) == 2
    pitch = np.array([0.0, 1.0, 0.0])
    assert np.linalg.norm(span @ pitch) > 0.99  # the pitch axis lies in the unobservable span
    assert res.parallax_rms_after_px < 0.12


def test_a_lens_the_models_miss_is_kept_where_blunders_are_not():
    """Along track, a lens the delivered right model lacks puts its cubic in the columns, across
    the epipolar lines: over 1 px of y-parallax at the swath's ends, which the neighbours share.
    Those points are kept (the parallax alone would have rejected them all: hrs seed 1 lost the
    outer 600-1000 columns on both sides that way), blunders among them still go."""
    from dataclasses import replace

    from core.sensors.linear_array import LensDistortion

    left, right = pair((0.0, 0.0), (20.0, -20.0))
    truth = right.with_params(np.array([-2e-5, 3e-5, 1e-5, 0.0, 0.0, 0.0]))
    unit = replace(truth, distortion=LensDistortion(k3=1.0))
    lon, lat = truth.localize(np.array([0.0, 0.5 * N_PX]), np.array([0.0, 0.0]), 900.0)
    edge = abs(np.diff(unit.project(lon, lat, 900.0)[0] - truth.project(lon, lat, 900.0)[0]))
    truth = replace(truth, distortion=LensDistortion(k3=2.0 / float(edge[0])))  # 2 px at ends
    lc, lr, rc, rr, _ = tie_points(left, truth, n=600, seed=7)
    rng = np.random.default_rng(8)
    bad = rng.choice(lc.size, 30, replace=False)
    rc[bad] += rng.choice([-1.0, 1.0], bad.size) * rng.uniform(3.0, 10.0, bad.size)
    res = relative_orientation(left, right, lc, lr, rc, rr, 900.0)
    ends = np.setdiff1d(np.flatnonzero((lc < 0.1 * N_PX) | (lc > 0.9 * N_PX)), bad)
    sigma = 1.4826 * np.median(np.abs(res.parallax_px[res.inlier]))
    assert np.mean(np.abs(res.parallax_px[ends]) > res.sigma_px * 3.0) > 0.5  # the old test
    assert res.inlier[ends].mean() > 0.95
    assert not res.inlier[bad].any()
    assert sigma < 0.5


@pytest.mark.parametrize("corrections", ["offset", "linear"])
def test_rpc_bias_compensation(across, corrections):
    """RPCs fitted to the synthetic models; the right one's truth carries a shift (offset) or
    an affine (linear): the across-epipolar part of the centre shift is recovered."""
    left, right, _, _ = across
    rpc_l, _ = fit_rpc(left, N_PX, N_PX, (0.0, 2500.0))
    rpc_r, _ = fit_rpc(right, N_PX, N_PX, (0.0, 2500.0))
    if corrections == "offset":
        truth = rpc_r.with_bias_mode("shift").with_params([3.0, -2.5])
    else:
        truth = rpc_r.with_bias_mode("affine").with_params([3.0, 0.8, -0.5, -2.5, 0.6, 0.4])
    lc, lr, rc, rr, _ = tie_points(rpc_l, truth, seed=9)
    res = relative_orientation(rpc_l, rpc_r, lc, lr, rc, rr, 900.0,
                               RelativeConfig(corrections=corrections))
    assert res.parallax_rms_after_px < 0.12 and res.point_angle.unit == "px"
    got, _ = moved_px(rpc_l, rpc_r, res.right_model, *grid_points())
    want, _ = moved_px(rpc_l, rpc_r, truth, *grid_points())
    # measured: 0.005 px at most (offset); the affine 0.02 px RMS, 0.04 at the corners, where
    # the tie points' affine is extrapolated
    assert np.abs(want).min() > 1.0
    assert np.sqrt(np.mean((got - want) ** 2)) < 0.03 and np.abs(got - want).max() < 0.06
    assert len(res.unobservable) == (1 if corrections == "offset" else 3)


def test_image_correction_of_a_known_image_shift(across):
    """An RPC moved by an image shift (and by an affine): image_correction states that shift,
    its affine, and its parts across and along the epipolar line at the centre (the
    direction taken from the left ray at two heights here)."""
    left, right, _, _ = across
    rpc_l, _ = fit_rpc(left, N_PX, N_PX, (0.0, 2500.0))
    rpc_r, _ = fit_rpc(right, N_PX, N_PX, (0.0, 2500.0))
    moved = rpc_r.with_bias_mode("shift").with_params([3.0, -2.5])
    lon, lat = rpc_r.localize(np.array([10.0, 590.0]), np.array([20.0, 400.0]), 900.0)
    dc, dr = (np.asarray(a) - np.asarray(b)
              for a, b in zip(moved.project(lon, lat, 900.0), rpc_r.project(lon, lat, 900.0),
                              strict=True))
    np.testing.assert_allclose(dc, dc[0], atol=1e-9)  # one shift everywhere
    got = image_correction(rpc_l, rpc_r, moved, N_PX, N_PX, 900.0)
    assert (got.col_shift_px, got.row_shift_px) == pytest.approx((dc[0], dr[0]), abs=1e-6)
    np.testing.assert_allclose(got.affine, [[0, 0, dc[0]], [0, 0, dr[0]]], atol=1e-6)
    assert got.affine_rms_px < 1e-6
    centre = 0.5 * (N_PX - 1)
    lon0, lat0 = rpc_r.localize(centre, centre, 900.0)
    lc, lr = rpc_l.project(lon0, lat0, 900.0)
    across, along = moved_px(rpc_l, rpc_r, moved, np.atleast_1d(lc), np.atleast_1d(lr),
                             np.array([900.0]))
    assert got.across_epipolar_px == pytest.approx(float(across[0]), abs=1e-3)
    assert got.along_epipolar_px == pytest.approx(float(along[0]), abs=1e-3)
    assert abs(got.across_epipolar_px) > 1.0 and abs(got.along_epipolar_px) > 1.0
    # an affine: the fitted affine is the one the model's own projections show
    affine = rpc_r.with_bias_mode("affine").with_params([3.0, 0.8, -0.5, -2.5, 0.6, 0.4])
    got = image_correction(rpc_l, rpc_r, affine, N_PX, N_PX, 900.0)
    c, r = np.meshgrid([0.0, N_PX - 1.0], [0.0, N_PX - 1.0])
    lon, lat = rpc_r.localize(c.ravel(), r.ravel(), 900.0)
    c2, r2 = affine.project(lon, lat, 900.0)
    a = np.array(got.affine)
    np.testing.assert_allclose(a[0, 0] * c.ravel() + a[0, 1] * r.ravel() + a[0, 2],
                               c2 - c.ravel(), atol=1e-3)
    np.testing.assert_allclose(a[1, 0] * c.ravel() + a[1, 1] * r.ravel() + a[1, 2],
                               r2 - r.ravel(), atol=1e-3)


def test_reference_heights_set_the_along_epipolar_part(across):
    left, right, truth, (lc, lr, rc, rr, h) = across
    res = relative_orientation(left, right, lc, lr, rc, rr, 900.0, OFFSET)
    rng = np.random.default_rng(2)
    fixed, along = fix_along_epipolar(left, res, lc, lr, rc, rr, h + rng.normal(0, 3, h.size),
                                      N_PX, N_PX)
    assert along.observable and along.n_points > 250
    assert along.sigma_px == pytest.approx(5.0 * 0.84 / GSD, rel=0.3)  # 5 m at B/H 0.84
    # now the adjusted model projects the ground where the truth does, both ways (the
    # truth's move along the curves: 0.66 px at the centre)
    across, along_px = moved_px(left, truth, fixed, *grid_points())
    _, want_along = moved_px(left, right, truth, *grid_points())
    assert np.abs(want_along).min() > 0.3
    assert np.abs(across).max() < 0.02 and np.abs(along_px).max() < 0.05
    assert along.shift_px == pytest.approx(float(np.median(want_along)), abs=0.05)
    # the tie points' heights now agree with the truth (0.1 px noise ~ 5 m at 40 m, B/H 0.84)
    fit = epipolar_fit(left, fixed, lc, lr, rc, rr, h)
    assert abs(np.median(fit.h_m - h)) < 1.0


def test_bad_input(across):
    left, right, _, (lc, lr, rc, rr, _) = across
    with pytest.raises(InsufficientDataError, match="5 tie points"):
        relative_orientation(left, right, lc[:5], lr[:5], rc[:5], rr[:5], 900.0, OFFSET)
    with pytest.raises(InputError, match="differ in length"):
        relative_orientation(left, right, lc, lr[:-1], rc, rr, 900.0)
    with pytest.raises(InputError, match="corrections"):
        RelativeConfig(corrections="quadratic")
