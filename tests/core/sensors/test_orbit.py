"""The orbit's compiled interpolation and local frames (:mod:`core.sensors.orbit_kernels`, used by
:class:`core.sensors.orbit.Orbit`) against independent implementations: SciPy's barycentric
Lagrange interpolator over the same samples, NumPy's cross products."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.interpolate import BarycentricInterpolator

from core.parallel import MIN_SPLIT
from core.sensors.orbit import LAGRANGE_POINTS, Orbit, orbital_frame, rotation_rpy


def _orbit(n: int, seed: int = 0) -> Orbit:
    """An orbit sampled unevenly about every minute, ``n`` times, with a radial wobble of a
    few minutes that no polynomial of 8 samples follows to a millimetre (another window of
    samples gives another answer)."""
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(0.8, 1.2, n)) * 60.0
    w = 2 * np.pi / 6000.0
    r = 7.2e6 * (1.0 + 1e-3 * np.sin(20 * w * t))
    pos = np.column_stack([r * np.cos(w * t), r * np.sin(w * t) * 0.4, r * np.sin(w * t) * 0.9])
    vel = np.gradient(pos, t, axis=0) + rng.normal(0, 0.1, (n, 3))
    return Orbit(t, pos, vel)


def _scipy_states(o: Orbit, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each time through the polynomial of its own window of samples: the ``k`` samples whose
    first lies ``k // 2`` before the first sample after t, kept inside the orbit."""
    n = o.times_s.size
    k = min(LAGRANGE_POINTS, n)
    pos, vel = np.empty((t.size, 3)), np.empty((t.size, 3))
    for i, ti in enumerate(t):
        s = int(np.clip(np.searchsorted(o.times_s, ti) - k // 2, 0, n - k))
        win = slice(s, s + k)
        pos[i] = BarycentricInterpolator(o.times_s[win], o.positions_m[win])(ti)
        vel[i] = BarycentricInterpolator(o.times_s[win], o.velocities_m_s[win])(ti)
    return pos, vel


@pytest.mark.parametrize("n", [3, 8, 30])
def test_interpolation_is_the_lagrange_polynomial_of_its_window(n: int):
    o = _orbit(n)
    # inside, on the samples, and up to a sample spacing beyond both ends
    t = np.concatenate([np.linspace(o.times_s[0] - 50.0, o.times_s[-1] + 50.0, 97),
                        o.times_s[[0, n // 2, -1]]])
    pos, vel = o.interpolate(t)
    ref_p, ref_v = _scipy_states(o, t)
    np.testing.assert_allclose(pos, ref_p, rtol=0, atol=1e-5)  # metres
    np.testing.assert_allclose(vel, ref_v, rtol=0, atol=1e-8)  # m/s
    # exact at the samples
    np.testing.assert_allclose(pos[-3:], o.positions_m[[0, n // 2, -1]], rtol=1e-12)


def test_interpolation_splits_large_calls_without_changing_them():
    o = _orbit(30, seed=1)
    t = np.random.default_rng(2).uniform(o.times_s[0], o.times_s[-1], 2 * MIN_SPLIT + 17)
    pos, vel = o.interpolate(t)
    few = slice(0, 300)
    one_p, one_v = o.interpolate(t[few])  # under MIN_SPLIT: one thread
    np.testing.assert_array_equal(pos[few], one_p)
    np.testing.assert_array_equal(vel[few], one_v)
    ref_p, _ = _scipy_states(o, t[-50:])
    np.testing.assert_allclose(pos[-50:], ref_p, rtol=0, atol=1e-5)


def test_a_nan_time_gives_nan_states():
    pos, vel = _orbit(12).interpolate(np.array([np.nan, 55.0]))
    assert np.isnan(pos[0]).all() and np.isnan(vel[0]).all()
    assert np.isfinite(pos[1]).all()


@pytest.mark.parametrize("m", [5, 2 * MIN_SPLIT + 3])
def test_orbital_frames_are_the_cross_products_of_position_and_velocity(m: int):
    rng = np.random.default_rng(m)
    p = rng.normal(0, 1, (m, 3)) * 7e6
    v = rng.normal(0, 1, (m, 3)) * 7e3
    f = orbital_frame(p, v)
    z = -p / np.linalg.norm(p, axis=1, keepdims=True)
    y = np.cross(z, v)
    y /= np.linalg.norm(y, axis=1, keepdims=True)
    np.testing.assert_allclose(f[:, :, 2], z, atol=1e-14)
    np.testing.assert_allclose(f[:, :, 1], y, atol=1e-14)
    np.testing.assert_allclose(f[:, :, 0], np.cross(y, z), atol=1e-14)
    # a rotation: orthonormal and right-handed
    np.testing.assert_allclose(np.einsum("mji,mjk->mik", f, f), np.broadcast_to(np.eye(3),
                                                                               f.shape),
                               atol=1e-13)
    np.testing.assert_allclose(np.linalg.det(f), 1.0, atol=1e-13)


@pytest.mark.parametrize("m", [7, 2 * MIN_SPLIT + 5])
def test_platform_is_the_orbit_the_frame_and_the_attitude_composed(m: int):
    from scipy.spatial.transform import Rotation

    o = _orbit(20, seed=3)
    rng = np.random.default_rng(m)
    t = rng.uniform(o.times_s[0], o.times_s[-1], m)
    ang = rng.uniform(-0.5, 0.5, (3, m))
    pos, frame, rot, cam = o.platform(t, ang)
    if m < 100:
        ref_p, ref_v = _scipy_states(o, t)
        np.testing.assert_allclose(pos, ref_p, rtol=0, atol=1e-5)
    else:
        ref_p, ref_v = o.interpolate(t)
        np.testing.assert_array_equal(pos, ref_p)
    z = -ref_p / np.linalg.norm(ref_p, axis=1, keepdims=True)
    y = np.cross(z, ref_v)
    y /= np.linalg.norm(y, axis=1, keepdims=True)
    np.testing.assert_allclose(frame, np.stack([np.cross(y, z), y, z], axis=2), atol=1e-12)
    # Rz(yaw) Ry(pitch) Rx(roll): SciPy's intrinsic z-y'-x'' Euler angles
    ref_rot = Rotation.from_euler("ZYX", np.column_stack([ang[2], ang[1], ang[0]])).as_matrix()
    np.testing.assert_allclose(rot, ref_rot, atol=1e-14)
    np.testing.assert_array_equal(rotation_rpy(*ang), rot)  # one formula, both paths
    one = rotation_rpy(*ang[:, 0])  # scalars give one matrix
    assert one.shape == (3, 3)
    np.testing.assert_array_equal(one, rot[0])
    np.testing.assert_allclose(cam, frame @ ref_rot, atol=1e-13)
