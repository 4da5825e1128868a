"""The protocol every sensor model follows, and algorithms written once for all of them.

Image coordinates: ``col`` (pixel, across track) and ``row`` (line, along track),
0-based with pixel centres at integers. Ground: WGS84 lon/lat degrees, ellipsoidal h metres.

The adjustments (relative and absolute orientation) see a model only through this protocol:
``param_names``/``params`` name and hold the adjustable corrections, ``with_params`` returns a
new model with other values, ``jacobian`` gives d(col, row)/d(params). They never ask which
sensor family they hold.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.choices import CORRECTIONS, Corrections
from core.dem import GeoDEM, first_crossing, march_levels
from core.errors import GeometryError, InputError
from core.geodesy import metres_per_degree

FloatArray = NDArray[np.float64]
#: the correction families a model adds to itself (``with_corrections``), as core.choices names
CorrectionKind = Corrections
CORRECTION_KINDS = CORRECTIONS


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
    def param_names(self) -> tuple[str, ...]:
        """Names of the adjustable parameters, in the order of ``params``."""
        ...

    @property
    def params(self) -> FloatArray:
        """The adjustable parameter vector (zeros for an unadjusted model)."""
        ...

    def with_params(self, p: ArrayLike) -> SensorModel:
        """A new model with the adjustable parameters set to ``p``."""
        ...

    def jacobian(self, lon_deg: ArrayLike, lat_deg: ArrayLike, h_m: ArrayLike) -> FloatArray:
        """d(col, row)/d(params) at ground points: shape (n, 2, len(params)), pixels per unit."""
        ...

    @property
    def param_units(self) -> tuple[str, ...]:
        """The unit of each parameter (``"rad"``, ``"rad/s"``, ``"m"``, ``"px"``...)."""
        ...

    def with_corrections(self, kind: CorrectionKind) -> SensorModel:
        """The model with the adjustable corrections of ``kind``: ``"offset"`` (pushbroom:
        attitude biases; RPC: an image shift) or ``"linear"`` (pushbroom: biases and rates;
        RPC: an affine), keeping the current values where they carry over."""
        ...


def numeric_jacobian(
    model: SensorModel, lon_deg: ArrayLike, lat_deg: ArrayLike, h_m: ArrayLike,
    steps: ArrayLike,
) -> FloatArray:
    """d(col, row)/d(params) by fourth-order central differences (steps +-s, +-2s) of ``project``.

    ``steps`` holds one step per parameter, in the parameter's unit; choose steps that move the
    image point by about a pixel. Shape (n, 2, p). The fallback for models without an analytic
    Jacobian, and the check of those that have one.
    """
    lon, lat, h = (np.ravel(a) for a in np.broadcast_arrays(
        np.asarray(lon_deg, dtype=np.float64), np.asarray(lat_deg, dtype=np.float64),
        np.asarray(h_m, dtype=np.float64)))
    p0 = np.asarray(model.params, dtype=np.float64)
    steps = np.asarray(steps, dtype=np.float64).ravel()
    if steps.shape != p0.shape or not np.all(steps > 0):
        raise InputError(f"numeric_jacobian needs {p0.size} positive steps, got {steps.tolist()}")
    out = np.empty((lon.size, 2, p0.size))
    for k in range(p0.size):
        val = []
        for mult in (1.0, -1.0, 2.0, -2.0):
            dp = np.zeros_like(p0)
            dp[k] = mult * steps[k]
            val.append(np.stack(model.with_params(p0 + dp).project(lon, lat, h), axis=1))
        out[:, :, k] = (8.0 * (val[0] - val[1]) - (val[2] - val[3])) / (12.0 * steps[k])
    return out


def ray_ground_move_per_m(model: SensorModel, col: FloatArray, row: FloatArray,
                          h_lo: float, h_hi: float) -> float:
    """Largest horizontal move (m) of the ground point per metre of height along the rays."""
    lon_a, lat_a = model.localize(col, row, np.full(col.shape, h_lo))
    lon_b, lat_b = model.localize(col, row, np.full(col.shape, h_hi))
    m_lon, m_lat = metres_per_degree(lat_a)
    horiz = np.hypot((lon_b - lon_a) * m_lon, (lat_b - lat_a) * m_lat)
    return float(np.nanmax(horiz)) / max(h_hi - h_lo, 1e-9)


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

    Robust on steep slopes (:func:`core.dem.first_crossing`): the ray is marched down from
    above the highest terrain in height steps small enough that the ground point never moves
    more than half a DEM cell, the first crossing (the visible surface) is kept, then refined by
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
        raise InputError(
            f"height range {h_range_m} is empty; give (h_min, h_max) with h_min < h_max")
    move = ray_ground_move_per_m(model, col, row, h_lo, h_hi)
    levels = march_levels(h_hi, h_lo, move, dem.cell_size_m(), min_step_m=0.05)

    def above(h: FloatArray, idx: NDArray[np.intp]) -> FloatArray:
        lon, lat = model.localize(col[idx], row[idx], h)
        return h - dem.height_m(lon, lat)  # >0 above ground, NaN off the DEM

    h = first_crossing(above, col.size, levels, tol_m=tol_m, max_bisections=max_iter)
    k = np.flatnonzero(np.isfinite(h))
    if k.size == 0:
        raise GeometryError(
            "no line of sight meets the DEM; check that the DEM covers the image and that "
            "its heights are ellipsoidal (SRTM + geoid)"
        )
    lon = np.full(col.size, np.nan)
    lat = np.full(col.size, np.nan)
    lon[k], lat[k] = model.localize(col[k], row[k], h[k])
    return lon.reshape(shape), lat.reshape(shape), h.reshape(shape)
