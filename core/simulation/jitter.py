"""High-frequency attitude jitter of a pushbroom platform.

Roll, pitch and yaw each get a sum of sinusoids with hashed phases::

    angle_a(t) = sum_k A[a, k] * sin(2 pi f_k t + phi[a, k]) - mean_a

``phi[a, k] = 2 pi * hash_uniform(seed, a, k)``, so the profile is a pure
function of time and seed: any block of image lines gets the same attitudes.
A low-order time polynomial (what the orientation adjusts) cannot absorb
frequencies whose period is well below the scene duration; that residual is
what the simulator uses jitter for.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.errors import InputError
from core.simulation.hashing import hash_uniform

__all__ = ["jitter_profile"]


def jitter_profile(t_s: ArrayLike, seed: int, amplitudes_rad: ArrayLike,
                   frequencies_hz: ArrayLike,
                   scene_interval_s: tuple[float, float] | None = None) -> NDArray[np.float64]:
    """Roll, pitch, yaw jitter angles at times ``t_s``.

    Args:
        t_s: times in seconds (any shape), e.g. line times from the scene start.
        seed: jitter seed.
        amplitudes_rad: sinusoid amplitudes, radians: shape (3,) (one per axis,
            every frequency) or (3, K) (per axis and frequency).
        frequencies_hz: the K frequencies, Hz (positive).
        scene_interval_s: (t_start, t_end); when given, the exact mean of each
            axis over that interval is removed (analytically, so per-tile calls
            agree). None keeps the raw sum, whose mean over many periods is small.

    Returns:
        float64 array of shape ``t_s.shape + (3,)``: roll, pitch, yaw in radians.
    """
    t = np.asarray(t_s, dtype=np.float64)
    f = np.atleast_1d(np.asarray(frequencies_hz, dtype=np.float64))
    if f.ndim != 1 or f.size == 0 or not np.all(f > 0) or not np.all(np.isfinite(f)):
        raise InputError(f"frequencies_hz must be a 1-D array of positive values, got {f!r}")
    amp = np.asarray(amplitudes_rad, dtype=np.float64)
    if amp.shape == (3,):
        amp = np.repeat(amp[:, None], f.size, axis=1)
    if amp.shape != (3, f.size):
        raise InputError(
            f"amplitudes_rad must have shape (3,) or (3, {f.size}) for {f.size} frequencies, "
            f"got {amp.shape}"
        )
    if scene_interval_s is not None and not scene_interval_s[1] > scene_interval_s[0]:
        raise InputError(f"scene_interval_s must be (start, end) with end > start, "
                         f"got {scene_interval_s!r}")
    phase = 2.0 * np.pi * hash_uniform(seed, np.arange(3)[:, None], np.arange(f.size)[None, :])
    omega = 2.0 * np.pi * f
    flat = np.ascontiguousarray(t.reshape(-1))
    out = np.zeros((flat.size, 3), dtype=np.float64)
    for a in range(3):
        for k in range(f.size):
            if amp[a, k] == 0.0:
                continue
            arg = np.ascontiguousarray(omega[k] * flat + phase[a, k])
            out[:, a] += amp[a, k] * np.sin(arg)
            if scene_interval_s is not None:
                t0, t1 = scene_interval_s
                mean = -(np.cos(omega[k] * t1 + phase[a, k]) - np.cos(omega[k] * t0 + phase[a, k]))
                out[:, a] -= amp[a, k] * mean / (omega[k] * (t1 - t0))
    return out.reshape(t.shape + (3,))
