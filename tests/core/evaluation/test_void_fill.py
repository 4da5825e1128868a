"""Delta-surface void filling on small grids with a known truth: the harmonic interpolation,
the fill and its counts, the ring statistics, the datum change, the settings refused."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from core.errors import InputError
from core.evaluation.void_fill import (
    FillConfig,
    delta_surface_fill,
    dsm_to_datum,
    harmonic_fill,
    nanmean_window,
)
from core.geoid import GeoidGrid
from core.heights import HeightFrame

N = 60
ROWS, COLS = np.mgrid[0:N, 0:N].astype(np.float64)
TRUTH = 400.0 + 30.0 * np.sin(ROWS / 7.0) + 2.0 * COLS  # metres


def disc(r0: float, c0: float, radius: float) -> np.ndarray:
    return (ROWS - r0) ** 2 + (COLS - c0) ** 2 <= radius ** 2


def test_a_plane_is_interpolated_exactly_and_parts_without_a_border_are_nan():
    plane = 3.0 + 0.5 * ROWS - 0.2 * COLS
    inner = np.zeros((N, N), dtype=bool)
    inner[10:40, 15:50] = True
    corner = np.zeros((N, N), dtype=bool)
    corner[0:5, 0:6] = True  # at the grid's corner: two sides off the grid (flat across them)
    island = disc(55.0, 30.0, 2.0)
    domain = inner | corner | island
    boundary = np.where(domain, np.nan, plane)
    boundary[50:, :] = np.nan  # around the island no fixed value
    h = harmonic_fill(boundary, domain)
    np.testing.assert_allclose(h[inner], plane[inner], atol=1e-9)
    fixed = np.isfinite(boundary) & ndimage.binary_dilation(corner) & ~corner
    assert plane[fixed].min() <= h[corner].min() and h[corner].max() <= plane[fixed].max()
    assert np.isnan(h[island]).all() and np.isnan(h[~domain]).all()
    with pytest.raises(InputError, match="same shape"):
        harmonic_fill(boundary[:10], domain)


def test_a_biased_dsm_fills_the_voids_exactly():
    """DSM = truth + 7 m (an unoriented DSM's datum error): the delta surface takes it out."""
    voids = disc(20.0, 20.0, 6.0) | disc(45.0, 40.0, 3.0)
    srtm = np.where(voids, np.nan, TRUTH)
    res = delta_surface_fill(srtm, TRUTH + 7.0)
    np.testing.assert_allclose(res.heights_m[voids], TRUTH[voids], atol=1e-9)
    assert (res.heights_m[~voids] == TRUTH[~voids]).all()  # valid cells untouched
    assert res.n_void == res.n_filled == voids.sum() and res.n_still_void == 0
    assert res.n_voids == 2 and res.n_voids_unanchored == 0
    assert res.ring.mean_m == pytest.approx(7.0) and res.ring.nmad_m == pytest.approx(0.0)
    np.testing.assert_allclose(res.delta_m[voids], -7.0, atol=1e-9)


def test_a_tilted_difference_is_followed_across_the_void():
    tilt = 0.3 * ROWS - 0.1 * COLS  # DSM - truth varies linearly (a DSM tilted by metres/km)
    voids = disc(30.0, 30.0, 9.0)
    res = delta_surface_fill(np.where(voids, np.nan, TRUTH), TRUTH + tilt)
    np.testing.assert_allclose(res.heights_m[voids], TRUTH[voids], atol=1e-9)


def test_where_the_dsm_is_missing_cells_stay_void_and_borderless_parts_take_the_median():
    voids = disc(20.0, 20.0, 6.0) | disc(45.0, 45.0, 4.0)
    dsm = TRUTH + 5.0
    dsm[disc(20.0, 20.0, 2.0)] = np.nan  # a hole of the DSM inside the first void
    around = disc(45.0, 45.0, 9.0) & ~disc(45.0, 45.0, 4.0)
    dsm[around] = np.nan  # the second void's border has no DSM: no local difference
    res = delta_surface_fill(np.where(voids, np.nan, TRUTH), dsm)
    hole = disc(20.0, 20.0, 2.0)
    assert np.isnan(res.heights_m[hole]).all()
    assert res.n_still_void == hole.sum() and res.n_filled == voids.sum() - hole.sum()
    assert res.n_voids_unanchored == 1 and res.n_cells_unanchored == disc(45, 45, 4).sum()
    assert res.fallback_delta_m == pytest.approx(-5.0)
    filled = res.filled
    np.testing.assert_allclose(res.heights_m[filled], TRUTH[filled], atol=1e-9)


def test_ring_statistics_and_a_blunder_at_the_border():
    rng = np.random.default_rng(1)
    noise = rng.normal(0.0, 2.0, (N, N))
    voids = disc(30.0, 30.0, 8.0)
    dsm = TRUTH + 4.0 + noise
    dsm[30, 40] += 300.0  # a DSM blunder next to the void (1 cell off its edge at col 38)
    dsm[30, 39] += 300.0
    res = delta_surface_fill(np.where(voids, np.nan, TRUTH), dsm, FillConfig(border_cells=3))
    assert res.ring.count > 100
    assert res.ring.median_m == pytest.approx(4.0, abs=0.5)
    assert res.ring.nmad_m == pytest.approx(2.0, abs=0.5)
    assert res.n_ring_rejected == 2
    err = res.heights_m[voids] - TRUTH[voids]
    # inside, the DSM's own noise remains (plus some of the border's); the blunder is gone
    assert np.abs(err).max() < 20.0
    assert np.percentile(np.abs(err), 68) < 2.0 * 2.0
    kept = delta_surface_fill(np.where(voids, np.nan, TRUTH), dsm, FillConfig(outlier_nmad=0))
    assert kept.n_ring_rejected == 0 and np.abs(kept.heights_m[voids] - TRUTH[voids]).max() > 50


def test_smoothing_the_ring_averages_the_references_cell_noise():
    rng = np.random.default_rng(2)
    voids = disc(30.0, 30.0, 10.0)
    srtm = np.where(voids, np.nan, TRUTH + rng.normal(0.0, 3.0, (N, N)))  # noisy reference
    raw = delta_surface_fill(srtm, TRUTH)
    smooth = delta_surface_fill(srtm, TRUTH, FillConfig(smooth_cells=2))
    e_raw = np.abs(raw.heights_m[voids] - TRUTH[voids])
    e_smooth = np.abs(smooth.heights_m[voids] - TRUTH[voids])
    assert np.percentile(e_smooth, 68) < 0.6 * np.percentile(e_raw, 68)


def test_nanmean_window_ignores_missing_cells():
    a = np.array([[1.0, np.nan, 3.0], [np.nan, np.nan, np.nan], [7.0, np.nan, 9.0]])
    m = nanmean_window(a, 1)
    assert m[1, 1] == pytest.approx(5.0) and m[0, 0] == pytest.approx(1.0)
    assert np.isnan(nanmean_window(np.full((3, 3), np.nan), 1)).all()


def test_dsm_heights_to_the_tiles_datum():
    geoid = GeoidGrid(np.full((3, 3), 48.0), 43.0, 4.0, 1.0, 1.0)  # N = 48 m
    lon, lat = np.array([5.0, 5.5]), np.array([44.0, 44.5])
    h = np.array([148.0, 248.0])
    np.testing.assert_allclose(dsm_to_datum(h, HeightFrame("ellipsoidal"), "egm96", lon, lat,
                                            geoid), [100.0, 200.0])
    np.testing.assert_allclose(dsm_to_datum(h, HeightFrame("egm96"), "ellipsoidal", lon, lat,
                                            geoid), [196.0, 296.0])
    feet = dsm_to_datum(h / 0.3048, HeightFrame("ellipsoidal", 0.3048), "ellipsoidal", lon, lat,
                        geoid)
    np.testing.assert_allclose(feet, h)
    with pytest.raises(InputError, match="datum"):
        dsm_to_datum(h, HeightFrame("egm96"), "navd88", lon, lat, geoid)


@pytest.mark.parametrize("kw", [{"border_cells": 0}, {"smooth_cells": -1},
                                {"outlier_nmad": float("nan")}])
def test_bad_settings_are_refused(kw):
    with pytest.raises(InputError):
        FillConfig(**kw)


def test_grids_of_different_shapes_are_refused():
    with pytest.raises(InputError, match="same nodes"):
        delta_surface_fill(TRUTH, TRUTH[:-1])
