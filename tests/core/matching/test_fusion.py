"""The multi-view DSM's pieces on synthetic data with known truth: the pairs' heights fused per
cell (weighted and median), the count of views, the pairs' height differences, the ROI of the
first image in another, and the grid of given heights."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from core.errors import InputError
from core.matching.fusion import (
    DIFF_EDGES_M,
    FusionConfig,
    difference_histograms,
    fuse_heights,
    histogram_median,
    median_of_pairs,
    pair_heights,
    weighted_median,
)
from core.matching.grid import MASK_VALID, grid_dem
from core.matching.rectify import box_in_image
from core.robust import nmad
from core.sensors.pushbroom_synthetic import SyntheticSpec, synthetic_pushbroom

PAIRS = np.array([[0, 1], [0, 2], [1, 2]])
B_H = np.array([0.11, 0.12, 0.23])  # the Marseille triplet's


def three_pairs(shape=(200, 200), seed=0):
    """A surface and three pairs' heights of it: noise 0.15 m / (B/H) each (a matching error
    of 0.3 px at 0.5 m pixels), the narrow pairs missing here and there, one of them with
    blunders of 10-30 m on 2 % of its cells."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[: shape[0], : shape[1]]
    truth = (100.0 + 10.0 * np.sin(xx / 17.0) + 5.0 * np.cos(yy / 11.0)).astype(np.float32)
    z = np.stack([truth + rng.normal(0, 0.15 / bh, shape) for bh in B_H]).astype(np.float32)
    z[0, :, :20] = np.nan  # only pairs 0-2 and 1-2 there: three views all the same
    z[:2, :, -20:] = np.nan  # only pair 1-2: two views
    blunder = rng.random(shape) < 0.02
    z[1][blunder] += rng.choice([-1.0, 1.0], blunder.sum()) * rng.uniform(10, 30, blunder.sum())
    return truth, z, blunder


def test_the_three_fusions_with_independent_errors_and_blunders():
    """Independent errors: the weighted mean of the pairs near the weighted median beats the
    best pair and the median; the weighted median keeps the best pair's heights (its weight
    outweighs the others'), the others' where it has none; a pair's blunders are left out by
    both; the median of the three follows the noisier pairs."""
    truth, z, blunder = three_pairs()
    fused = {m: fuse_heights(z, B_H**2, PAIRS, FusionConfig(method=m))
             for m in ("weighted_median", "weighted_mean", "median")}
    inner = (slice(None), slice(20, -20))
    err = {m: nmad((f.z_m - truth)[inner]) for m, f in fused.items()}
    best = nmad((z[2] - truth)[inner])
    # noise 1.36, 1.25 and 0.65 m: measured 0.54 m for the weighted mean (the inverse-variance
    # optimum, 0.53), 0.67 m for the median, 0.65 m for the best pair alone
    assert err["weighted_mean"] < 0.85 * best and err["weighted_mean"] < 0.85 * err["median"]
    np.testing.assert_array_equal(fused["weighted_median"].z_m, z[2])
    gap = z.copy()
    gap[2, :10, 50:60] = np.nan  # where the best pair has none, the others'
    got = fuse_heights(gap, B_H**2, PAIRS).z_m[:10, 50:60]
    assert ((got == z[0, :10, 50:60]) | (got == z[1, :10, 50:60])).all()
    for m in ("weighted_median", "weighted_mean"):
        assert np.abs(fused[m].z_m - truth)[blunder].max() < 5.0  # blunders of 10-30 m out
    assert all(np.isfinite(f.z_m).all() for f in fused.values())
    weighted = fused["weighted_mean"]
    # views: three images where pairs 0-1 or 0-2 join 1-2, two where 1-2 is alone
    assert (weighted.views[:, 20:-20][~blunder[:, 20:-20]] == 3).all()
    assert (weighted.views[:, -20:] == 2).all()
    # there only 0-2 and 1-2: one left out by chance (3 sigma) leaves two images
    assert (weighted.views[:, :20][~blunder[:, :20]] == 3).mean() > 0.99
    # a blunder of 0-2 left out: 0-1 and 1-2 still see three images, 1-2 alone two
    assert (weighted.views[blunder & np.isfinite(z[0])] == 3).mean() > 0.99
    assert (weighted.views[:, :20][blunder[:, :20]] == 2).mean() > 0.99
    np.testing.assert_array_equal(fused["weighted_median"].views, weighted.views)
    assert (fused["median"].views[:, 20:-20] == 3).all()


def test_weighted_median_and_median_against_sorting():
    rng = np.random.default_rng(1)
    z = rng.normal(0, 1, (4, 30)).astype(np.float32)
    z[rng.random(z.shape) < 0.3] = np.nan
    z[:, 0] = np.nan
    w = np.array([1.0, 2.0, 0.5, 3.0])
    got = weighted_median(z, w)
    for k in range(z.shape[1]):
        ok = np.isfinite(z[:, k])
        if not ok.any():
            assert np.isnan(got[k])
            continue
        order = np.argsort(z[ok, k])
        vals, ws = z[ok, k][order], w[ok][order]
        want = vals[np.searchsorted(np.cumsum(ws), 0.5 * ws.sum())]
        assert got[k] == want
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # numpy's all-NaN slice
        want = np.nanmedian(z, axis=0)
    np.testing.assert_array_equal(median_of_pairs(z), want.astype(np.float32))


def test_pair_heights_and_their_differences():
    """Each pair's median per cell (points of two pairs in one grid); the histogram median of
    two pairs' differences against numpy's median, to the 5 mm of a bin."""
    rng = np.random.default_rng(2)
    x, y = rng.uniform(0, 10, 4000), rng.uniform(-10, 0, 4000)
    pair = rng.integers(0, 2, 4000)
    h = 50.0 + np.where(pair == 1, 0.8, 0.0) + rng.normal(0, 0.3, 4000)
    zp = pair_heights(x, y, h, pair, 2, 0.0, 0.0, 1.0, (10, 10))
    cell = np.floor(-y).astype(int) * 10 + np.floor(x).astype(int)
    for k in (0, 1):
        sel = pair == k
        want = [np.median(h[sel][cell[sel] == c]) for c in range(100)]
        np.testing.assert_allclose(zp[k].ravel(), want, atol=1e-4)
    hist = difference_histograms(zp)
    assert hist.shape == (1, DIFF_EDGES_M.size - 1) and hist.sum() == 100
    d = (zp[0] - zp[1]).ravel()
    assert histogram_median(hist[0]) == pytest.approx(float(np.median(d)), abs=0.005)
    assert np.isnan(histogram_median(np.zeros(DIFF_EDGES_M.size - 1)))


def test_given_heights_are_gridded_with_the_mask_rules():
    """grid_dem with the cells' heights given (a fusion): those heights, the pairs' points
    still saying which cells are mismatched or outside, small holes filled."""
    x, y = np.meshgrid(np.arange(10) + 0.5, -(np.arange(10) + 0.5))
    x, y = x.ravel(), y.ravel()
    status = np.zeros(100, np.uint8)
    status[55] = 1  # mismatched
    h = np.where(status == 0, 10.0, np.nan)
    z = np.full((10, 10), 7.0, np.float32)
    z[5, 5] = np.nan
    cells = grid_dem(x, y, h, status, 0.0, 0.0, 1.0, (10, 10), max_hole_cells=5,
                     min_island_cells=0, z_m=z)
    assert cells.z_m[0, 0] == 7.0  # the given height, not the points' 10 m
    assert cells.z_m[5, 5] == pytest.approx(7.0) and cells.mask[5, 5] == MASK_VALID  # filled
    plain = grid_dem(x, y, h, status, 0.0, 0.0, 1.0, (10, 10), max_hole_cells=0,
                     min_island_cells=0)
    assert plain.z_m[0, 0] == 10.0 and np.isnan(plain.z_m[5, 5]) and plain.mask[5, 5] == 1


def test_the_roi_of_one_image_in_another():
    """The box of the second image that sees the first one's box at two heights: every
    edge point of the box at either height falls in it, and it is tight (within a pixel)."""
    def view(inc):
        return synthetic_pushbroom(SyntheticSpec(5.25, 44.2, 800.0, n_cols=600, n_rows=600,
                                                 gsd_m=40.0, incidence_deg=inc,
                                                 epoch_utc="2023-07-12T10:00:00Z"))
    a, b = view(25.0), view(-20.0)
    box = (100, 150, 300, 420)
    got = box_in_image(a, box, b, (600, 600), (200.0, 1500.0))
    cs, rs = [], []
    for h in (200.0, 850.0, 1500.0):
        c, r = np.meshgrid(np.arange(box[0], box[2]), np.arange(box[1], box[3]))
        lon, lat = a.localize(c.ravel().astype(float), r.ravel().astype(float), h)
        pc, pr = b.project(lon, lat, h)
        cs.append(pc)
        rs.append(pr)
    c, r = np.concatenate(cs), np.concatenate(rs)
    inside = (c >= 0) & (c <= 599) & (r >= 0) & (r <= 599)
    assert got is not None
    assert (c[inside] >= got[0] - 1e-6).all() and (c[inside] < got[2]).all()
    assert (r[inside] >= got[1] - 1e-6).all() and (r[inside] < got[3]).all()
    assert got[0] > c[inside].min() - 1.0 and got[2] < min(c[inside].max(), 599) + 2.0
    assert got[1] > r[inside].min() - 1.0 and got[3] < min(r[inside].max(), 599) + 2.0
    far = synthetic_pushbroom(SyntheticSpec(7.25, 44.2, 800.0, n_cols=600, n_rows=600,
                                            gsd_m=40.0, epoch_utc="2023-07-12T10:00:00Z"))
    assert box_in_image(a, box, far, (600, 600), (200.0, 1500.0)) is None


def test_bad_input():
    with pytest.raises(InputError, match="fusion method"):
        FusionConfig(method="mean")
    with pytest.raises(InputError, match="one of each per pair"):
        fuse_heights(np.zeros((2, 3, 3)), [1.0], PAIRS[:2])
    with pytest.raises(InputError, match="> 0"):
        fuse_heights(np.zeros((2, 3, 3)), [1.0, 0.0], PAIRS[:2])
