"""Whole-DEM coregistration: the 3-D translation that aligns a DEM with a reference (Nuth & Kaab
2011, plus a vertical bias).

Both DEMs are regular north-up grids in one coordinate system: two :class:`core.dem.GeoDEM`
(degrees) or two :class:`core.dem.SurfaceGrid` (projected metres). The reference is sampled at
the DEM's nodes moved by the current horizontal shift (cubic spline, so sub-pixel shifts are
not blurred), and the height differences ``dh = ref - dem`` obey, to first order,

    dh / tan(slope) = e_east sin(aspect) + e_north cos(aspect) + dz / tan(slope)

with the aspect the direction of steepest descent (clockwise from north) and ``e`` the shift
still missing: a robust fit of the cosine gives ``e``, the shift is updated, and so on until it
moves less than ``tol_px``. The vertical shift is then the robust mean of ``dh``. Convention
(the same as :mod:`core.matching.surface`): adding ``(dx, dy, dz)`` to the DEM's coordinates
aligns it with the reference, ``ref(x + dx, y + dy) = dem(x, y) + dz``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import map_coordinates, spline_filter

from core.dem import GeoDEM, SurfaceGrid
from core.errors import ConvergenceError, InputError, InsufficientDataError
from core.geodesy import metres_per_degree
from core.robust import nmad

FloatArray = NDArray[np.float64]
DemGrid = GeoDEM | SurfaceGrid


@dataclass(frozen=True)
class CoregConfig:
    """Iterations, convergence (reference pixels), the slopes used (degrees) and the robust
    cut (in NMADs) of the height differences."""

    max_iterations: int = 50
    tol_px: float = 1e-4
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


class _Sampler:
    """Cubic-spline samples of the reference (voids: NaN near them)."""

    def __init__(self, ref: DemGrid) -> None:
        z = np.asarray(ref.values, dtype=np.float64)
        self.void = ~np.isfinite(z)
        filled = np.where(self.void, np.nanmean(z) if np.isfinite(z).any() else 0.0, z)
        self.coeffs = spline_filter(filled, order=3, mode="mirror")
        self.ref = ref

    def __call__(self, x: FloatArray, y: FloatArray) -> FloatArray:
        fi, fj = self.ref.indices(x, y)
        v = map_coordinates(self.coeffs, [fi.ravel(), fj.ravel()], order=3, mode="mirror",
                            prefilter=False).reshape(fi.shape)
        near_void = map_coordinates(self.void.astype(np.float64), [fi.ravel(), fj.ravel()],
                                    order=1, mode="constant", cval=1.0).reshape(fi.shape)
        nr, nc = self.ref.shape
        inside = (fi >= 1) & (fi <= nr - 2) & (fj >= 1) & (fj <= nc - 2)
        return np.where(inside & (near_void == 0), v, np.nan)


def nuth_kaab(reference: DemGrid, dem: DemGrid, config: CoregConfig = CoregConfig()
              ) -> CoregResult:
    """The translation aligning ``dem`` with ``reference``: two :class:`~core.dem.GeoDEM`
    (lon/lat degrees) or two :class:`~core.dem.SurfaceGrid` (projected metres), each of at
    least 4x4 cells."""
    if reference.geographic != dem.geographic:
        raise InputError("the DEM and the reference must both be geographic or both projected; "
                         "reproject one onto the other's CRS first")
    for g in (reference, dem):
        if min(g.shape) < 4:
            raise InputError(f"a DEM grid needs at least 4x4 cells, got {g.shape}")
    sample = _Sampler(reference)
    x, y = dem.nodes()
    z = np.asarray(dem.values, dtype=np.float64)
    ref_dx, ref_dy = reference.axes[2:]
    dem_dx, dem_dy = dem.axes[2:]
    if dem.geographic:
        mx, my = metres_per_degree(y)
    else:
        mx, my = np.ones_like(x), np.ones_like(y)
    sx = sy = 0.0
    step_px = np.inf
    nmad_before = None
    for iteration in range(1, config.max_iterations + 1):
        ref = sample(x + sx, y + sy)
        dh = ref - z
        # slope and aspect of the reference where the DEM lies, in metres
        gy, gx = np.gradient(ref, dem_dy, dem_dx)  # per grid unit
        ge, gn = gx / mx, gy / my  # dz/d(east), dz/d(north), per metre
        tan_slope = np.hypot(ge, gn)
        aspect = np.arctan2(-ge, -gn)  # direction of steepest descent, clockwise from north
        ok = np.isfinite(dh) & np.isfinite(tan_slope)
        ok &= (tan_slope > np.tan(np.radians(config.min_slope_deg)))
        ok &= (tan_slope < np.tan(np.radians(config.max_slope_deg)))
        if ok.sum() < config.min_points:
            raise InsufficientDataError(
                f"only {int(ok.sum())} cells of the DEM overlap the reference on usable slopes "
                f"({config.min_points} needed); check that the two DEMs cover the same area")
        d = dh[ok]
        med, nm = float(np.median(d)), nmad(d)
        if nmad_before is None:
            nmad_before = nm
        keep = np.abs(d - med) < config.outlier_nmad * max(nm, 1e-6)
        t = tan_slope[ok][keep]
        a = aspect[ok][keep]
        target = (d[keep]) / t
        design = np.stack([np.sin(a), np.cos(a), 1.0 / t], axis=1)
        w = t**2  # weigh by slope: the cosine is well measured on steep cells
        coef, *_ = np.linalg.lstsq(design * np.sqrt(w)[:, None], target * np.sqrt(w), rcond=None)
        de, dn = coef[0], coef[1]
        ddx = de / float(np.median(mx[ok]))
        ddy = dn / float(np.median(my[ok]))
        sx, sy = sx + ddx, sy + ddy
        step_px = max(abs(ddx / ref_dx), abs(ddy / ref_dy))
        if step_px < config.tol_px:
            break
    else:
        raise ConvergenceError(
            f"coregistration did not converge in {config.max_iterations} iterations (last step "
            f"{step_px:.2g} px); the DEMs may differ too much or be too flat")
    ref = sample(x + sx, y + sy)
    dh = (ref - z)[np.isfinite(ref - z)]
    med, nm = float(np.median(dh)), nmad(dh)
    keep = np.abs(dh - med) < config.outlier_nmad * max(nm, 1e-6)
    dz = float(np.mean(dh[keep]))
    yc = float(np.median(y)) if dem.geographic else 0.0
    if dem.geographic:
        me, mn = (float(v) for v in metres_per_degree(yc))
    else:
        me = mn = 1.0
    return CoregResult(
        shift_x=float(sx), shift_y=float(sy), shift_east_m=float(sx * me),
        shift_north_m=float(sy * mn), shift_up_m=dz, shift_col_px=float(sx / ref_dx),
        shift_row_px=float(sy / ref_dy), n_iterations=iteration, n_points=int(dh.size),
        nmad_before_m=float(nmad_before), nmad_after_m=nmad(dh[keep]))
