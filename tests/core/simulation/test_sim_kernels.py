"""The simulator's compiled kernels give the bytes of independent implementations: SciPy's
bilinear ``map_coordinates``, a pure-Python gradient noise, and the generic NumPy march of
:func:`core.dem.first_crossing` (which the sensor models still use)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.ndimage import map_coordinates

from core.dem import first_crossing, march_levels
from core.simulation import raycast_kernels as K
from core.simulation.fields import fbm, gradient_noise
from core.simulation.hashing import derive_seed, hash_u64, hash_uniform

_ANGLES = [(k + 0.5) * (2.0 * math.pi / 16) for k in range(16)]


def _noise_py(x: float, y: float, seed: int, wavelength_m: float) -> float:
    """Perlin's improved 2-D gradient noise written out with Python floats, one point."""
    ox = float(hash_uniform(derive_seed(seed, "offset-x")))
    oy = float(hash_uniform(derive_seed(seed, "offset-y")))
    u, v = x / wavelength_m + ox, y / wavelength_m + oy
    i0, j0 = math.floor(u), math.floor(v)
    xf, yf = u - math.floor(u), v - math.floor(v)

    def ramp(di: int, dj: int, ax: float, ay: float) -> float:
        k = int(hash_u64(seed, i0 + di, j0 + dj)) >> 60
        return np.cos(_ANGLES[k]) * ax + np.sin(_ANGLES[k]) * ay

    def fade(t: float) -> float:
        return t * t * t * (t * (t * 6.0 - 15.0) + 10.0)

    n00, n10 = ramp(0, 0, xf, yf), ramp(1, 0, xf - 1.0, yf)
    n01, n11 = ramp(0, 1, xf, yf - 1.0), ramp(1, 1, xf - 1.0, yf - 1.0)
    a = n00 + fade(xf) * (n10 - n00)
    b = n01 + fade(xf) * (n11 - n01)
    return (a + fade(yf) * (b - a)) * math.sqrt(2.0)


def test_gradient_noise_and_fbm_match_a_pure_python_noise() -> None:
    rng = np.random.default_rng(3)
    x = np.concatenate([rng.uniform(-4e5, 9e5, 300), np.arange(-6, 6) * 25.0])
    y = np.concatenate([rng.uniform(4.4e6, 5.4e6, 300), np.arange(-6, 6) * 25.0])
    for seed, wl in ((0, 25.0), (2**64 - 5, 3.0), (11, 400.0)):
        got = gradient_noise(x, y, seed, wl)
        want = np.array([_noise_py(a, b, seed, wl) for a, b in zip(x, y, strict=True)])
        assert got.tobytes() == want.tobytes()
    w = [0.5**k for k in range(4)]
    want = sum(wk * np.array([_noise_py(a, b, derive_seed(7, "fbm-octave", k), 100.0 / 2**k)
                              for a, b in zip(x, y, strict=True)]) for k, wk in enumerate(w))
    assert fbm(x, y, 7, 100.0, 4).tobytes() == (want / sum(w)).tobytes()
    assert np.isnan(gradient_noise(np.array([np.nan, 1.0]), np.array([0.0, np.inf]), 1, 5.0)).all()


def _rough_grid(rng: np.random.Generator, shape: tuple[int, int]) -> np.ndarray:
    z = 500.0 + np.cumsum(np.cumsum(rng.normal(0, 3.0, shape), 0), 1)
    for a, b in rng.integers(0, min(shape) - 4, (shape[0] * shape[1] // 80, 2)):
        z[a:a + 4, b:b + 4] = z[a, b] + 40.0  # flat roofs: occlusions, and tiles' tops
    z[5:15, 30:40] = np.nan  # a void
    return z


def test_bilinear_sample_is_scipy_map_coordinates_bit_for_bit() -> None:
    rng = np.random.default_rng(0)
    z = _rough_grid(rng, (40, 60))
    nr, nc = z.shape
    fi = np.concatenate([rng.uniform(-1, nr, 20000), [0, nr - 1, nr - 1, 0, 7.0, nr - 1]])
    fj = np.concatenate([rng.uniform(-1, nc, 20000), [0, nc - 1, 0, nc - 1, 31.5, 3.25]])
    got = K.sample_grid(z, 0.0, 0.0, 1.0, 1.0, fj, fi)
    inside = (fi >= 0) & (fi <= nr - 1) & (fj >= 0) & (fj <= nc - 1)
    want = np.full(fi.shape, np.nan)
    want[inside] = map_coordinates(z, [fi[inside], fj[inside]], order=1, mode="nearest",
                                   prefilter=False)
    assert got.tobytes() == want.tobytes()
    assert np.isnan(got[~inside]).all() and np.isnan(got[inside]).any()  # the void propagates


@pytest.mark.parametrize("tan_inc", [0.0, 0.47, 1.3])
@pytest.mark.parametrize("mesa", [False, True])
def test_ray_march_is_the_generic_first_crossing(tan_inc: float, mesa: bool) -> None:
    rng = np.random.default_rng(1)
    z = _rough_grid(rng, (80, 90))
    x0, y0, dx, dy = 1000.0, 5000.0, 10.0, -10.0
    n = 20000
    hl = np.array([300.0, 600.0, 900.0])
    fx, fy = rng.uniform(x0 - 50, x0 + 950, n), rng.uniform(y0 - 850, y0 + 50, n)
    bend = 1e-5 * (hl - 600.0) ** 2  # a slightly curved line of sight
    rx = np.stack([fx + tan_inc * (h - 500.0) + b for h, b in zip(hl, bend, strict=True)])
    ry = np.stack([fy - 0.3 * tan_inc * (h - 500.0) for h in hl])
    top, bottom = float(np.nanmax(z)) + 0.5, float(np.nanmin(z)) - 0.5
    levels = march_levels(top, bottom, tan_inc * 1.05, 10.0, 1e-3)
    if mesa:  # a flat top 1 m above a level: there lines of sight meet the tiles' highest node
        z[20:60, 20:70] = levels[len(levels) // 3] + 1.0
    den = [(hl[0] - hl[1]) * (hl[0] - hl[2]), (hl[1] - hl[0]) * (hl[1] - hl[2]),
           (hl[2] - hl[0]) * (hl[2] - hl[1])]

    def xy(h: np.ndarray, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ls = [(h - hl[1]) * (h - hl[2]) / den[0], (h - hl[0]) * (h - hl[2]) / den[1],
              (h - hl[0]) * (h - hl[1]) / den[2]]
        return (ls[0] * rx[0, idx] + ls[1] * rx[1, idx] + ls[2] * rx[2, idx],
                ls[0] * ry[0, idx] + ls[1] * ry[1, idx] + ls[2] * ry[2, idx])

    def above(h: np.ndarray, idx: np.ndarray) -> np.ndarray:
        x, y = xy(h, idx)
        fi, fj = (y - y0) / dy, (x - x0) / dx
        inside = (fi >= 0) & (fi <= z.shape[0] - 1) & (fj >= 0) & (fj <= z.shape[1] - 1)
        s = np.full(h.shape, np.nan)
        s[inside] = map_coordinates(z, [fi[inside], fj[inside]], order=1, mode="nearest",
                                    prefilter=False)
        return h - s

    want = first_crossing(above, n, levels, tol_m=1e-3, max_bisections=40)
    got = K.ray_first_heights(rx, ry, hl, z, x0, y0, dx, dy, levels, 1e-3, 40)
    assert got.tobytes() == want.tobytes()
    assert 0.02 < np.isnan(got).mean() < 0.5  # rays off the grid and through the void
    gx, gy = K.ray_xy(rx, ry, hl, got)
    wx, wy = xy(want, np.arange(n))
    assert gx.tobytes() == wx.tobytes() and gy.tobytes() == wy.tobytes()
