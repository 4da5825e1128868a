"""Whole-DEM coregistration: the 3-D translation that aligns a DEM with a reference (Nuth & Kaab
2011, plus a vertical bias).

Both DEMs are regular north-up grids in one coordinate system, geographic (degrees) or
projected (metres). The reference is sampled at the DEM's nodes moved by the current
horizontal shift (cubic spline, so sub-pixel shifts are not blurred), and the height
differences ``dh = ref - dem`` obey, to first order,

    dh / tan(slope) = e_east sin(aspect) + e_north cos(aspect) + dz / tan(slope)

with the aspect the direction of steepest descent (clockwise from north) and ``e`` the shift
still missing: a robust fit of the cosine gives ``e``, the shift is updated, and so on until it
moves less than ``tol_px``. The vertical shift is then the robust mean of ``dh``. Convention
(the same as :mod:`core.surface_match`): adding ``(dx, dy, dz)`` to the DEM's coordinates
aligns it with the reference, ``ref(x + dx, y + dy) = dem(x, y) + dz``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import map_coordinates, spline_filter

from core.errors import ConvergenceError, InputError, InsufficientDataError
from core.geodesy import WGS84_A_M, WGS84_E2

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class Grid:
    """A north-up grid: ``z_m[i, j]`` at ``x0 + j dx``, ``y0 + i dy`` (cell centres; ``dy`` < 0
    for north-up). ``geographic``: x, y are lon, lat degrees, else projected metres. NaN = void.
    """

    z_m: FloatArray
    x0: float
    y0: float
    dx: float
    dy: float
    geographic: bool

    def __post_init__(self) -> None:
        z = np.asarray(self.z_m, dtype=np.float64)
        if z.ndim != 2 or min(z.shape) < 4:
            raise InputError(f"a DEM grid needs at least 4x4 cells, got {z.shape}")
        if self.dx == 0 or self.dy == 0:
            raise InputError("DEM grid spacings must be non-zero")
        object.__setattr__(self, "z_m", z)

    def nodes(self) -> tuple[FloatArray, FloatArray]:
        i, j = np.mgrid[0:self.z_m.shape[0], 0:self.z_m.shape[1]]
        return self.x0 + j * self.dx, self.y0 + i * self.dy


def metres_per_unit(lat_deg: FloatArray | float) -> tuple[FloatArray, FloatArray]:
    """Exact WGS84 metres per degree of longitude and latitude (radii of curvature)."""
    phi = np.radians(lat_deg)
    w = np.sqrt(1.0 - WGS84_E2 * np.sin(phi) ** 2)
    n = WGS84_A_M / w
    m = WGS84_A_M * (1.0 - WGS84_E2) / w**3
    return np.radians(1.0) * n * np.cos(phi), np.radians(1.0) * m


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


def _nmad(v: FloatArray) -> float:
    return float(1.4826 * np.median(np.abs(v - np.median(v))))


class _Sampler:
    """Cubic-spline samples of the reference (voids: NaN near them)."""

    def __init__(self, ref: Grid) -> None:
        z = ref.z_m
        self.void = ~np.isfinite(z)
        filled = np.where(self.void, np.nanmean(z) if np.isfinite(z).any() else 0.0, z)
        self.coeffs = spline_filter(filled, order=3, mode="mirror")
        self.ref = ref

    def __call__(self, x: FloatArray, y: FloatArray) -> FloatArray:
        fj = (x - self.ref.x0) / self.ref.dx
        fi = (y - self.ref.y0) / self.ref.dy
        v = map_coordinates(self.coeffs, [fi.ravel(), fj.ravel()], order=3, mode="mirror",
                            prefilter=False).reshape(fi.shape)
        near_void = map_coordinates(self.void.astype(np.float64), [fi.ravel(), fj.ravel()],
                                    order=1, mode="constant", cval=1.0).reshape(fi.shape)
        nr, nc = self.ref.z_m.shape
        inside = (fi >= 1) & (fi <= nr - 2) & (fj >= 1) & (fj <= nc - 2)
        return np.where(inside & (near_void == 0), v, np.nan)


def nuth_kaab(reference: Grid, dem: Grid, config: CoregConfig = CoregConfig()) -> CoregResult:
    """The translation aligning ``dem`` with ``reference`` (both geographic or both projected)."""
    if reference.geographic != dem.geographic:
        raise InputError("the DEM and the reference must both be geographic or both projected; "
                         "reproject one onto the other's CRS first")
    sample = _Sampler(reference)
    x, y = dem.nodes()
    z = dem.z_m
    if dem.geographic:
        mx, my = metres_per_unit(y)
    else:
        mx, my = np.ones_like(x), np.ones_like(y)
    sx = sy = 0.0
    step_px = np.inf
    nmad_before = None
    for iteration in range(1, config.max_iterations + 1):
        ref = sample(x + sx, y + sy)
        dh = ref - z
        # slope and aspect of the reference where the DEM lies, in metres
        gy, gx = np.gradient(ref, dem.dy, dem.dx)  # per grid unit
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
        med, nm = float(np.median(d)), _nmad(d)
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
        step_px = max(abs(ddx / reference.dx), abs(ddy / reference.dy))
        if step_px < config.tol_px:
            break
    else:
        raise ConvergenceError(
            f"coregistration did not converge in {config.max_iterations} iterations (last step "
            f"{step_px:.2g} px); the DEMs may differ too much or be too flat")
    ref = sample(x + sx, y + sy)
    dh = (ref - z)[np.isfinite(ref - z)]
    med, nm = float(np.median(dh)), _nmad(dh)
    keep = np.abs(dh - med) < config.outlier_nmad * max(nm, 1e-6)
    dz = float(np.mean(dh[keep]))
    yc = float(np.median(y)) if dem.geographic else 0.0
    if dem.geographic:
        me, mn = (float(v) for v in metres_per_unit(yc))
    else:
        me = mn = 1.0
    return CoregResult(
        shift_x=float(sx), shift_y=float(sy), shift_east_m=float(sx * me),
        shift_north_m=float(sy * mn), shift_up_m=dz, shift_col_px=float(sx / reference.dx),
        shift_row_px=float(sy / reference.dy), n_iterations=iteration, n_points=int(dh.size),
        nmad_before_m=float(nmad_before), nmad_after_m=_nmad(dh[keep]))
