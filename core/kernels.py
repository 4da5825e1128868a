"""Compiled (Numba) kernels of the hot loops: RPC00B projection, the orbit's interpolation
and local frames, the ortho lattice interpolation and image resampling.

This module imports Numba, which takes a second or more: the modules that use it
(:mod:`core.sensors.rpc`, :mod:`core.sensors.orbit`, :mod:`core.ortho`) import it inside the
functions that call it, so ``gcpfree --help`` and every module import stay fast. Each kernel compiles on its first call
and is cached on disk (``cache=True``), so a later process only loads it.

The kernels are serial and release the GIL (``nogil=True``); :func:`run_split` spreads one
large call over the cores with plain threads, which stays safe when several threads (Dask's
tile workers) call kernels at once and after a fork, unlike Numba's own thread pools.

Conventions are those of the callers: image positions are fractional (row, col) indices of
the source array, 0-based, pixel centres at integers; NaN marks missing values.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable

import numba
import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

MIN_SPLIT = 65_536  # elements per thread below which a call stays on one thread
_CORES = os.cpu_count() or 1


def run_split(kernel: Callable[..., None], n: int, *args: object,
              min_split: int = MIN_SPLIT) -> None:
    """Run ``kernel(*args, start, stop)`` over ``0 .. n`` in contiguous parts, one thread each
    (as many as the cores and ``n / min_split`` allow; the calling thread takes a part)."""
    k = 1 if n < 2 * min_split else max(1, min(_CORES, n // max(min_split, 1)))
    if k == 1:
        kernel(*args, 0, n)
        return
    bounds = [n * i // k for i in range(k + 1)]
    threads = [threading.Thread(target=kernel, args=(*args, bounds[i], bounds[i + 1]))
               for i in range(1, k)]
    for t in threads:
        t.start()
    try:
        kernel(*args, bounds[0], bounds[1])
    finally:
        for t in threads:
            t.join()


# ---------------------------------------------------------------------------- RPC00B


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _cubic20(c: tuple[float, ...], x: float, y: float, z: float, xy: float, xz: float,
             yz: float, xx: float, yy: float, zz: float) -> float:
    """One cubic on the RPC00B monomials (order of :mod:`core.sensors.rpc`); ``c`` is a tuple
    of 20 values, so the compiler keeps them in registers across the loop."""
    return (c[0] + c[1] * x + c[2] * y + c[3] * z + c[4] * xy + c[5] * xz + c[6] * yz
            + c[7] * xx + c[8] * yy + c[9] * zz + c[10] * xy * z + c[11] * xx * x
            + c[12] * x * yy + c[13] * x * zz + c[14] * xx * y + c[15] * yy * y
            + c[16] * y * zz + c[17] * xx * z + c[18] * yy * z + c[19] * zz * z)


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _rpc_project_range(col_num: tuple[float, ...], col_den: tuple[float, ...],
                       row_num: tuple[float, ...], row_den: tuple[float, ...],
                       norm: tuple[float, ...], lon: FloatArray, lat: FloatArray,
                       h: FloatArray, col: FloatArray, row: FloatArray, start: int,
                       stop: int) -> None:
    lon_off, lat_off, alt_off = norm[0], norm[1], norm[2]
    ilon, ilat, ialt = 1.0 / norm[3], 1.0 / norm[4], 1.0 / norm[5]
    col_scale, col_off, row_scale, row_off = norm[6], norm[7], norm[8], norm[9]
    a00, a01, a10, a11, t0, t1 = norm[10], norm[11], norm[12], norm[13], norm[14], norm[15]
    biased = norm[16] != 0.0
    for i in range(start, stop):
        x = (lon[i] - lon_off) * ilon
        y = (lat[i] - lat_off) * ilat
        z = (h[i] - alt_off) * ialt
        xy, xz, yz, xx, yy, zz = x * y, x * z, y * z, x * x, y * y, z * z
        col[i] = (_cubic20(col_num, x, y, z, xy, xz, yz, xx, yy, zz)
                  / _cubic20(col_den, x, y, z, xy, xz, yz, xx, yy, zz)) * col_scale + col_off
        row[i] = (_cubic20(row_num, x, y, z, xy, xz, yz, xx, yy, zz)
                  / _cubic20(row_den, x, y, z, xy, xz, yz, xx, yy, zz)) * row_scale + row_off
    if biased:
        for i in range(start, stop):
            c, r = col[i], row[i]
            col[i] = a00 * c + a01 * r + t0
            row[i] = a10 * c + a11 * r + t1


def rpc_project(coeffs: FloatArray, lon: FloatArray, lat: FloatArray, h: FloatArray,
                ground: FloatArray, image: FloatArray) -> tuple[FloatArray, FloatArray]:
    """RPC00B projection of 1-D ground points (degrees, metres) to biased image (col, row).

    ``coeffs`` (4, 20): col_num, col_den, row_num, row_den; ``ground``: lon_off, lat_off,
    alt_off, lon_scale, lat_scale, alt_scale; ``image``: col_scale, col_off, row_scale,
    row_off, then the bias ``A`` (a00, a01, a10, a11) and ``t`` (t0, t1) with
    ``biased = A @ (col, row) + t``, then 1.0 to apply it (0.0: no bias).
    """
    n = lon.size
    col, row = np.empty(n), np.empty(n)
    polys = tuple(tuple(float(v) for v in c) for c in np.asarray(coeffs, dtype=np.float64))
    norm = tuple(float(v) for v in (*ground, *image))
    run_split(_rpc_project_range, n, *polys, norm,
              *(np.ascontiguousarray(a, dtype=np.float64) for a in (lon, lat, h)), col, row)
    return col, row


# ---------------------------------------------------------------------------- orbits


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


# ---------------------------------------------------------------------------- lattices


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _along_cols(nodes: FloatArray, col_taps: NDArray[np.intp], col_w: FloatArray
                ) -> FloatArray:
    """(F, ny, nx) node values interpolated along the columns: (F, ny, n_cols)."""
    n_f, ny, _ = nodes.shape
    n_cols = col_taps.shape[0]
    tmp = np.empty((n_f, ny, n_cols))
    for f in range(n_f):
        for a in range(ny):
            for j in range(n_cols):
                tmp[f, a, j] = (col_w[j, 0] * nodes[f, a, col_taps[j, 0]]
                                + col_w[j, 1] * nodes[f, a, col_taps[j, 1]]
                                + col_w[j, 2] * nodes[f, a, col_taps[j, 2]]
                                + col_w[j, 3] * nodes[f, a, col_taps[j, 3]])
    return tmp


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _upsample(nodes: FloatArray, row_taps: NDArray[np.intp], row_w: FloatArray,
              col_taps: NDArray[np.intp], col_w: FloatArray) -> FloatArray:
    tmp = _along_cols(nodes, col_taps, col_w)
    n_f, n_rows, n_cols = nodes.shape[0], row_taps.shape[0], col_taps.shape[0]
    out = np.empty((n_f, n_rows, n_cols))
    for f in range(n_f):
        for i in range(n_rows):
            t0, t1, t2, t3 = row_taps[i, 0], row_taps[i, 1], row_taps[i, 2], row_taps[i, 3]
            w0, w1, w2, w3 = row_w[i, 0], row_w[i, 1], row_w[i, 2], row_w[i, 3]
            for j in range(n_cols):
                out[f, i, j] = (w0 * tmp[f, t0, j] + w1 * tmp[f, t1, j] + w2 * tmp[f, t2, j]
                                + w3 * tmp[f, t3, j])
    return out


def upsample(nodes: FloatArray, row_taps: NDArray[np.intp], row_w: FloatArray,
             col_taps: NDArray[np.intp], col_w: FloatArray) -> FloatArray:
    """Node values (F, ny, nx) interpolated at every cell, (F, n_rows, n_cols): a separable
    4-tap filter, cell ``i`` of the rows taking ``sum_a row_w[i, a] * nodes[row_taps[i, a]]``
    (the same along the columns)."""
    return _upsample(np.ascontiguousarray(nodes, dtype=np.float64), row_taps, row_w, col_taps,
                     col_w)


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _image_position(coeffs: FloatArray, row_taps: NDArray[np.intp], row_w: FloatArray,
                    col_taps: NDArray[np.intp], col_w: FloatArray, h: FloatArray,
                    h_mid: float, h_half: float) -> tuple[FloatArray, FloatArray]:
    n_terms = coeffs.shape[0] // 2
    tmp = _along_cols(coeffs, col_taps, col_w)
    n_rows, n_cols = h.shape
    col = np.empty((n_rows, n_cols))
    row = np.empty((n_rows, n_cols))
    cf = np.empty((coeffs.shape[0], n_cols))  # one row of cells' coefficients
    u = np.empty(n_cols)
    for i in range(n_rows):
        t0, t1, t2, t3 = row_taps[i, 0], row_taps[i, 1], row_taps[i, 2], row_taps[i, 3]
        w0, w1, w2, w3 = row_w[i, 0], row_w[i, 1], row_w[i, 2], row_w[i, 3]
        for k in range(coeffs.shape[0]):
            for j in range(n_cols):
                cf[k, j] = (w0 * tmp[k, t0, j] + w1 * tmp[k, t1, j] + w2 * tmp[k, t2, j]
                            + w3 * tmp[k, t3, j])
        for j in range(n_cols):
            u[j] = (h[i, j] - h_mid) / h_half
        for o in range(2):
            out = col if o == 0 else row
            top = o * n_terms + n_terms - 1
            for j in range(n_cols):
                out[i, j] = cf[top, j]
            for k in range(top - 1, o * n_terms - 1, -1):
                for j in range(n_cols):
                    out[i, j] = out[i, j] * u[j] + cf[k, j]
    return col, row


def image_position(coeffs: FloatArray, row_taps: NDArray[np.intp], row_w: FloatArray,
                   col_taps: NDArray[np.intp], col_w: FloatArray, h: FloatArray,
                   h_mid: float, h_half: float) -> tuple[FloatArray, FloatArray]:
    """Image (col, row) of every cell from height polynomials on a lattice.

    ``coeffs`` (2, d + 1, ny, nx): at each node, col and row as polynomials in
    ``u = (h - h_mid) / h_half`` (increasing powers); they are interpolated at each cell (the
    separable filter of :func:`upsample`) and evaluated at the cell's height ``h``
    (n_rows, n_cols); NaN where ``h`` is NaN.
    """
    c = np.ascontiguousarray(coeffs, dtype=np.float64)
    return _image_position(c.reshape(-1, *c.shape[2:]), row_taps, row_w, col_taps, col_w,
                           np.ascontiguousarray(h, dtype=np.float64), float(h_mid),
                           float(h_half))


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _cell_heights(nodes: FloatArray, row_taps: NDArray[np.intp], row_w: FloatArray,
                  col_taps: NDArray[np.intp], col_w: FloatArray, z: NDArray) -> FloatArray:
    tmp = _along_cols(nodes, col_taps, col_w)
    n_rows, n_cols = row_taps.shape[0], col_taps.shape[0]
    h = np.empty((n_rows, n_cols))
    buf = np.empty((3, n_cols))
    for i in range(n_rows):
        t0, t1, t2, t3 = row_taps[i, 0], row_taps[i, 1], row_taps[i, 2], row_taps[i, 3]
        w0, w1, w2, w3 = row_w[i, 0], row_w[i, 1], row_w[i, 2], row_w[i, 3]
        for f in range(3):
            for j in range(n_cols):
                buf[f, j] = (w0 * tmp[f, t0, j] + w1 * tmp[f, t1, j] + w2 * tmp[f, t2, j]
                             + w3 * tmp[f, t3, j])
        for j in range(n_cols):
            h[i, j] = _bilinear_at(z, buf[0, j], buf[1, j]) + buf[2, j]
    return h


def cell_heights(nodes: FloatArray, row_taps: NDArray[np.intp], row_w: FloatArray,
                 col_taps: NDArray[np.intp], col_w: FloatArray, z: NDArray) -> FloatArray:
    """Heights of every cell from a DEM ``z`` and lattice nodes (3, ny, nx) holding the DEM's
    fractional row and column indices and the height to add (geoid undulation): the three
    interpolated at the cell (:func:`upsample`), then ``bilinear(z, fi, fj) + n``
    (:func:`bilinear`), without storing the interpolated indices."""
    return _cell_heights(np.ascontiguousarray(nodes, dtype=np.float64), row_taps, row_w,
                         col_taps, col_w, np.ascontiguousarray(z))


# ---------------------------------------------------------------------------- resampling


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _bilinear_at(src: NDArray, i: float, j: float) -> float:
    n_r, n_c = src.shape
    if not (i >= 0.0 and i <= n_r - 1 and j >= 0.0 and j <= n_c - 1):
        return np.nan
    i0, j0 = int(np.floor(i)), int(np.floor(j))
    di, dj = i - i0, j - j0
    i1, j1 = min(i0 + 1, n_r - 1), min(j0 + 1, n_c - 1)
    top = (1.0 - dj) * src[i0, j0] + dj * src[i0, j1]
    bottom = (1.0 - dj) * src[i1, j0] + dj * src[i1, j1]
    return (1.0 - di) * top + di * bottom


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _bilinear(src: NDArray, fi: FloatArray, fj: FloatArray, out: FloatArray) -> None:
    for k in range(fi.size):
        out[k] = _bilinear_at(src, fi[k], fj[k])


def bilinear(src: NDArray, fi: FloatArray, fj: FloatArray) -> FloatArray:
    """Bilinear value of ``src`` (2-D, any real type) at fractional (row, col) indices; NaN
    outside ``[0, n - 1]`` and where any of the 4 taps is NaN (a tap of weight 0 included, as
    ``scipy.ndimage.map_coordinates(order=1)`` does). Output of the indices' shape."""
    fi, fj = np.broadcast_arrays(np.asarray(fi, dtype=np.float64),
                                 np.asarray(fj, dtype=np.float64))
    out = np.empty(fi.shape)
    _bilinear(np.ascontiguousarray(src), np.ascontiguousarray(fi).ravel(),
              np.ascontiguousarray(fj).ravel(), out.reshape(-1))
    return out


NEAREST, BILINEAR, CUBIC = 0, 1, 2
"""Resampling kernels of :func:`resample_window`."""


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _tap(src: NDArray, i: int, j: int, nodata: float, has_nodata: bool) -> float:
    """Pixel (i, j) of ``src``, indices clamped to the array (edges repeated), NaN when it
    equals ``nodata``."""
    i = min(max(i, 0), src.shape[0] - 1)
    j = min(max(j, 0), src.shape[1] - 1)
    v = float(src[i, j])
    if has_nodata and v == nodata:
        return np.nan
    return v


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _keys(t: float) -> tuple[float, float, float, float]:
    t2 = t * t
    t3 = t2 * t
    return (0.5 * (-t3 + 2 * t2 - t), 0.5 * (3 * t3 - 5 * t2 + 2),
            0.5 * (-3 * t3 + 4 * t2 + t), 0.5 * (t3 - t2))


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _resample_window(src: NDArray, col: FloatArray, row: FloatArray, col0: float,
                     row0: float, factor: int, width: float, height: float, nodata: float,
                     has_nodata: bool, kind: int, pad: int, out: FloatArray) -> None:
    shift = 0.5 * (factor - 1)
    for k in range(col.size):
        c, r = col[k], row[k]
        if not (c >= -0.5 and c <= width - 0.5 and r >= -0.5 and r <= height - 0.5):
            out[k] = np.nan
            continue
        # positions in the window padded by ``pad`` (the NumPy kernels' arithmetic), then
        # back to window indices: clamping repeats the window's edges as the padding did
        lc = (c - col0 - shift) / factor + pad
        lr = (r - row0 - shift) / factor + pad
        if kind == 0:
            out[k] = _tap(src, int(np.floor(lr + 0.5)) - pad, int(np.floor(lc + 0.5)) - pad,
                          nodata, has_nodata)
        elif kind == 1:
            if not (lr >= 0.0 and lr <= src.shape[0] + 2 * pad - 1
                    and lc >= 0.0 and lc <= src.shape[1] + 2 * pad - 1):
                out[k] = np.nan  # off the padded window (the NumPy sampler's rule)
                continue
            fi, fj = np.floor(lr), np.floor(lc)
            di, dj = lr - fi, lc - fj
            i0, j0 = int(fi) - pad, int(fj) - pad
            top = ((1.0 - dj) * _tap(src, i0, j0, nodata, has_nodata)
                   + dj * _tap(src, i0, j0 + 1, nodata, has_nodata))
            bottom = ((1.0 - dj) * _tap(src, i0 + 1, j0, nodata, has_nodata)
                      + dj * _tap(src, i0 + 1, j0 + 1, nodata, has_nodata))
            out[k] = (1.0 - di) * top + di * bottom
        else:
            fi, fj = np.floor(lr), np.floor(lc)
            wi, wj = _keys(lr - fi), _keys(lc - fj)
            i0, j0 = int(fi) - pad, int(fj) - pad
            acc = 0.0
            for a in range(4):
                s = 0.0
                for b in range(4):
                    s += wj[b] * _tap(src, i0 + a - 1, j0 + b - 1, nodata, has_nodata)
                acc += wi[a] * s
            out[k] = acc


def resample_window(src: NDArray, col: FloatArray, row: FloatArray, origin: tuple[int, int],
                    factor: int, image_size: tuple[int, int], nodata: float | None,
                    kind: int, pad: int) -> FloatArray:
    """Image values at image positions (col, row) from ``src``, the window of the image whose
    sample (0, 0) averages the ``factor x factor`` pixels from ``origin`` = (col0, row0).

    NaN where the position is NaN or outside the image footprint (``image_size`` (cols,
    rows), pixel edges at -0.5 and n - 0.5), or where a tap of the kernel (``kind``:
    :data:`NEAREST`, :data:`BILINEAR`, :data:`CUBIC` with Keys' a = -0.5) equals ``nodata``
    (NaN taps give NaN too). Taps beyond the window repeat its edges. ``pad`` only fixes the
    rounding: positions are computed in the window padded by ``pad``, as the NumPy kernels
    did. Output of the positions' shape.
    """
    col, row = np.broadcast_arrays(np.asarray(col, dtype=np.float64),
                                   np.asarray(row, dtype=np.float64))
    out = np.empty(col.shape)
    has_nodata = nodata is not None and not np.isnan(nodata)
    _resample_window(np.ascontiguousarray(src), np.ascontiguousarray(col).ravel(),
                     np.ascontiguousarray(row).ravel(), float(origin[0]), float(origin[1]),
                     int(factor), float(image_size[0]), float(image_size[1]),
                     float(nodata) if has_nodata else 0.0, has_nodata, int(kind), int(pad),
                     out.reshape(-1))
    return out


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _footprint_bounds(col: FloatArray, row: FloatArray, width: float, height: float
                      ) -> tuple[int, float, float, float, float]:
    n = 0
    c_lo, c_hi, r_lo, r_hi = np.inf, -np.inf, np.inf, -np.inf
    for k in range(col.size):
        c, r = col[k], row[k]
        if c >= -0.5 and c <= width - 0.5 and r >= -0.5 and r <= height - 0.5:
            n += 1
            c_lo, c_hi = min(c_lo, c), max(c_hi, c)
            r_lo, r_hi = min(r_lo, r), max(r_hi, r)
    return n, c_lo, c_hi, r_lo, r_hi


def footprint_bounds(col: FloatArray, row: FloatArray, image_size: tuple[int, int]
                     ) -> tuple[int, float, float, float, float]:
    """How many positions fall in the image footprint (``image_size`` (cols, rows), edges at
    -0.5 and n - 0.5; NaN never does) and their (col_min, col_max, row_min, row_max)."""
    return _footprint_bounds(np.ascontiguousarray(col, dtype=np.float64).ravel(),
                             np.ascontiguousarray(row, dtype=np.float64).ravel(),
                             float(image_size[0]), float(image_size[1]))


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _to_integer(values: FloatArray, out: NDArray, lo: float, hi: float, nodata: float,
                has_nodata: bool, bump: float) -> None:
    for k in range(values.size):
        v = values[k]
        if np.isnan(v):
            out[k] = nodata if has_nodata else 0.0
            continue
        r = min(max(np.rint(v), lo), hi)
        if has_nodata and r == nodata:
            r = nodata + bump
        out[k] = r


def to_integer(values: FloatArray, dtype: np.dtype, nodata: float | None) -> NDArray:
    """Values as an integer type: rounded half to even, clipped to the type's range, a valid
    value equal to ``nodata`` moved one step off it, NaN written as ``nodata`` (0 without
    one)."""
    info = np.iinfo(dtype)
    values = np.ascontiguousarray(values, dtype=np.float64)
    out = np.empty(values.shape, dtype)
    has_nodata = nodata is not None and not np.isnan(nodata)
    bump = 1.0 if has_nodata and nodata < info.max else -1.0
    _to_integer(values.reshape(-1), out.reshape(-1), float(info.min), float(info.max),
                float(nodata) if has_nodata else 0.0, has_nodata, bump)
    return out
