"""Compiled (Numba) RPC00B projection, the hot loop of :meth:`core.sensors.rpc.RPCModel.project`.

This module imports Numba, which takes a second or more: :mod:`core.sensors.rpc` imports it
inside the function that calls it, so ``gcpfree --help`` and every module import stay fast. The
kernel compiles on its first call and is cached on disk (``cache=True``); it is serial, releases
the GIL and is spread over the cores by :func:`core.parallel.run_split`.
"""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import NDArray

from core.parallel import run_split

FloatArray = NDArray[np.float64]


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
