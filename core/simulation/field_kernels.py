"""Compiled (Numba) kernels of the simulator's counter-based hash and gradient noise.

The same arithmetic as the NumPy expressions they replace, point by point and in the same
order (SplitMix64 on wrapping ``uint64``; the noise's ``+ - * /`` and ``floor``, exactly rounded,
no fused multiply-add: Numba contracts nothing without ``fastmath``), so the fields keep their
bytes; a point goes through every octave in one pass instead of a dozen array temporaries per
octave. Transcendental functions (Box-Muller's log and cos) stay in NumPy, whose SIMD paths may
round differently from libm's.

This module imports Numba: :mod:`core.simulation.hashing` and :mod:`core.simulation.fields`
import it inside the functions that call it, so module imports stay fast. Kernels compile on
their first call and are cached on disk; they are serial and release the GIL (the simulator's
Dask threads run them side by side).
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray

GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_C1 = np.uint64(0xBF58476D1CE4E5B9)
_C2 = np.uint64(0x94D049BB133111EB)
_S30 = np.uint64(30)
_S27 = np.uint64(27)
_S31 = np.uint64(31)
_S11 = np.uint64(11)
_S60 = np.uint64(60)
_TWO_POW_M53 = 2.0**-53
_N_GRAD = 16
_ANGLES = (np.arange(_N_GRAD) + 0.5) * (2.0 * np.pi / _N_GRAD)
GX = np.cos(_ANGLES)  # the 16 unit gradients of the noise lattice
GY = np.sin(_ANGLES)
SQRT2 = float(np.sqrt(2.0))

U64 = NDArray[np.uint64]
I64 = NDArray[np.int64]
F64 = NDArray[np.float64]


@numba.njit(inline="always")
def _mix(z: np.uint64) -> np.uint64:
    z = (z ^ (z >> _S30)) * _C1
    z = (z ^ (z >> _S27)) * _C2
    return z ^ (z >> _S31)


@numba.njit(cache=True, nogil=True, error_model="numpy")
def seed_state(seed: np.uint64) -> np.uint64:
    """The hash's state after the seed: ``mix(seed + G)``."""
    return _mix(np.uint64(seed) + GOLDEN)


@numba.njit(cache=True, nogil=True, error_model="numpy")
def hash_keys(state: np.uint64, keys: I64) -> U64:
    """``h = mix(h ^ (key_n + G n))`` over the rows of ``keys`` (K, n) from ``state``: the
    hash of each column's keys, as :func:`core.simulation.hashing.hash_u64`."""
    n_keys, n = keys.shape
    out = np.empty(n, dtype=np.uint64)
    for p in range(n):
        h = state
        for k in range(n_keys):
            h = _mix(h ^ (np.uint64(keys[k, p]) + GOLDEN * np.uint64(k + 1)))
        out[p] = h
    return out


@numba.njit(inline="always")
def _node_hash(state: np.uint64, i: np.int64, j: np.int64) -> np.uint64:
    h = _mix(state ^ (np.uint64(i) + GOLDEN))
    return _mix(h ^ (np.uint64(j) + GOLDEN * np.uint64(2)))


@numba.njit(inline="always")
def _fade(t: float) -> float:
    return t * t * t * (t * (t * 6.0 - 15.0) + 10.0)


@numba.njit(inline="always")
def _noise(u: float, v: float, state: np.uint64, gx: F64, gy: F64) -> float:
    """Gradient noise at lattice coordinates (u, v): the four corner ramps, quintic-faded."""
    if not (np.isfinite(u) and np.isfinite(v)):
        return np.nan
    fu = np.floor(u)
    fv = np.floor(v)
    xf = u - fu
    yf = v - fv
    i0 = np.int64(fu)
    j0 = np.int64(fv)
    k00 = np.intp(_node_hash(state, i0, j0) >> _S60)
    k10 = np.intp(_node_hash(state, i0 + 1, j0) >> _S60)
    k01 = np.intp(_node_hash(state, i0, j0 + 1) >> _S60)
    k11 = np.intp(_node_hash(state, i0 + 1, j0 + 1) >> _S60)
    xf1 = xf - 1.0
    yf1 = yf - 1.0
    n00 = gx[k00] * xf + gy[k00] * yf
    n10 = gx[k10] * xf1 + gy[k10] * yf
    n01 = gx[k01] * xf + gy[k01] * yf1
    n11 = gx[k11] * xf1 + gy[k11] * yf1
    sx = _fade(xf)
    sy = _fade(yf)
    a = n00 + sx * (n10 - n00)
    b = n01 + sx * (n11 - n01)
    return (a + sy * (b - a)) * SQRT2


@numba.njit(cache=True, nogil=True, error_model="numpy")
def noise_sum(x: F64, y: F64, states: U64, wavelength_m: F64, off_x: F64, off_y: F64,
              coef: F64, raw: bool, gx: F64, gy: F64) -> F64:
    """``sum_k coef[k] * noise_k(x / wavelength_m[k] + off_x[k], y / ... + off_y[k])`` at each
    point, added from 0.0 in the order of the octaves (as ``total += coef * noise`` does);
    ``raw``: the single octave's value itself (no 0.0 added, which would turn -0.0 into 0.0)."""
    n = x.size
    out = np.empty(n)
    n_oct = states.size
    for p in range(n):
        xp = x[p]
        yp = y[p]
        if raw:
            out[p] = _noise(xp / wavelength_m[0] + off_x[0], yp / wavelength_m[0] + off_y[0],
                            states[0], gx, gy)
            continue
        total = 0.0
        for k in range(n_oct):
            total = total + coef[k] * _noise(xp / wavelength_m[k] + off_x[k],
                                             yp / wavelength_m[k] + off_y[k], states[k], gx, gy)
        out[p] = total
    return out


@numba.njit(cache=True, nogil=True, error_model="numpy")
def cell_uniform(x: F64, y: F64, state: np.uint64, cell_m: float) -> F64:
    """The hashed uniform of the ``cell_m`` square holding each point; NaN off the finite
    plane (as :func:`core.simulation.fields.cell_uniform`)."""
    n = x.size
    out = np.empty(n)
    for p in range(n):
        if not (np.isfinite(x[p]) and np.isfinite(y[p])):
            out[p] = np.nan
            continue
        i = np.int64(np.floor(x[p] / cell_m))
        j = np.int64(np.floor(y[p] / cell_m))
        out[p] = np.float64(_node_hash(state, i, j) >> _S11) * _TWO_POW_M53
    return out
