"""Noise fields: tile independence, statistics, spectral behaviour, input checks."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from core.errors import InputError
from core.simulation.fields import (
    cell_uniform,
    fbm,
    fbm_threshold,
    fractal_detail_m,
    gradient_noise,
)
from core.simulation.hashing import derive_seed, hash_uniform


def _field(x: np.ndarray, y: np.ndarray, seed: int = 7) -> np.ndarray:
    return (fbm(x, y, seed, 400.0, 6)
            + fractal_detail_m(x, y, seed, 1.5, 1.0, 30.0, 0.8)
            + cell_uniform(x, y, seed, 37.0))


def test_tiles_are_bit_identical_to_whole(splits: tuple[int, int], ground_grid: Callable,
                                          assemble_tiles: Callable) -> None:
    x, y = ground_grid(256, 256)
    whole = _field(x, y)
    tiled = assemble_tiles(lambda tx, ty, r, c: _field(tx, ty), splits=splits)
    assert whole.tobytes() == tiled.tobytes()


def test_scattered_points_equal_grid_values(ground_grid: Callable) -> None:
    # the bounding-box lookup path and the direct path hash the same nodes
    x, y = ground_grid(64, 64)
    whole = fbm(x, y, 3, 50.0, 5)
    idx = np.array([5, 700, 4095, 1234])
    pts = fbm(x.reshape(-1)[idx], y.reshape(-1)[idx], 3, 50.0, 5)
    assert pts.tobytes() == whole.reshape(-1)[idx].tobytes()
    strided = fbm(x[::3, ::-2], y[::3, ::-2], 3, 50.0, 5)
    assert strided.tobytes() == whole[::3, ::-2].tobytes()


def test_same_seed_same_bytes_other_seed_differs(ground_grid: Callable) -> None:
    x, y = ground_grid(64, 64)
    assert _field(x, y, 1).tobytes() == _field(x, y, 1).tobytes()
    assert np.mean(_field(x, y, 1) == _field(x, y, 2)) < 0.01


def test_gradient_noise_vanishes_on_lattice_nodes_and_is_continuous() -> None:
    seed, wl = 5, 10.0
    ox = float(hash_uniform(derive_seed(seed, "offset-x")))
    oy = float(hash_uniform(derive_seed(seed, "offset-y")))
    i, j = np.meshgrid(np.arange(-3, 4), np.arange(-3, 4))
    nodes = gradient_noise((i - ox) * wl, (j - oy) * wl, seed, wl)
    np.testing.assert_allclose(nodes, 0.0, atol=1e-12)
    # Lipschitz: the gradient is bounded (about 2.2 / wavelength)
    x = np.linspace(0, 200, 20_001)
    v = gradient_noise(x, 3.3, seed, wl)
    assert np.max(np.abs(np.diff(v))) < 3.0 / wl * (x[1] - x[0])
    assert 0.2 < v.std() < 0.45


def test_fbm_range_and_mean() -> None:
    g = np.arange(600, dtype=np.float64) * 7.3
    x, y = np.meshgrid(g + 3e5, g + 4e6)
    f = fbm(x, y, 1, 100.0, 5)
    assert f.min() >= -1.0 and f.max() <= 1.0
    assert abs(f.mean()) < 0.02
    assert 0.1 < f.std() < 0.4


@pytest.mark.parametrize("fraction", [0.05, 0.3, 0.7])
def test_fbm_threshold_gives_area_fraction(fraction: float) -> None:
    g = np.arange(500, dtype=np.float64) * 13.1
    x, y = np.meshgrid(g - 2e4, g + 7e5)
    f = fbm(x, y, 99, 100.0, 4)
    share = np.mean(f > fbm_threshold(fraction, 4))
    assert abs(share - fraction) < 0.03 + 0.1 * fraction


def _increment_slope(f: np.ndarray, lags: np.ndarray) -> float:
    s = [np.std(f[:, lag:] - f[:, :-lag]) for lag in lags]
    return float(np.polyfit(np.log(lags), np.log(s), 1)[0])


def _sample_grid() -> tuple[np.ndarray, np.ndarray]:
    x, y = np.meshgrid(np.arange(640.0), np.arange(512.0) * 1.7)
    return x + 1e5, y + 3e6


def test_fbm_spectral_slope_follows_persistence() -> None:
    x, y = _sample_grid()
    lags = np.array([8, 16, 32, 64, 128])
    rough = _increment_slope(fbm(x, y, 4, 1024.0, 10, persistence=0.7), lags)
    smooth = _increment_slope(fbm(x, y, 4, 1024.0, 10, persistence=0.5), lags)
    assert rough == pytest.approx(-np.log2(0.7), abs=0.1)
    assert smooth > rough + 0.2


@pytest.mark.parametrize("hurst", [0.4, 0.8])
def test_fractal_detail_power_law(hurst: float) -> None:
    x, y = _sample_grid()
    f = fractal_detail_m(x, y, 4, 2.0, 2.0, 1024.0, hurst)
    assert _increment_slope(f, np.array([8, 16, 32, 64, 128])) == pytest.approx(hurst, abs=0.12)


def test_fractal_detail_amplitude_is_its_std() -> None:
    x, y = _sample_grid()
    f = fractal_detail_m(x, y, 8, 2.0, 2.0, 32.0, 0.8)
    assert f.std() == pytest.approx(2.0, rel=0.1)
    assert abs(f.mean()) < 0.1
    assert np.all(fractal_detail_m(x[:2], y[:2], 8, 0.0, 2.0, 32.0, 0.8) == 0.0)


def test_fractal_detail_adds_nothing_coarser_than_max_wavelength() -> None:
    # block means over 4 max-wavelengths retain little of the detail's variance
    x, y = _sample_grid()
    f = fractal_detail_m(x, y, 8, 2.0, 1.0, 16.0, 0.8)
    blocks = f[:512, :640].reshape(8, 64, 10, 64).mean(axis=(1, 3))
    assert blocks.std() < 0.15 * f.std()


@pytest.mark.parametrize("kwargs, match", [
    ({"base_wavelength_m": 0.0}, "base_wavelength_m"),
    ({"octaves": 0}, "octaves"),
    ({"lacunarity": 1.0}, "lacunarity"),
    ({"persistence": -0.5}, "persistence"),
])
def test_fbm_input_errors(kwargs: dict, match: str) -> None:
    args = {"base_wavelength_m": 10.0, "octaves": 3, "persistence": 0.5, "lacunarity": 2.0}
    args.update(kwargs)
    with pytest.raises(InputError, match=match):
        fbm(0.0, 0.0, 1, **args)


def test_fractal_detail_input_errors() -> None:
    with pytest.raises(InputError, match="min_wavelength_m"):
        fractal_detail_m(0.0, 0.0, 1, 1.0, 50.0, 30.0, 0.8)
    with pytest.raises(InputError, match="hurst"):
        fractal_detail_m(0.0, 0.0, 1, 1.0, 1.0, 30.0, 1.5)
    with pytest.raises(InputError, match="fraction"):
        fbm_threshold(1.5, 3)


def test_non_finite_coordinates_give_nan_without_warnings() -> None:
    x = np.array([1.0, np.nan, 3.0, np.inf])
    y = np.array([2.0, 2.0, np.nan, 2.0])
    for f in (fbm(x, y, 1, 10.0, 3), fractal_detail_m(x, y, 1, 1.0, 1.0, 8.0, 0.8),
              cell_uniform(x, y, 1, 5.0)):
        assert np.isfinite(f[0]) and np.all(np.isnan(f[1:]))
