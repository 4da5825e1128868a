"""Whole-DEM coregistration: the 3-D translation that aligns a DEM with a reference (Nuth & Kaab
2011, plus a vertical bias).

Both DEMs are regular north-up grids in one coordinate system: two :class:`core.dem.GeoDEM`
(degrees) or two :class:`core.dem.SurfaceGrid` (projected metres). The reference is sampled at
the DEM's nodes moved by the current horizontal shift (cubic spline, so sub-pixel shifts are
not blurred), and the height differences ``dh = ref - dem`` obey, to first order,

    dh / tan(slope) = e_east sin(aspect) + e_north cos(aspect) + dz / tan(slope)

with the aspect the direction of steepest descent (clockwise from north) and ``e`` the shift
still missing: a robust fit of the cosine gives ``e`` (with the slope squared as weight it is
the linear fit ``dh = -dz/de e_east - dz/dn e_north + dz`` on the reference's gradient), the
shift is updated, and so on until the next step would move it less than ``tol_px`` (the shift
is then the one the last ``dh`` were measured at). The vertical shift is the robust mean of
those ``dh``. Convention (the same as :mod:`core.matching.surface`): adding
``(dx, dy, dz)`` to the DEM's coordinates aligns it with the reference,
``ref(x + dx, y + dy) = dem(x, y) + dz``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import correlate1d, map_coordinates, spline_filter

from core.dem import GeoDEM, SurfaceGrid
from core.errors import ConvergenceError, InputError, InsufficientDataError
from core.geodesy import metres_per_degree
from core.robust import nmad

FloatArray = NDArray[np.float64]
DemGrid = GeoDEM | SurfaceGrid
STATS_SAMPLE = 100_000  # height differences the outlier cut of an iteration is measured on


@dataclass(frozen=True)
class CoregConfig:
    """Iterations, convergence (reference pixels), the slopes used (degrees) and the robust
    cut (in NMADs) of the height differences.

    ``tol_px``: the iterations stop once a step moves less than this, xdem's threshold (its
    ``NuthKaab(offset_threshold=0.001)``); on the SRTM tile a tenth of it moved the answer by
    1e-5 px for one iteration more."""

    max_iterations: int = 50
    tol_px: float = 1e-3
    min_slope_deg: float = 2.0
    max_slope_deg: float = 70.0
    outlier_nmad: float = 4.0
    min_points: int = 100

    def __post_init__(self) -> None:
        if not (0 <= self.min_slope_deg < self.max_slope_deg < 90 and self.tol_px > 0):
            raise InputError("need 0 <= min_slope_deg < max_slope_deg < 90 and tol_px > 0")


@dataclass(frozen=True)
class CoregResult:
    """The translation (adding it to the DEM aligns it with the reference) and the fit.

    ``shift_x``/``shift_y`` in the grids' units (degrees or metres), ``shift_east_m``,
    ``shift_north_m``, ``shift_up_m`` in metres, ``shift_col_px``/``shift_row_px`` in the
    reference's pixels; ``nmad_before_m``/``nmad_after_m`` of the height differences.
    """

    shift_x: float
    shift_y: float
    shift_east_m: float
    shift_north_m: float
    shift_up_m: float
    shift_col_px: float
    shift_row_px: float
    n_iterations: int
    n_points: int
    nmad_before_m: float
    nmad_after_m: float

    def to_dict(self) -> dict[str, Any]:
        return dict(vars(self))


def _bspline3_weights(t: float) -> FloatArray:
    """Weights of the cubic B-spline's taps -1, 0, 1, 2 at fraction ``t`` in [0, 1)."""
    return np.array([(1 - t) ** 3, 3 * t**3 - 6 * t**2 + 4, -3 * t**3 + 3 * t**2 + 3 * t + 1,
                     t**3]) / 6.0


def _translate_axis(a: FloatArray, offset: float, n_out: int, axis: int, order: int
                    ) -> FloatArray:
    """``out[k] = sum_m w_m a[k + floor(offset) + m]`` along ``axis`` for ``k < n_out``: the
    spline (``order`` 3: coefficients, taps -1..2) or linear (``order`` 1, taps 0, 1) value of
    ``a`` at ``k + offset``, one pass of :func:`scipy.ndimage.correlate1d`. Where a tap falls
    beyond ``a``'s ends its edge stands in: such points lie outside the reference's interior,
    which :class:`_Sampler` masks."""
    k0 = int(np.floor(offset))
    t = offset - k0
    w = _bspline3_weights(t) if order == 3 else np.array([1.0 - t, t])
    full = correlate1d(a, w, axis=axis, mode="nearest", origin=-1)  # taps from k - 1 (k)
    n = a.shape[axis]
    if 0 <= k0 and k0 + n_out <= n:
        return full[k0:k0 + n_out] if axis == 0 else full[:, k0:k0 + n_out]
    return np.take(full, np.clip(np.arange(n_out) + k0, 0, n - 1), axis=axis)


class _Sampler:
    """Cubic-spline samples of the reference (voids: NaN near them)."""

    def __init__(self, ref: DemGrid) -> None:
        z = np.asarray(ref.values, dtype=np.float64)
        self.void = ~np.isfinite(z)
        self.void_f = self.void.astype(np.float64)
        filled = np.where(self.void, np.nanmean(z) if np.isfinite(z).any() else 0.0, z)
        self.coeffs = spline_filter(filled, order=3, mode="mirror")
        self.ref = ref

    def _masked(self, v: FloatArray, near_void: FloatArray, fi: FloatArray, fj: FloatArray
                ) -> FloatArray:
        nr, nc = self.ref.shape
        inside = (fi >= 1) & (fi <= nr - 2) & (fj >= 1) & (fj <= nc - 2)
        return np.where(inside & (near_void == 0), v, np.nan)

    def __call__(self, x: FloatArray, y: FloatArray) -> FloatArray:
        fi, fj = self.ref.indices(x, y)
        v = map_coordinates(self.coeffs, [fi.ravel(), fj.ravel()], order=3, mode="mirror",
                            prefilter=False).reshape(fi.shape)
        near_void = map_coordinates(self.void_f, [fi.ravel(), fj.ravel()],
                                    order=1, mode="constant", cval=1.0).reshape(fi.shape)
        return self._masked(v, near_void, fi, fj)

    def translated(self, row0: float, col0: float, shape: tuple[int, int]) -> FloatArray:
        """The same samples as :meth:`__call__` at the reference's fractional (row, col)
        ``(row0 + i, col0 + j)`` for ``i, j`` over ``shape``: the nodes of a grid with the
        reference's steps, moved. A separable filter of four taps per axis instead of a
        16-tap look-up per point (:func:`scipy.ndimage.map_coordinates`)."""
        nr, nc = shape
        v = _translate_axis(_translate_axis(self.coeffs, row0, nr, 0, 3), col0, nc, 1, 3)
        if self.void.any():
            near_void = _translate_axis(_translate_axis(self.void_f, row0, nr, 0, 1),
                                        col0, nc, 1, 1)
        else:  # beyond the reference is outside anyway
            near_void = np.zeros(shape)
        fi = (row0 + np.arange(nr, dtype=np.float64))[:, None]
        fj = (col0 + np.arange(nc, dtype=np.float64))[None, :]
        return self._masked(v, near_void, fi, fj)


def _same_steps(a: DemGrid, b: DemGrid) -> bool:
    return all(abs(p - q) <= 1e-9 * abs(q) for p, q in zip(a.axes[2:], b.axes[2:], strict=True))


def _weighted_median(values: FloatArray, counts: FloatArray) -> float:
    """The median of a sample holding ``counts[k]`` copies of ``values[k]`` (as
    ``np.median`` of the repeated values)."""
    order = np.argsort(values)
    v, c = values[order], np.cumsum(counts[order])
    n = c[-1]
    lo = v[np.searchsorted(c, (n - 1) // 2, side="right")]
    hi = v[np.searchsorted(c, n // 2, side="right")]
    return float(0.5 * (lo + hi))


def nuth_kaab(reference: DemGrid, dem: DemGrid, config: CoregConfig = CoregConfig()
              ) -> CoregResult:
    """The translation aligning ``dem`` with ``reference``: two :class:`~core.dem.GeoDEM`
    (lon/lat degrees) or two :class:`~core.dem.SurfaceGrid` (projected metres), each of at
    least 4x4 cells.

    Each iteration fits, by least squares on the cells of usable slope whose height
    difference lies within ``outlier_nmad`` NMADs of the median, the first-order model
    ``dh = -dz/de * e_east - dz/dn * e_north + dz`` (Nuth & Kaab's cosine of the aspect
    weighted by the slope squared, written without the angles). When the DEM's grid has the
    reference's steps (a DEM read onto the reference's grid), the reference is resampled by a
    separable filter (:meth:`_Sampler.translated`), the same values as the general look-up.
    """
    if reference.geographic != dem.geographic:
        raise InputError("the DEM and the reference must both be geographic or both projected; "
                         "reproject one onto the other's CRS first")
    for g in (reference, dem):
        if min(g.shape) < 4:
            raise InputError(f"a DEM grid needs at least 4x4 cells, got {g.shape}")
    sample = _Sampler(reference)
    z = np.asarray(dem.values, dtype=np.float64)
    x0, y0, dem_dx, dem_dy = dem.axes
    ref_dx, ref_dy = reference.axes[2:]
    row0, col0 = (float(v) for v in reference.indices(x0, y0))
    if _same_steps(dem, reference):
        def sample_at(sx: float, sy: float) -> FloatArray:
            return sample.translated(row0 + sy / ref_dy, col0 + sx / ref_dx, z.shape)
    else:
        x, y = dem.nodes()

        def sample_at(sx: float, sy: float) -> FloatArray:
            return sample(x + sx, y + sy)
    # metres per grid unit, by row (latitude) for degrees
    lat_rows = y0 + dem_dy * np.arange(z.shape[0], dtype=np.float64)
    if dem.geographic:
        mx_rows, my_rows = metres_per_degree(lat_rows)
    else:
        mx_rows, my_rows = np.ones_like(lat_rows), np.ones_like(lat_rows)
    mx, my = mx_rows[:, None], my_rows[:, None]
    tan2_min, tan2_max = np.tan(np.radians([config.min_slope_deg, config.max_slope_deg])) ** 2
    sx = sy = 0.0
    step_px = np.inf
    nmad_before = None
    for iteration in range(1, config.max_iterations + 1):
        ref = sample_at(sx, sy)
        dh = ref - z
        # slope of the reference where the DEM lies: dz/d(east), dz/d(north), per metre
        g_n, g_e = np.gradient(ref, dem_dy, dem_dx)  # per grid unit
        if dem.geographic:
            g_e /= mx
            g_n /= my
        tan2_slope = g_e * g_e + g_n * g_n
        with np.errstate(invalid="ignore"):  # NaN slopes next to voids fail both tests
            ok = (tan2_slope > tan2_min) & (tan2_slope < tan2_max) & np.isfinite(dh)
        cells = np.flatnonzero(ok)
        if cells.size < config.min_points:
            raise InsufficientDataError(
                f"only {cells.size} cells of the DEM overlap the reference on usable slopes "
                f"({config.min_points} needed); check that the two DEMs cover the same area")
        d = dh.ravel()[cells]
        if nmad_before is None:
            nmad_before = nmad(d)
        # the outlier cut from a regular sample of at most about STATS_SAMPLE differences
        # (the median of 1e5 values is within 0.4 % of a sigma of the whole one's)
        sample_d = d[::max(1, d.size // STATS_SAMPLE)]
        med = float(np.median(sample_d))
        keep = np.abs(d - med) < config.outlier_nmad * max(nmad(sample_d, med), 1e-6)
        cells, d = cells[keep], d[keep]
        ge, gn = g_e.ravel()[cells], g_n.ravel()[cells]
        # least squares of d = -ge e_east - gn e_north + dz: its normal equations
        sum_e, sum_n = ge.sum(), gn.sum()
        normal = np.array([[ge @ ge, ge @ gn, -sum_e], [ge @ gn, gn @ gn, -sum_n],
                           [-sum_e, -sum_n, float(d.size)]])
        de, dn, _ = np.linalg.lstsq(normal, np.array([-(ge @ d), -(gn @ d), d.sum()]),
                                    rcond=None)[0]
        if dem.geographic:  # the metres back to degrees, at the median scale of the cells used
            rows_used = ok.sum(axis=1).astype(np.float64)
            ddx = de / _weighted_median(mx_rows, rows_used)
            ddy = dn / _weighted_median(my_rows, rows_used)
        else:
            ddx, ddy = de, dn
        step_px = max(abs(ddx / ref_dx), abs(ddy / ref_dy))
        if step_px < config.tol_px:  # converged: the shift stays where dh was just measured
            break
        sx, sy = sx + ddx, sy + ddy
    else:
        raise ConvergenceError(
            f"coregistration did not converge in {config.max_iterations} iterations (last step "
            f"{step_px:.2g} px); the DEMs may differ too much or be too flat")
    dh = dh[np.isfinite(dh)]
    med = float(np.median(dh))
    nm = nmad(dh, med)
    keep = np.abs(dh - med) < config.outlier_nmad * max(nm, 1e-6)
    dz = float(np.mean(dh[keep]))
    if dem.geographic:
        yc = float(np.median(lat_rows))
        me, mn = (float(v) for v in metres_per_degree(yc))
    else:
        me = mn = 1.0
    return CoregResult(
        shift_x=float(sx), shift_y=float(sy), shift_east_m=float(sx * me),
        shift_north_m=float(sy * mn), shift_up_m=dz, shift_col_px=float(sx / ref_dx),
        shift_row_px=float(sy / ref_dy), n_iterations=iteration, n_points=int(dh.size),
        nmad_before_m=float(nmad_before), nmad_after_m=nmad(dh[keep]))
