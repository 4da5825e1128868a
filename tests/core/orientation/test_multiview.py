"""Joint relative orientation of N images on a synthetic along-track triplet with known truth:
the pairs' heights agree after it (they do not pair by pair), the source ray's Jacobian, the
tracks chained from pairs, and the common height set from a reference."""

from __future__ import annotations

import numpy as np
import pytest

from core.errors import InputError
from core.intersection import triangulate
from core.orientation.multiview import (
    RelativeConfig,
    fix_along_joint,
    joint_relative_orientation,
)
from core.orientation.relative import relative_orientation
from core.orientation.tracks import (
    PairTies,
    Tracks,
    equations_of,
    fit_group,
    motion,
    track_groups,
    tracks_from_pairs,
)
from core.sensors.pushbroom_synthetic import SyntheticSpec, synthetic_pushbroom

N_PX, GSD = 600, 40.0
OFFSET = RelativeConfig(corrections="offset")
PAIRS = ((0, 1), (0, 2), (1, 2))


def view(pitch_deg: float):
    return synthetic_pushbroom(SyntheticSpec(
        5.25, 44.2, 800.0, n_cols=N_PX, n_rows=N_PX, gsd_m=GSD, incidence_deg=0.0,
        pitch_deg=pitch_deg, epoch_utc="2023-07-12T10:00:00Z")).with_corrections("offset")


@pytest.fixture(scope="module")
def triplet():
    """Nadir, forward and backward views of one pass (B/H 0.21 and 0.43), the two others'
    attitudes off by 10-40 urad (pitch moves them along track: 100-150 m of height), and
    ground points over a hilly surface."""
    delivered = [view(0.0), view(12.0), view(-12.0)]
    truth = [delivered[0], delivered[1].with_params([2e-5, 3e-5, 1e-5]),
             delivered[2].with_params([-1e-5, -4e-5, 2e-5])]
    rng = np.random.default_rng(0)

    def ground(n):
        lc, lr = rng.uniform(30, N_PX - 30, n), rng.uniform(60, N_PX - 60, n)
        h = 800.0 + 600.0 * np.sin(lc / 90.0) * np.cos(lr / 70.0)
        return (*truth[0].localize(lc, lr, h), h)

    def pixels(m, g, noise=0.05):
        c, r = m.project(*g)
        return c + rng.normal(0, noise, c.size), r + rng.normal(0, noise, c.size)

    g = ground(300)
    fixed = truth[0].project(*g)  # the fixed image's interest points: shared by two pairs
    o1, o2 = pixels(truth[1], g), pixels(truth[2], g)
    pairs = [PairTies(0, 1, fixed[0][:200], fixed[1][:200], o1[0][:200], o1[1][:200], 900.0),
             PairTies(0, 2, fixed[0][100:], fixed[1][100:], o2[0][100:], o2[1][100:], 900.0)]
    g12 = ground(150)
    pairs.append(PairTies(1, 2, *pixels(truth[1], g12), *pixels(truth[2], g12), 900.0))
    return delivered, truth, g, pairs


def pair_heights_m(models, truth, g):
    """The median height error (m) of each pair's intersection of the true ground's pixels
    through ``models`` (core.intersection: the rays' closest approach)."""
    out = {}
    for i, j in PAIRS:
        (ci, ri), (cj, rj) = truth[i].project(*g), truth[j].project(*g)
        t = triangulate([models[i], models[j]], [ci, cj], [ri, rj], (-500.0, 3000.0))
        out[(i, j)] = float(np.median(t.h_m - g[2]))
    return out


def spread(heights):
    return max(heights.values()) - min(heights.values())


def test_the_pairs_agree_after_the_joint_orientation(triplet):
    """Pair by pair, each pair's along-track error stays (no y-parallax shows it): the pairs'
    heights 36 m apart. Jointly, the 100 points the three views see tie them: within 2.5 m
    (the 0.05 px matching noise over 100 points is 1-2 m at these B/H and 40 m pixels)."""
    delivered, truth, g, pairs = triplet
    tracks, which = tracks_from_pairs(3, pairs)
    assert tracks.n == 450 and int((tracks.seen.sum(axis=1) == 3).sum()) == 100
    assert [np.unique(w).size for w in which] == [200, 200, 150]
    res = joint_relative_orientation(delivered, tracks, OFFSET)
    assert res.converged and res.rejected.size <= 5 and res.fixed == 0  # 3 of 450 at 3 sigma
    assert res.models[0] is delivered[0]  # the fixed image is not touched
    assert res.rms_before_px > 0.3 and res.rms_after_px < 0.08
    for p in res.pairs:
        assert p.parallax_rms_before_px > 0.12 and p.parallax_rms_after_px < 0.08, p
    before = pair_heights_m(delivered, truth, g)
    pairwise = [delivered[0]] + [relative_orientation(
        delivered[0], delivered[j], p.col_i, p.row_i, p.col_j, p.row_j, 900.0,
        OFFSET).right_model for j, p in ((1, pairs[0]), (2, pairs[1]))]
    assert spread(before) > 30.0 and spread(pair_heights_m(pairwise, truth, g)) > 30.0
    joint = pair_heights_m(res.models, truth, g)
    assert spread(joint) < 2.5, joint
    # what stays unseen: their common height (here -127 m: the metadata's), and per image a
    # roll-yaw combination that hardly moves it
    assert len(res.unobservable) == 2
    assert all(-140.0 < v < -110.0 for v in joint.values())


def test_without_points_seen_three_times_the_pairs_stay_apart(triplet):
    """The same pairs with no pixel shared: each image's pitch is unobservable (it moves
    every pair it is in along its epipolar lines), so are both roll-yaw combinations: four
    directions where the triplet's tracks left two; the pairs' heights stay apart."""
    delivered, truth, g, pairs = triplet
    apart = [PairTies(p.i, p.j, p.col_i + (0.25 if p.j == 2 else 0.0), p.row_i, p.col_j,
                      p.row_j, 900.0) for p in pairs]
    tracks, _ = tracks_from_pairs(3, apart)
    assert int((tracks.seen.sum(axis=1) == 3).sum()) == 0
    res = joint_relative_orientation(delivered, tracks, OFFSET)
    assert len(res.unobservable) == 4
    assert spread(pair_heights_m(res.models, truth, g)) > 30.0


def test_equations_jacobian_against_numeric(triplet):
    """d(equations)/dp of a group whose source is adjusted (images 1 -> 2) and of one the
    three views see, against central differences of the equations themselves (the heights
    solved again each time)."""
    delivered, _, _, pairs = triplet
    tracks, _ = tracks_from_pairs(3, pairs)
    models = [delivered[0]] + [m.with_params([1e-5, -2e-5, 1e-5]) for m in delivered[1:]]
    offsets, n_p = {1: (0, 3), 2: (3, 6)}, 6
    groups = {(g.source, g.targets): g for g in track_groups(tracks, 0)}
    p0 = np.concatenate([m.params for m in models[1:]])
    for key in ((1, (2,)), (0, (1, 2))):
        g = groups[key]
        fit = fit_group(models, g, tracks.col, tracks.row, tracks.h0_m[g.idx])
        a = equations_of(fit, motion(models, g, fit, offsets, n_p))
        num = np.empty_like(a)
        for k in range(n_p):
            step = np.zeros(n_p)
            step[k] = 2e-7
            y = []
            for sign in (1.0, -1.0):
                p = p0 + sign * step
                ms = [models[0], models[1].with_params(p[:3]), models[2].with_params(p[3:])]
                y.append(fit_group(ms, g, tracks.col, tracks.row, fit.h_m).y)
            num[:, :, k] = (y[0] - y[1]) / 4e-7
        scale = np.abs(num).max(axis=(0, 1))
        np.testing.assert_allclose(a / scale, num / scale, atol=2e-3)
        assert np.abs(num[:, :, :3]).max() > 1e4 and np.abs(num[:, :, 3:]).max() > 1e4


def test_tracks_are_chained_through_shared_pixels():
    """Two pairs sharing a pixel of image 0 make one track seen three times; a chain that
    would give image 1 two pixels is split back into its pairs' points; each pair's points
    know their track."""
    p01 = PairTies(0, 1, [10.0, 20.0], [5.0, 6.0], [11.0, 21.0], [5.5, 6.5], [100.0, np.nan])
    p02 = PairTies(0, 2, [10.0, 30.0], [5.0, 7.0], [12.0, 32.0], [4.0, 8.0], [110.0, 120.0])
    p12 = PairTies(1, 2, [21.0], [6.5], [40.0], [9.0], np.nan)
    p21 = PairTies(2, 1, [40.0], [9.0], [22.0], [6.5], np.nan)  # image 1 again, elsewhere
    tracks, which = tracks_from_pairs(3, [p01, p02], h_default_m=50.0)
    assert tracks.n == 3
    t = which[0][0]
    assert which[1][0] == t and np.isfinite(tracks.col[t]).all()
    np.testing.assert_array_equal(tracks.col[t], [10.0, 11.0, 12.0])
    assert tracks.h0_m[t] == pytest.approx(105.0)  # the pairs' heights averaged
    assert tracks.h0_m[which[0][1]] == 50.0  # none known: the default
    tracks, which = tracks_from_pairs(3, [p01, p12, p21])
    # 21.0 -> 40.0 -> 22.0: image 1 twice, so these three observations stay apart
    assert tracks.n == 4 and len({which[0][1], which[1][0], which[2][0]}) == 3
    assert (tracks.seen.sum(axis=1) == 2).all()
    with pytest.raises(InputError, match="two different images"):
        PairTies(1, 1, [0.0], [0.0], [0.0], [0.0], 0.0)
    with pytest.raises(InputError, match="fewer than two"):
        Tracks(np.array([[1.0, np.nan]]), np.array([[1.0, np.nan]]), 0.0)


def test_a_reference_sets_the_common_height(triplet):
    """With reference heights under the tie points (truth + 3 m noise), the common height the
    tie points cannot see is set: every pair within 2.5 m of the truth."""
    delivered, truth, g, pairs = triplet
    tracks, _ = tracks_from_pairs(3, pairs)
    res = joint_relative_orientation(delivered, tracks, OFFSET)
    # the reference under each track: the true surface where its source ray meets it
    src = res.source
    col = tracks.col[np.arange(tracks.n), src]
    row = tracks.row[np.arange(tracks.n), src]
    href = np.empty(tracks.n)
    for s in (0, 1):
        sel = src == s
        h = np.full(sel.sum(), 900.0)
        for _ in range(20):  # the surface of the fixture, h(lc, lr) over the nadir image
            lon, lat = truth[s].localize(col[sel], row[sel], h)
            lc, lr = truth[0].project(lon, lat, h)
            h = 800.0 + 600.0 * np.sin(lc / 90.0) * np.cos(lr / 70.0)
        href[sel] = h
    href += np.random.default_rng(4).normal(0, 3.0, href.size)
    dirs = np.array([[u.step[n] for n in res.param_names] for u in res.unobservable]).T
    models, along = fix_along_joint(res.models, 0, tracks, res.inlier, dirs, href,
                                    [(N_PX, N_PX)] * 3)
    assert along.observable and along.n_points == res.inlier.sum() and along.shift_px[0] == 0.0
    assert along.height_offset_m == pytest.approx(-127.0, abs=3.0)
    heights = pair_heights_m(models, truth, g)
    assert all(abs(v) < 2.5 for v in heights.values()), heights
