"""The correlation peaks every matcher shares: NCC over a search area with nodata, the integer
peak and its neighbourhood, the sub-pixel vertex and the peak's curvature; orientation
correlation against a direct sum over scipy's Sobel gradients."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from core.matching.peaks import (
    INVALID,
    integer_peak,
    ncc,
    ncc_surface,
    orientation_correlation,
    orientation_surface,
    parabola_peak,
    peak_hessian,
    quadratic_peak,
)
from core.matching.tiepoints import MIN_CORRELATION


def test_quadratic_peak_finds_the_vertex_of_a_quadratic():
    v, u = np.mgrid[-1:2, -1:2].astype(float)
    z = 0.9 - 0.3 * (u - 0.23) ** 2 - 0.2 * (v + 0.41) ** 2 + 0.05 * (u - 0.23) * (v + 0.41)
    dx, dy = quadratic_peak(z[None])
    assert dx[0] == pytest.approx(0.23, abs=1e-9)
    assert dy[0] == pytest.approx(-0.41, abs=1e-9)


def test_quadratic_peak_and_hessian_of_an_exact_paraboloid():
    y, x = np.mgrid[-1:2, -1:2]
    z = 1.0 - 0.5 * ((x - 0.3) ** 2 * 2 + (y + 0.2) ** 2 * 3) + 0.1 * (x - 0.3) * (y + 0.2)
    (dx,), (dy,) = quadratic_peak(z)
    assert dx == pytest.approx(0.3, abs=1e-12) and dy == pytest.approx(-0.2, abs=1e-12)
    np.testing.assert_allclose(peak_hessian(z)[0], [[-2.0, 0.1], [0.1, -3.0]], atol=1e-12)


def test_a_saddle_falls_back_to_the_parabolas_on_each_axis():
    """A fit without a maximum says nothing about the peak: the parabolas through the centre
    row and column do (0 on an axis where even that has none); never beyond one step."""
    y, x = np.mgrid[-1:2, -1:2].astype(float)
    z = 1.0 - 0.5 * (x - 0.2) ** 2 + 0.4 * y**2  # a maximum along x, a minimum along y
    dx, dy = quadratic_peak(z)
    assert dx[0] == pytest.approx(parabola_peak(z[1, 0], z[1, 1], z[1, 2])) == pytest.approx(0.2)
    assert dy[0] == 0.0
    assert np.all(np.abs(quadratic_peak(np.array([[0, 0, 0], [0, 1, 5.0], [0, 0, 0]]))) <= 1.0)


def test_ncc_surface_marks_nodata_and_the_peak_is_found():
    rng = np.random.default_rng(0)
    search = rng.normal(size=(40, 50)).astype(np.float32)
    tpl = search[12:21, 30:39].copy()
    surf = ncc_surface(search, tpl)
    ix, iy, val, nb = integer_peak(surf)
    assert (ix, iy) == (30, 12) and val == pytest.approx(1.0, abs=1e-5) and nb.shape == (3, 3)
    invalid = np.zeros(search.shape, np.uint8)
    invalid[15, 33] = 1  # inside the matching window: that position and its neighbours go
    masked = ncc_surface(search, tpl, invalid)
    assert masked[12, 30] == INVALID and masked[7, 25] == INVALID and masked[16, 34] != INVALID
    assert integer_peak(masked)[3] is None or integer_peak(masked)[:2] != (30, 12)
    assert integer_peak(surf[12:, 30:])[3] is None  # the peak on the border: no neighbourhood


def test_ncc_of_one_patch_and_of_a_stack():
    rng = np.random.default_rng(1)
    a = rng.normal(size=(4, 7, 7))
    b = 2.0 * a + 3.0
    np.testing.assert_allclose(ncc(a, b), 1.0, atol=1e-12)
    assert float(ncc(a[0], -a[0])) == pytest.approx(-1.0)
    assert np.isnan(ncc(np.ones((5, 5)), a[0, :5, :5]))


def _directions(a: np.ndarray) -> np.ndarray:
    """Unit Sobel gradients of the interior by scipy, (2, h - 2, w - 2)."""
    g = np.stack([ndimage.sobel(a, axis=1), ndimage.sobel(a, axis=0)])[:, 1:-1, 1:-1]
    return g / np.linalg.norm(g, axis=0)


def test_orientation_surface_is_the_mean_cosine_of_the_gradient_directions():
    """Against a direct sum over scipy's Sobel directions at every position; the template cut
    from the search area (with its one-pixel border) peaks at 1 where it was cut."""
    rng = np.random.default_rng(3)
    search = ndimage.gaussian_filter(rng.normal(size=(30, 34)), 1.0).astype(np.float32)
    tpl = search[9:20, 14:25].copy()  # 9x9 compared, with its border
    surf = orientation_surface(search, tpl)
    assert surf.shape == (20, 24)
    t = _directions(tpl.astype(np.float64))
    direct = np.array([[np.sum(_directions(search[r:r + 11, c:c + 11].astype(np.float64)) * t)
                        / 81.0 for c in range(24)] for r in range(20)])
    np.testing.assert_allclose(surf, direct, atol=2e-6)
    ix, iy, val, nb = integer_peak(surf)
    assert (ix, iy) == (14, 9) and val == pytest.approx(1.0, abs=1e-5) and nb is not None
    assert np.max(np.delete(surf.ravel(), 9 * 24 + 14)) < 0.9
    invalid = np.zeros(search.shape, np.uint8)
    invalid[9, 14] = 1  # the template's border at the peak: that position goes, its far
    masked = orientation_surface(search, tpl, invalid)  # neighbours stay
    assert masked[9, 14] == INVALID and masked[0, 4] == INVALID and masked[10, 15] != INVALID


def test_orientation_correlation_ignores_what_keeps_the_directions():
    """A gain and an offset keep every gradient's direction (correlation 1); a monotone change
    of the grey values (a gamma of 2.5) keeps them but for the differences' discretisation
    (measured 0.9997, NCC 0.987-0.995); unrelated 15x15 patches of white noise score about 0
    (measured standard deviation 0.073), never the tie points' threshold."""
    rng = np.random.default_rng(4)
    a = 50.0 + ndimage.gaussian_filter(rng.normal(size=(3, 17, 17)), (0, 1.2, 1.2)) * 30.0
    np.testing.assert_allclose(orientation_correlation(a, 3.0 * a - 7.0), 1.0, atol=1e-12)
    b = 5.0 + 0.02 * a**2.5
    oc = orientation_correlation(a, b)
    assert np.all(oc > 0.999) and np.all(oc > ncc(a[:, 1:-1, 1:-1], b[:, 1:-1, 1:-1]))
    noise = rng.normal(size=(400, 17, 17))
    oc = orientation_correlation(noise[:200], noise[200:])
    assert abs(oc.mean()) < 0.01 and np.max(np.abs(oc)) < MIN_CORRELATION["orientation"]
    assert np.isnan(orientation_correlation(np.where(a == a[0, 5, 5], np.nan, a), b)[0])
