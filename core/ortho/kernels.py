"""Compiled (Numba) kernels of the orthorectification: the ortho lattice's interpolation
(nodes upsampled to cells, image positions, cell heights) and the image resampling.

This module imports Numba: :mod:`core.ortho.ortho` imports it inside the functions that call it,
so module imports stay fast. Kernels compile on their first call and are cached on disk; they are
serial, release the GIL and are spread over the cores by :func:`core.parallel.run_split`.

Conventions are those of the callers: image positions are fractional (row, col) indices of the
source array, 0-based, pixel centres at integers; NaN marks missing values.
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


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
