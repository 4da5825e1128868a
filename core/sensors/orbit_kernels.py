"""Compiled (Numba) kernels of the orbit: Lagrange interpolation of the state vectors, the
orbital and platform frames, roll-pitch-yaw rotations (:mod:`core.sensors.orbit` calls them).

This module imports Numba: :mod:`core.sensors.orbit` imports it inside the functions that call
it, so module imports stay fast. Kernels compile on their first call and are cached on disk;
they are serial, release the GIL and are spread over the cores by :func:`core.parallel.run_split`.
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray

from core.parallel import run_split

FloatArray = NDArray[np.float64]


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _state_at(times: FloatArray, positions: FloatArray, velocities: FloatArray, k: int,
              tm: float) -> tuple[float, float, float, float, float, float]:
    """Position and velocity at time tm: the Lagrange polynomial of its window of samples."""
    n = times.size
    s = min(max(np.searchsorted(times, tm) - k // 2, 0), n - k)
    px = py = pz = vx = vy = vz = 0.0
    for j in range(k):
        tj = times[s + j]
        w = 1.0
        for i in range(k):
            if i != j:
                w *= (tm - times[s + i]) / (tj - times[s + i])
        px += w * positions[s + j, 0]
        py += w * positions[s + j, 1]
        pz += w * positions[s + j, 2]
        vx += w * velocities[s + j, 0]
        vy += w * velocities[s + j, 1]
        vz += w * velocities[s + j, 2]
    return px, py, pz, vx, vy, vz


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _frame_of(p: FloatArray, v: FloatArray, frame: FloatArray) -> None:
    """The local orbital frame of position p and velocity v (3,) into frame (3, 3)."""
    r = np.sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2])
    zx, zy, zz = -p[0] / r, -p[1] / r, -p[2] / r
    yx, yy, yz = zy * v[2] - zz * v[1], zz * v[0] - zx * v[2], zx * v[1] - zy * v[0]
    ny = np.sqrt(yx * yx + yy * yy + yz * yz)
    yx, yy, yz = yx / ny, yy / ny, yz / ny
    frame[0, 0], frame[1, 0], frame[2, 0] = yy * zz - yz * zy, yz * zx - yx * zz, yx * zy - yy * zx
    frame[0, 1], frame[1, 1], frame[2, 1] = yx, yy, yz
    frame[0, 2], frame[1, 2], frame[2, 2] = zx, zy, zz


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _rpy_into(roll: float, pitch: float, yaw: float, r: FloatArray) -> None:
    """``Rz(yaw) Ry(pitch) Rx(roll)`` into r (3, 3)."""
    cr, sr = np.cos(roll), np.sin(roll)
    cp, sp = np.cos(pitch), np.sin(pitch)
    cy, sy = np.cos(yaw), np.sin(yaw)
    r[0, 0], r[0, 1], r[0, 2] = cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr
    r[1, 0], r[1, 1], r[1, 2] = sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr
    r[2, 0], r[2, 1], r[2, 2] = -sp, cp * sr, cp * cr


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _rotations_rpy(ang: FloatArray, rot: FloatArray, start: int, stop: int) -> None:
    for m in range(start, stop):
        _rpy_into(ang[0, m], ang[1, m], ang[2, m], rot[m])


def rotations_rpy(roll: FloatArray, pitch: FloatArray, yaw: FloatArray) -> FloatArray:
    """``Rz(yaw) Ry(pitch) Rx(roll)`` of angles (rad) of one shape: that shape + (3, 3)."""
    ang = np.stack(np.broadcast_arrays(*(np.asarray(a, dtype=np.float64)
                                         for a in (roll, pitch, yaw))))
    shape = ang.shape[1:]
    ang = np.ascontiguousarray(ang.reshape(3, -1))
    rot = np.empty((ang.shape[1], 3, 3))
    run_split(_rotations_rpy, ang.shape[1], ang, rot)
    return rot.reshape(shape + (3, 3))


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _orbit_states(times: FloatArray, positions: FloatArray, velocities: FloatArray, k: int,
                  t: FloatArray, pos: FloatArray, vel: FloatArray, start: int,
                  stop: int) -> None:
    for m in range(start, stop):
        (pos[m, 0], pos[m, 1], pos[m, 2], vel[m, 0], vel[m, 1],
         vel[m, 2]) = _state_at(times, positions, velocities, k, t[m])


def orbit_states(times: FloatArray, positions: FloatArray, velocities: FloatArray,
                 k: int, t: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Positions and velocities (m, 3) at times ``t`` (m,): Lagrange polynomials through the
    ``k`` samples around each time (``times`` (n,) increasing, ``k <= n``; the window starts
    ``k // 2`` samples before the first sample after t, clipped to the ends)."""
    t = np.ascontiguousarray(t, dtype=np.float64).ravel()
    pos, vel = np.empty((t.size, 3)), np.empty((t.size, 3))
    run_split(_orbit_states, t.size, np.ascontiguousarray(times, dtype=np.float64),
              np.ascontiguousarray(positions, dtype=np.float64),
              np.ascontiguousarray(velocities, dtype=np.float64), int(k), t, pos, vel)
    return pos, vel


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _orbital_frames(pos: FloatArray, vel: FloatArray, frame: FloatArray, start: int,
                    stop: int) -> None:
    for m in range(start, stop):
        _frame_of(pos[m], vel[m], frame[m])


def orbital_frames(pos: FloatArray, vel: FloatArray) -> FloatArray:
    """Local orbital frames (m, 3, 3), columns X (Y x Z), Y (Z x V, unit), Z (-P/|P|), of
    positions and velocities (m, 3); see :mod:`core.sensors.orbit`."""
    pos = np.ascontiguousarray(pos, dtype=np.float64).reshape(-1, 3)
    vel = np.ascontiguousarray(vel, dtype=np.float64).reshape(-1, 3)
    frame = np.empty((pos.shape[0], 3, 3))
    run_split(_orbital_frames, pos.shape[0], pos, vel, frame)
    return frame


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _platform_frames(times: FloatArray, positions: FloatArray, velocities: FloatArray, k: int,
                     t: FloatArray, ang: FloatArray, pos: FloatArray, frame: FloatArray,
                     rot: FloatArray, cam: FloatArray, start: int, stop: int) -> None:
    v = np.empty(3)
    for m in range(start, stop):
        (pos[m, 0], pos[m, 1], pos[m, 2], v[0], v[1],
         v[2]) = _state_at(times, positions, velocities, k, t[m])
        _frame_of(pos[m], v, frame[m])
        r = rot[m]
        _rpy_into(ang[0, m], ang[1, m], ang[2, m], r)
        f = frame[m]
        for i in range(3):
            for j in range(3):
                cam[m, i, j] = f[i, 0] * r[0, j] + f[i, 1] * r[1, j] + f[i, 2] * r[2, j]


def platform_frames(times: FloatArray, positions: FloatArray, velocities: FloatArray, k: int,
                    t: FloatArray, ang: FloatArray
                    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """A pushbroom platform at times ``t`` (m,) with attitude angles ``ang`` (3, m) (roll,
    pitch, yaw, rad): position (m, 3) (:func:`orbit_states`), orbital frame (m, 3, 3)
    (:func:`orbital_frames`), attitude rotation ``Rz(yaw) Ry(pitch) Rx(roll)`` (m, 3, 3)
    and camera -> ECEF (frame @ rotation), in one pass."""
    t = np.ascontiguousarray(t, dtype=np.float64).ravel()
    ang = np.ascontiguousarray(ang, dtype=np.float64).reshape(3, t.size)
    n = t.size
    pos, frame = np.empty((n, 3)), np.empty((n, 3, 3))
    rot, cam = np.empty((n, 3, 3)), np.empty((n, 3, 3))
    run_split(_platform_frames, n, np.ascontiguousarray(times, dtype=np.float64),
              np.ascontiguousarray(positions, dtype=np.float64),
              np.ascontiguousarray(velocities, dtype=np.float64), int(k), t, ang, pos, frame,
              rot, cam)
    return pos, frame, rot, cam
