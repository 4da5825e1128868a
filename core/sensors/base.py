"""The protocol every sensor model follows, and algorithms written once for all of them.

Image coordinates: ``col`` (pixel, across track) and ``row`` (line, along track),
0-based with pixel centres at integers. Ground: WGS84 lon/lat degrees, ellipsoidal h metres.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.dem import GeoDEM
from core.errors import GeometryError, InputError

FloatArray = NDArray[np.float64]


@runtime_checkable
class SensorModel(Protocol):
    """What relative/absolute orientation, matching and ortho need from a sensor model."""

    def project(
        self, lon_deg: ArrayLike, lat_deg: ArrayLike, h_m: ArrayLike
    ) -> tuple[FloatArray, FloatArray]:
        """Ground (lon, lat, h) -> image (col, row)."""
        ...

    def localize(
        self, col: ArrayLike, row: ArrayLike, h_m: ArrayLike
    ) -> tuple[FloatArray, FloatArray]:
        """Image (col, row) at ellipsoidal height h -> ground (lon, lat)."""
        ...

    @property
    def params(self) -> FloatArray:
        """The adjustable parameter vector (zeros for an unadjusted model)."""
        ...

    def with_params(self, p: ArrayLike) -> SensorModel:
        """A new model with the adjustable parameters set to ``p``."""
        ...


def ray_height_step_m(model: SensorModel, col: FloatArray, row: FloatArray,
                      h_lo: float, h_hi: float, cell_m: float) -> float:
    """Height step along the line of sight that moves the ground point by <= half a DEM cell."""
    lon_a, lat_a = model.localize(col, row, np.full(col.shape, h_lo))
    lon_b, lat_b = model.localize(col, row, np.full(col.shape, h_hi))
    dy = (lat_b - lat_a) * 111_320.0
    dx = (lon_b - lon_a) * 111_320.0 * np.cos(np.radians(lat_a))
    horiz = float(np.nanmax(np.hypot(dx, dy))) / max(h_hi - h_lo, 1e-9)  # m per m of height
    if horiz <= 1e-6:
        return h_hi - h_lo
    return max(0.5 * cell_m / horiz, 0.05)


def localize_on_dem(
    model: SensorModel,
    col: ArrayLike,
    row: ArrayLike,
    dem: GeoDEM,
    *,
    h_range_m: tuple[float, float] | None = None,
    tol_m: float = 1e-3,
    max_iter: int = 60,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Intersect the lines of sight of image points with a DEM: (col, row) -> (lon, lat, h).

    Robust on steep slopes: the ray is marched down from above the highest terrain
    in height steps small enough that the ground point never moves more than half
    a DEM cell, the first crossing (the visible surface) is kept, then refined by
    bisection to ``tol_m``. Points whose ray never meets the DEM get NaN.
    """
    col = np.atleast_1d(np.asarray(col, dtype=np.float64))
    row = np.atleast_1d(np.asarray(row, dtype=np.float64))
    col, row = np.broadcast_arrays(col, row)
    shape = col.shape
    col, row = col.ravel(), row.ravel()
    if h_range_m is None:
        lo, hi = dem.height_range_m()
        if not np.isfinite(lo):
            raise InputError("the DEM holds no valid height; fill voids or choose another DEM")
        h_range_m = (lo - 10.0, hi + 10.0)
    h_lo, h_hi = map(float, h_range_m)
    if not h_hi > h_lo:
        raise InputError(f"height range {h_range_m} is empty; give (h_min, h_max) with h_min < h_max")
    step = ray_height_step_m(model, col, row, h_lo, h_hi, dem.cell_size_m())
    levels = np.linspace(h_hi, h_lo, int(np.ceil((h_hi - h_lo) / step)) + 1)

    def above(h: FloatArray, c: FloatArray, r: FloatArray) -> FloatArray:
        lon, lat = model.localize(c, r, h)
        return h - dem.height_m(lon, lat)  # >0 above ground, NaN off the DEM

    n = col.size
    found = np.zeros(n, dtype=bool)
    h_up = np.full(n, np.nan)
    h_dn = np.full(n, np.nan)
    prev_h = np.full(n, levels[0])
    prev_d = above(prev_h, col, row)
    for lev in levels[1:]:
        todo = ~found
        if not todo.any():
            break
        h = np.full(int(todo.sum()), lev)
        d = above(h, col[todo], row[todo])
        cross = (prev_d[todo] > 0) & (d <= 0)
        idx = np.flatnonzero(todo)[cross]
        h_up[idx] = prev_h[todo][cross]
        h_dn[idx] = lev
        found[idx] = True
        prev_h[todo] = lev
        prev_d[todo] = d
    if not found.any():
        raise GeometryError(
            "no line of sight meets the DEM; check that the DEM covers the image and that "
            "its heights are ellipsoidal (SRTM + geoid)"
        )
    k = np.flatnonzero(found)
    a, b = h_dn[k], h_up[k]  # a below ground, b above
    ck, rk = col[k], row[k]
    for _ in range(max_iter):
        m = 0.5 * (a + b)
        d = above(m, ck, rk)
        up = d > 0
        b = np.where(up, m, b)
        a = np.where(up, a, m)
        if np.max(b - a) <= tol_m:
            break
    h = np.full(n, np.nan)
    h[k] = 0.5 * (a + b)
    lon = np.full(n, np.nan)
    lat = np.full(n, np.nan)
    lon[k], lat[k] = model.localize(ck, rk, h[k])
    return lon.reshape(shape), lat.reshape(shape), h.reshape(shape)
