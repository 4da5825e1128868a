"""Local surface matching of the relative DEM to the reference: simulated GCPs from SRTM alone.

Step 3 of the chain (Goncalves 3.3). Around each tie point, the relative DEM's cells within a
radius (heights ``h'``, ellipsoidal, in the frame the relative orientation left them) are
compared with the reference DEM (SRTM + EGM96, ellipsoidal) shifted by ``(dlon, dlat)`` over a
grid of shifts (default -20" .. +20" every 1"): the correlation coefficient of the two height
sets is computed for every shift at once, its peak refined to a fraction of an arcsecond by a
quadratic fit (then, optionally, a finer grid around it), and the vertical shift is the robust
mean of the height differences at the refined position. The window's local 3-D shift moves the
tie point's relative ground coordinates onto the reference: a simulated GCP.

Cells are first averaged onto a lattice of about the reference's cell size (finer detail is
absent from SRTM and would only cost time). Quality of a window: peak correlation, the peak's
sharpness turned into a horizontal precision in metres, the relief (std of ``h'``), the number
of cells, the share of the window masked (mismatched cells or reference voids), and a
precision predicted from the relief before matching (relief sufficiency): with RMS slope ``g``
and height noise ``s`` over ``N`` independent patches (the window's area over the squared
correlation length of the reference's errors) the shift is known to about ``s / (g sqrt(N))``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from enum import IntEnum
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.dem import GeoDEM
from core.errors import InputError
from core.geodesy import metres_per_degree

FloatArray = NDArray[np.float64]
ARCSEC = 1.0 / 3600.0


class WindowStatus(IntEnum):
    """Outcome of a window: 0 usable, else why it was refused."""

    OK = 0
    TOO_FEW_CELLS = 1  # the relative DEM has too few valid cells in the window
    MASKED = 2  # too large a share masked (mismatch or reference voids)
    LOW_RELIEF = 3  # the relief cannot give the needed precision
    LOW_CORRELATION = 4  # the best correlation is too low to trust
    EDGE_PEAK = 5  # the peak is on the border of the searched shifts
    IMPRECISE = 6  # the peak is too flat: the shift is not known well enough


@dataclass(frozen=True)
class SurfaceMatchConfig:
    """Settings of :func:`match_window` (lengths in metres, shifts in arcseconds).

    ``cell_m`` None averages the window on the reference's own cell size. ``error_length_m``
    is the correlation length of the reference's height errors (SRTM: a few hundred metres),
    ``height_noise_m`` their standard deviation (SRTM: about 4-5 m), both used by the
    predicted precision. A window is refused when that prediction, or the measured precision,
    exceeds ``max_precision_m``. ``detrend``: compare the two surfaces about their best-fit
    planes (the relative DEM may be tilted: an along-epipolar drift that tie points cannot see
    tilts it by metres per kilometre), the vertical shift then being the plane's height at
    the window's centre.
    """

    radius_m: float = 4000.0
    shift_max_arcsec: float = 20.0
    shift_step_arcsec: float = 1.0
    cell_m: float | None = None
    refine_step_arcsec: float | None = 0.1
    min_cells: int = 100
    max_masked_share: float = 0.5
    min_correlation: float = 0.6
    max_precision_m: float = 10.0
    height_noise_m: float = 5.0
    error_length_m: float = 300.0
    detrend: bool = True

    def __post_init__(self) -> None:
        if not (self.radius_m > 0 and self.shift_max_arcsec > 0
                and 0 < self.shift_step_arcsec <= self.shift_max_arcsec):
            raise InputError(
                f"surface matching needs a window radius > 0 m (--window-radius, got "
                f"{self.radius_m:g}), a largest shift > 0 arcsec (--max-shift, got "
                f"{self.shift_max_arcsec:g}) and a shift step in (0, largest shift] (got "
                f"{self.shift_step_arcsec:g})")
        if self.refine_step_arcsec is not None and not (
                0 < self.refine_step_arcsec < self.shift_step_arcsec):
            raise InputError(f"the surface-matching refinement step ({self.refine_step_arcsec:g}"
                             "\") must be smaller than the search step, or none")
        if not (0 <= self.max_masked_share <= 1 and -1 < self.min_correlation < 1):
            raise InputError("surface matching needs a largest masked share in [0, 1] and a "
                             "least correlation in (-1, 1)")
        if not (self.max_precision_m > 0 and self.height_noise_m > 0
                and self.error_length_m > 0 and self.min_cells >= 10):
            raise InputError("surface matching needs a precision limit, a reference noise and "
                             "an error length > 0 m, and at least 10 cells per window")


@dataclass(frozen=True)
class WindowMatch:
    """The local 3-D shift of one window and its quality.

    The shift maps the relative DEM onto the reference: a relative point (lon, lat, h) lies at
    ``(lon + shift_lon_arcsec", lat + shift_lat_arcsec", h + shift_h_m)`` in the reference.
    ``shift_east_m``/``shift_north_m`` are the same horizontal shift in metres;
    ``precision_m`` the horizontal precision from the peak's sharpness, ``precision_h_m`` the
    vertical one (the differences' robust spread over the root of the independent patches);
    ``predicted_precision_m`` the precision the relief promised before matching (with the
    reference's nominal noise ``cfg.height_noise_m``); ``spread_m`` the robust spread of the
    height differences about their dominant mode after the shift (NaN when not matched);
    ``n_dem_cells`` the window's lattice cells the relative DEM fills (``n_cells`` of them have
    a reference height too): a scene smaller than a window fills few of them.
    """

    status: WindowStatus
    shift_lon_arcsec: float = float("nan")
    shift_lat_arcsec: float = float("nan")
    shift_h_m: float = float("nan")
    shift_east_m: float = float("nan")
    shift_north_m: float = float("nan")
    correlation: float = float("nan")
    precision_m: float = float("nan")
    precision_h_m: float = float("nan")
    predicted_precision_m: float = float("nan")
    relief_m: float = float("nan")
    rms_slope: float = float("nan")
    n_cells: int = 0
    masked_share: float = 1.0
    spread_m: float = float("nan")
    n_dem_cells: int = 0

    @property
    def ok(self) -> bool:
        return self.status == WindowStatus.OK

    def to_dict(self) -> dict[str, Any]:
        d = dict(vars(self))
        d["status"] = self.status.name
        return {k: (None if isinstance(v, float) and not np.isfinite(v) else v)
                for k, v in d.items()}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> WindowMatch:
        kw = {k: (float("nan") if v is None else v) for k, v in d.items()}
        kw["status"] = WindowStatus[d["status"]]
        return cls(**kw)


# ------------------------------------------------------------------------- window lattice


@dataclass(frozen=True, eq=False)
class WindowCells:
    """The relative DEM in a window, averaged on a lattice: lon/lat (degrees) and height ``h_m``
    of each lattice cell (NaN when no valid relative cell fell in it), ``cell_m`` its size."""

    lon_deg: FloatArray
    lat_deg: FloatArray
    h_m: FloatArray
    x_m: FloatArray
    y_m: FloatArray
    cell_m: float
    shape: tuple[int, int]
    n_input: int
    n_masked: int
    n_disk: int


def window_cells(lon_deg: ArrayLike, lat_deg: ArrayLike, h_m: ArrayLike,
                 centre: tuple[float, float], radius_m: float, cell_m: float) -> WindowCells:
    """Average the relative DEM's cells (NaN heights = mismatched) within ``radius_m`` of
    ``centre`` onto a square lattice of ``cell_m`` around it, or coarser when the relative DEM
    is: a lattice cell is at least sqrt(2) times the input's spacing, so that every cell of a
    complete input receives a value whatever the grids' orientations."""
    lon = np.ravel(np.asarray(lon_deg, dtype=np.float64))
    lat = np.ravel(np.asarray(lat_deg, dtype=np.float64))
    h = np.ravel(np.asarray(h_m, dtype=np.float64))
    m_lon, m_lat = metres_per_degree(centre[1])
    x = (lon - centre[0]) * float(m_lon)
    y = (lat - centre[1]) * float(m_lat)
    inside = np.hypot(x, y) <= radius_m
    cell_m = max(float(cell_m), np.sqrt(2.0) * _spacing_m(x[inside], y[inside]))
    n_side = 2 * int(np.ceil(radius_m / cell_m))
    ix = np.floor((x[inside] + n_side * cell_m / 2) / cell_m).astype(np.int64)
    iy = np.floor((y[inside] + n_side * cell_m / 2) / cell_m).astype(np.int64)
    keep = (ix >= 0) & (ix < n_side) & (iy >= 0) & (iy < n_side)
    idx = iy[keep] * n_side + ix[keep]
    hv = h[inside][keep]
    good = np.isfinite(hv)
    total = np.bincount(idx[good], weights=hv[good], minlength=n_side * n_side)
    count = np.bincount(idx[good], minlength=n_side * n_side)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(count > 0, total / count, np.nan)
    gx = (np.arange(n_side) + 0.5) * cell_m - n_side * cell_m / 2
    xx, yy = np.meshgrid(gx, gx)
    in_disk = (np.hypot(xx, yy) <= radius_m).ravel()
    mean = np.where(in_disk, mean, np.nan)
    return WindowCells(centre[0] + xx.ravel() / float(m_lon), centre[1] + yy.ravel() / float(m_lat),
                       mean, xx.ravel(), yy.ravel(), float(cell_m), (n_side, n_side),
                       int(inside.sum()),
                       int((~np.isfinite(h[inside])).sum()), int(in_disk.sum()))


def _spacing_m(x: FloatArray, y: FloatArray, n_sample: int = 400) -> float:
    """Typical distance between neighbouring input cells (median nearest-neighbour distance of
    a sample)."""
    if x.size < 2:
        return 0.0
    from scipy.spatial import cKDTree

    pts = np.stack([x, y], axis=1)
    sample = pts[np.linspace(0, len(pts) - 1, min(n_sample, len(pts))).astype(np.int64)]
    d, _ = cKDTree(pts).query(sample, k=2)
    return float(np.median(d[:, 1]))


# ------------------------------------------------------------------------- matching


def _basis(cells: WindowCells, ok: NDArray[np.bool_], detrend: bool) -> FloatArray:
    """Regressors removed before correlating: a constant, and a plane with ``detrend`` (x, y
    in kilometres from the centre, for conditioning)."""
    one = np.ones(int(ok.sum()))
    if not detrend:
        return one[:, None]
    return np.stack([one, cells.x_m[ok] / 1000.0, cells.y_m[ok] / 1000.0], axis=1)


def _correlations(cells: WindowCells, reference: GeoDEM, shifts_deg: FloatArray,
                  detrend: bool = True, chunk: int = 128) -> tuple[FloatArray, FloatArray]:
    """Correlation coefficient (partial: about the best constant, or plane with ``detrend``,
    of each set over the pairs valid at that shift) and valid-pair count for each (dlon, dlat)
    shift (n, 2)."""
    ok = np.isfinite(cells.h_m)
    lon, lat = cells.lon_deg[ok], cells.lat_deg[ok]
    h0 = float(np.mean(cells.h_m[ok]))  # near the reference's heights: conditioning only
    h = cells.h_m[ok] - h0
    b = _basis(cells, ok, detrend)
    bb = b[:, :, None] * b[:, None, :]  # (n, k, k)
    rho = np.full(len(shifts_deg), np.nan)
    count = np.zeros(len(shifts_deg))
    for s in range(0, len(shifts_deg), chunk):
        sh = shifts_deg[s:s + chunk]
        ref = reference.height_m(lon[None, :] + sh[:, :1], lat[None, :] + sh[:, 1:])
        valid = np.isfinite(ref)
        v = valid.astype(np.float64)
        r = np.where(valid, ref - h0, 0.0)  # the basis holds a constant: any offset does
        gram = (v @ bb.reshape(len(h), -1)).reshape(len(sh), *bb.shape[1:])
        bh = v @ (b * h[:, None])
        br = r @ b
        with np.errstate(invalid="ignore", divide="ignore"):
            try:
                sol_h = np.linalg.solve(gram, bh[:, :, None])[:, :, 0]
                sol_r = np.linalg.solve(gram, br[:, :, None])[:, :, 0]
            except np.linalg.LinAlgError:  # a shift with too few pairs: solve one by one
                sol_h, sol_r = _lstsq_each(gram, bh), _lstsq_each(gram, br)
            hh = v @ (h * h) - np.sum(bh * sol_h, axis=1)
            rr = np.sum(r * r, axis=1) - np.sum(br * sol_r, axis=1)
            hr = r @ h - np.sum(bh * sol_r, axis=1)
            rho[s:s + chunk] = hr / np.sqrt(hh * rr)
        count[s:s + chunk] = v.sum(axis=1)
    return rho, count


def _lstsq_each(gram: FloatArray, rhs: FloatArray) -> FloatArray:
    return np.stack([np.linalg.lstsq(g, y, rcond=None)[0] for g, y in zip(gram, rhs,
                                                                            strict=True)])


def _valid_rho(cells: WindowCells, reference: GeoDEM, sx_arcsec: FloatArray,
               sy_arcsec: FloatArray, min_cells: int, detrend: bool) -> FloatArray:
    """Correlations at shifts (arcsec), NaN where fewer than ``min_cells`` pairs are valid."""
    rho, count = _correlations(cells, reference, np.stack([sx_arcsec, sy_arcsec], 1) * ARCSEC,
                               detrend)
    return np.where(count >= min_cells, rho, np.nan)


def quadratic_peak(z: FloatArray) -> tuple[float, float, FloatArray]:
    """Offset (dx, dy) in grid steps of the maximum of the quadratic fitted to a 3x3 patch (rows
    y, columns x; centre at 0), and the fit's Hessian (2, 2) per step squared."""
    y, x = np.mgrid[-1:2, -1:2]
    design = np.stack([np.ones(9), x.ravel(), y.ravel(), x.ravel() ** 2, x.ravel() * y.ravel(),
                       y.ravel() ** 2], axis=1)
    c, *_ = np.linalg.lstsq(design, z.ravel(), rcond=None)
    hess = np.array([[2 * c[3], c[4]], [c[4], 2 * c[5]]])
    grad = np.array([c[1], c[2]])
    try:
        off = -np.linalg.solve(hess, grad)
    except np.linalg.LinAlgError:
        off = np.zeros(2)
    if not np.all(np.isfinite(off)) or np.max(np.abs(off)) > 1.0:
        off = np.clip(np.nan_to_num(off), -1.0, 1.0)
    return float(off[0]), float(off[1]), hess


def _grid(half: float, step: float) -> FloatArray:
    n = int(round(half / step))
    return np.arange(-n, n + 1) * step


def predicted_precision_m(cells: WindowCells, cfg: SurfaceMatchConfig) -> tuple[float, float,
                                                                                 float, int]:
    """(precision m, relief m, RMS slope, independent patches) the window's relief promises.

    With ``cfg.detrend`` the relief is the heights' spread about their best-fit plane and the
    slopes are taken about their mean: a plane carries no information once a tilt is free.
    """
    h = cells.h_m.reshape(cells.shape)
    gy, gx = np.gradient(h, cells.cell_m)
    if cfg.detrend and np.isfinite(gx).any() and np.isfinite(gy).any():
        gx, gy = gx - np.nanmean(gx), gy - np.nanmean(gy)
    g2 = gx**2 + gy**2
    ok = np.isfinite(g2)
    relief = _relief_m(cells, cfg.detrend)
    if ok.sum() < 3:
        return float("inf"), relief, 0.0, 0
    slope = float(np.sqrt(np.mean(g2[ok])))
    area = ok.sum() * cells.cell_m**2
    n_eff = max(int(area / max(cfg.error_length_m, cells.cell_m) ** 2), 1)
    if slope <= 0:
        return float("inf"), relief, slope, n_eff
    return cfg.height_noise_m / (slope * np.sqrt(n_eff)), relief, slope, n_eff


def _relief_m(cells: WindowCells, detrend: bool) -> float:
    """Standard deviation of the window's heights (about their best-fit plane with
    ``detrend``)."""
    ok = np.isfinite(cells.h_m)
    if ok.sum() < 4:
        return 0.0
    b = _basis(cells, ok, detrend)
    coef, *_ = np.linalg.lstsq(b, cells.h_m[ok], rcond=None)
    return float(np.std(cells.h_m[ok] - b @ coef))


def match_window(lon_deg: ArrayLike, lat_deg: ArrayLike, h_m: ArrayLike,
                 centre: tuple[float, float], reference: GeoDEM,
                 cfg: SurfaceMatchConfig = SurfaceMatchConfig(),
                 prior: tuple[float, float, float] | None = None) -> WindowMatch:
    """The local 3-D shift of the relative DEM around ``centre`` (lon, lat degrees) onto the
    reference. ``lon_deg``, ``lat_deg``, ``h_m``: the relative DEM's cells (NaN heights: cells
    the matching could not fill), at least those within ``cfg.radius_m``.

    ``prior``: (dlon, dlat, half-width) in arcseconds, the shift expected from other windows:
    only shifts within the half-width of it are searched (inside the ``cfg`` range); a peak
    on the border of that box is ``EDGE_PEAK`` (search again without the prior)."""
    m_lon, m_lat = (float(v) for v in metres_per_degree(centre[1]))
    cell = cfg.cell_m if cfg.cell_m is not None else reference.cell_size_m()
    cells = window_cells(lon_deg, lat_deg, h_m, centre, cfg.radius_m, cell)
    valid = np.isfinite(cells.h_m)
    ref0 = reference.height_m(cells.lon_deg[valid], cells.lat_deg[valid])
    n_pairs = int(np.isfinite(ref0).sum())
    masked = 1.0 - n_pairs / max(cells.n_disk, 1)  # mismatched cells or reference voids
    pred, relief, slope, n_eff = predicted_precision_m(cells, cfg)
    base = dict(relief_m=relief, rms_slope=slope, n_cells=n_pairs, masked_share=masked,
                predicted_precision_m=pred, n_dem_cells=int(valid.sum()))
    if n_pairs < cfg.min_cells:
        return WindowMatch(WindowStatus.TOO_FEW_CELLS, **base)
    if masked > cfg.max_masked_share:
        return WindowMatch(WindowStatus.MASKED, **base)
    if not pred <= cfg.max_precision_m:
        return WindowMatch(WindowStatus.LOW_RELIEF, **base)
    # coarse to fine: every other step over the whole range, then every step around the best
    grid = _grid(cfg.shift_max_arcsec, cfg.shift_step_arcsec)
    gx, gy = np.meshgrid(grid, grid)
    rho = np.full(gx.shape, np.nan)
    box = np.ones(gx.shape, dtype=bool)
    if prior is not None:
        box = (np.abs(gx - prior[0]) <= prior[2]) & (np.abs(gy - prior[1]) <= prior[2])
        if not box.any():
            return WindowMatch(WindowStatus.EDGE_PEAK, **base)
    coarse = np.zeros(gx.shape, dtype=bool)
    coarse[::2, ::2] = True
    coarse &= box
    rho[coarse] = _valid_rho(cells, reference, gx[coarse], gy[coarse], cfg.min_cells,
                              cfg.detrend)
    if not np.isfinite(rho).any():
        return WindowMatch(WindowStatus.MASKED, **base)
    cy, cx = np.unravel_index(int(np.nanargmax(rho)), rho.shape)
    near = np.zeros(gx.shape, dtype=bool)
    near[max(cy - 3, 0):cy + 4, max(cx - 3, 0):cx + 4] = True
    near &= ~coarse & box
    rho[near] = _valid_rho(cells, reference, gx[near], gy[near], cfg.min_cells,
                            cfg.detrend)
    iy, ix = np.unravel_index(int(np.nanargmax(rho)), rho.shape)
    inner = np.zeros(gx.shape, dtype=bool)  # the searched box without its border
    inner[1:-1, 1:-1] = True
    if prior is not None:
        inner &= ((np.abs(gx - prior[0]) < prior[2] - 0.5 * cfg.shift_step_arcsec)
                  & (np.abs(gy - prior[1]) < prior[2] - 0.5 * cfg.shift_step_arcsec))
    if not inner[iy, ix]:
        return WindowMatch(WindowStatus.EDGE_PEAK, correlation=float(rho[iy, ix]), **base)
    patch = rho[iy - 1:iy + 2, ix - 1:ix + 2]
    if not np.all(np.isfinite(patch)):
        return WindowMatch(WindowStatus.MASKED, **base)
    dx, dy, hess = quadratic_peak(patch)
    step = cfg.shift_step_arcsec
    sx, sy = grid[ix] + dx * step, grid[iy] + dy * step
    hess = hess / step**2  # per arcsec squared
    if cfg.refine_step_arcsec is not None:
        fine = _grid(0.5 * step, cfg.refine_step_arcsec)  # the 1" quadratic is within 0.2"
        fx, fy = np.meshgrid(sx + fine, sy + fine)
        rf, _ = _correlations(cells, reference,
                              np.stack([fx.ravel(), fy.ravel()], 1) * ARCSEC, cfg.detrend)
        rf = rf.reshape(fx.shape)
        if np.isfinite(rf).all():
            jy, jx = np.unravel_index(int(np.argmax(rf)), rf.shape)
            jy = int(np.clip(jy, 1, rf.shape[0] - 2))
            jx = int(np.clip(jx, 1, rf.shape[1] - 2))
            ddx, ddy, _ = quadratic_peak(rf[jy - 1:jy + 2, jx - 1:jx + 2])
            sx = float(fx[jy, jx] + ddx * cfg.refine_step_arcsec)
            sy = float(fy[jy, jx] + ddy * cfg.refine_step_arcsec)
    peak = float(np.nanmax(rho))
    ref = reference.height_m(cells.lon_deg[valid] + sx * ARCSEC,
                             cells.lat_deg[valid] + sy * ARCSEC)
    diff = ref - cells.h_m[valid]
    use = np.isfinite(diff)
    basis = _basis(cells, valid, cfg.detrend)[use]
    coef, spread = _robust_fit(diff[use], basis, mode_scale_m=cfg.height_noise_m)
    dz = float(coef[0])  # at the centre: x = y = 0 there
    # precision: near its peak rho(s) ~ 1 - k s^2 / 2 with k = slope^2 / relief^2 along the
    # flattest direction (the peak's curvature, per m^2); least squares then knows the shift to
    # spread / (slope sqrt(N)) = spread / (relief sqrt(k N)) over N independent patches
    scale = np.diag([1.0 / (ARCSEC * m_lon), 1.0 / (ARCSEC * m_lat)])  # arcsec per metre
    curv = float(np.min(np.abs(np.linalg.eigvalsh(scale @ hess @ scale))))
    precision = (float(spread / (relief * np.sqrt(curv * n_eff))) if curv > 0 and relief > 0
                 else float("inf"))
    result = WindowMatch(
        WindowStatus.OK, shift_lon_arcsec=float(sx), shift_lat_arcsec=float(sy),
        shift_h_m=dz, shift_east_m=float(sx * ARCSEC * m_lon),
        shift_north_m=float(sy * ARCSEC * m_lat), correlation=peak, precision_m=precision,
        precision_h_m=float(spread / np.sqrt(max(n_eff, 1))), spread_m=float(spread), **base)
    if peak < cfg.min_correlation:
        return WindowMatch(**{**vars(result), "status": WindowStatus.LOW_CORRELATION})
    if not precision <= cfg.max_precision_m:
        return WindowMatch(**{**vars(result), "status": WindowStatus.IMPRECISE})
    return result


def _robust_fit(d: FloatArray, basis: FloatArray, k: float = 1.5, n_iter: int = 10,
                mode_scale_m: float | None = None) -> tuple[FloatArray, float]:
    """Fit of ``d`` on ``basis`` (n, k) and the robust spread (1.4826 MAD) of its residuals.

    Huber IRLS first; then, with ``mode_scale_m``, the fit is moved to the dominant mode of
    the residuals (the peak of their kernel density) and refined with Gaussian (Welsch)
    weights of that scale, which ignore a second population: the relative DEM is a surface
    model, the reference has no canopy (SRTM partly, the simulator's not at all), and
    forests on a third of a window pulled the Huber fit 5 m down on the simulated ``spot``
    pair (17.5 m trees on 32 % of it); the spread is then that of the dominant population.
    """
    if d.size < basis.shape[1]:
        return np.full(basis.shape[1], np.nan), float("nan")

    def mad(r: FloatArray) -> float:
        return max(float(1.4826 * np.median(np.abs(r - np.median(r)))), 1e-6)

    coef, *_ = np.linalg.lstsq(basis, d, rcond=None)
    res = d - basis @ coef
    s = mad(res)
    for _ in range(n_iter):
        w = 1.0 / np.maximum(np.abs(res) / (k * s), 1.0)
        sw = np.sqrt(w)
        coef, *_ = np.linalg.lstsq(basis * sw[:, None], d * sw, rcond=None)
        res = d - basis @ coef
        s = mad(res)
    if mode_scale_m is None:
        return coef, s
    h = float(mode_scale_m)
    lo, hi = np.percentile(res, (0.5, 99.5))
    step = h / 10.0
    edges = np.arange(lo - 3 * h, hi + 3 * h + step, step)
    density, _ = np.histogram(res, bins=edges)
    from scipy.ndimage import gaussian_filter1d

    peak = int(np.argmax(gaussian_filter1d(density.astype(np.float64), 0.5 * h / step)))
    coef = coef.copy()
    coef[0] += 0.5 * (edges[peak] + edges[peak + 1])
    for _ in range(n_iter):
        res = d - basis @ coef
        sw = np.exp(-0.25 * (res / h) ** 2)  # sqrt of the Gaussian weight exp(-r^2 / 2h^2)
        if np.count_nonzero(sw > 0.1) < basis.shape[1]:
            break
        coef, *_ = np.linalg.lstsq(basis * sw[:, None], d * sw, rcond=None)
    res = d - basis @ coef
    core = np.abs(res) < 3.0 * h
    return coef, mad(res[core]) if core.sum() >= basis.shape[1] else mad(res)


# ------------------------------------------------------------------------- search prior


def shift_prior(lon_deg: ArrayLike, lat_deg: ArrayLike, matches: Sequence[WindowMatch],
                lon_new: ArrayLike, lat_new: ArrayLike, min_half_arcsec: float = 6.0,
                min_windows: int = 6) -> FloatArray | None:
    """Search priors ``(n, 3)``: (dlon, dlat, half-width) arcseconds for windows at
    ``lon_new``/``lat_new``, from the shifts of the ``matches`` already found at
    ``lon_deg``/``lat_deg``: the relative DEM's misplacement is smooth over the scene (an
    offset plus a tilt and scale left by the relative orientation), so an affine fit of the
    good windows' shifts predicts the others'. Half-width: ``min_half_arcsec`` or four times
    the fit's robust scatter plus a step, whichever is larger. None with fewer than
    ``min_windows`` good windows (search everywhere)."""
    lon, lat = np.asarray(lon_deg, float), np.asarray(lat_deg, float)
    ok = np.array([m.ok for m in matches], dtype=bool)
    if ok.sum() < min_windows:
        return None
    lon0, lat0 = float(np.mean(lon[ok])), float(np.mean(lat[ok]))
    a = np.stack([np.ones(ok.sum()), lon[ok] - lon0, lat[ok] - lat0], axis=1)
    shifts = np.array([[m.shift_lon_arcsec, m.shift_lat_arcsec] for m, k in zip(matches, ok,
                                                                              strict=True)
                       if k])
    coef, *_ = np.linalg.lstsq(a, shifts, rcond=None)
    res = shifts - a @ coef
    scatter = 1.4826 * float(np.median(np.abs(res - np.median(res, axis=0))))
    half = max(min_half_arcsec, 4.0 * scatter + 1.0)
    ln, lt = np.asarray(lon_new, float), np.asarray(lat_new, float)
    b = np.stack([np.ones(ln.size), ln.ravel() - lon0, lt.ravel() - lat0], axis=1)
    pred = b @ coef
    return np.column_stack([pred, np.full(len(pred), half)])


# ------------------------------------------------------------------------- relief sufficiency


@dataclass(frozen=True)
class ReliefVerdict:
    """Whether the scene gives surface matching what it needs, judged before orienting, and
    if not the true reason (:attr:`reason`).

    ``n_qualified``: windows whose relief promises ``max_precision_m`` (the precision predicted
    from the relief and the measured noise, see :func:`realistic_precision_m`), of
    ``n_windows`` placed; ``n_small``: windows the relative DEM fills with fewer than
    ``min_cells`` lattice cells of ``cell_m`` (the scene, or its overlap, is smaller than a
    window: ``best_dem_cells`` is the most any window got); ``n_voids``: windows the relative
    DEM fills but the reference leaves without heights (voids) or that are masked beyond the
    allowed share; the other windows are judged on their relief. ``relief_found_m``: the
    median relief (std of heights) of the judged windows; ``relief_needed_m``: the median over
    them of the relief that would have made them qualify (the predicted precision goes as one
    over the slopes, so as one over the relief of a terrain of the same shape; NaN when no
    judged window has a slope).
    """

    n_windows: int
    n_qualified: int
    n_needed: int
    relief_found_m: float
    relief_needed_m: float
    max_precision_m: float
    n_small: int = 0
    n_voids: int = 0
    best_dem_cells: int = 0
    min_cells: int = 100
    cell_m: float = float("nan")
    radius_m: float = float("nan")

    @property
    def enough(self) -> bool:
        return self.n_qualified >= self.n_needed

    @property
    def n_judged(self) -> int:
        return self.n_windows - self.n_small - self.n_voids

    @property
    def reason(self) -> str | None:
        """None when enough windows qualify, else why not: ``"too_small"`` (no window holds
        enough of the relative DEM: the scene is smaller than a window), ``"voids"`` (the
        reference has no heights under the windows), ``"few_windows"`` (every window judged
        qualifies, but too few fit in the scene), ``"too_flat"``."""
        if self.enough:
            return None
        if self.n_judged == 0:
            return "too_small" if self.n_small >= self.n_voids else "voids"
        if self.n_qualified == self.n_judged:
            return "few_windows"
        return "too_flat"

    def message(self) -> str:
        """The refusal in one line: what was found, what is needed, what to do. Never NaN."""
        n, need = self.n_windows, self.n_needed
        skipped = "" if not (self.n_small or self.n_voids) else (
            f" ({self.n_small} too little of the scene, {self.n_voids} on reference voids)")
        if self.reason == "too_small":
            area = self.min_cells * self.cell_m**2 / 1e6
            have = self.best_dem_cells * self.cell_m**2 / 1e6
            return (f"the scene is too small for SRTM surface matching: the best of {n} windows "
                    f"holds {self.best_dem_cells} cells of the relative DEM at the reference's "
                    f"{self.cell_m:.0f} m (about {have:.2g} km2), {self.min_cells} are needed "
                    f"(about {area:.2g} km2 of overlap, in windows of radius "
                    f"{self.radius_m:g} m); use a scene covering kilometres of terrain, or "
                    "real GCPs")
        if self.reason == "voids":
            return (f"the reference DEM has no heights under the scene: {self.n_voids} of {n} "
                    f"surface-matching windows fall on its voids or are masked beyond the "
                    f"allowed share; fill the reference's voids (gcpfree fill-voids) or use "
                    "another reference")
        if self.reason == "few_windows":
            return (f"the scene holds too few surface-matching windows: {n} placed, "
                    f"{self.n_qualified} with enough relief{skipped}, {need} needed; use a "
                    "larger scene, or lower --min-windows or --window-radius")
        if np.isfinite(self.relief_needed_m):
            needed = f"needed about {self.relief_needed_m:.1f} m"
        else:
            needed = "no window has a slope to match on"
        return (f"the terrain is too flat for GCP-free orientation: {self.n_qualified} of "
                f"{self.n_judged} windows judged{skipped} have the relief to fix the position "
                f"to {self.max_precision_m:g} m ({need} needed); relief found "
                f"{self.relief_found_m:.1f} m (median std of heights per window), {needed}; "
                "use real GCPs or a scene with more relief")

    def to_dict(self) -> dict[str, Any]:
        return {k: (None if isinstance(v, float) and not np.isfinite(v) else v)
                for k, v in vars(self).items()} | {"enough": self.enough,
                                                    "reason": self.reason}


def scene_size_verdict(overlap_m2: float, cfg: SurfaceMatchConfig,
                       cell_m: float) -> str | None:
    """Before anything is matched: None when the pair's overlap (``overlap_m2``, its largest
    over the heights the scene may have) can hold one surface-matching window's
    ``cfg.min_cells`` lattice cells of ``cell_m`` (the reference's cell, or ``cfg.cell_m``),
    else the refusal, with its figures. The relief verdict judges the windows afterwards; this
    only spares minutes of matching on a scene that cannot hold one window."""
    cell = float(cfg.cell_m if cfg.cell_m is not None else cell_m)
    needed = cfg.min_cells * cell**2
    if not overlap_m2 < needed:
        return None
    return (f"the scene is too small for SRTM surface matching: the two images overlap on about "
            f"{overlap_m2 / 1e6:.2g} km2 ({overlap_m2 / cell**2:.0f} cells of the reference's "
            f"{cell:.0f} m), one window needs {cfg.min_cells} cells (about "
            f"{needed / 1e6:.2g} km2); use a scene covering kilometres of terrain, or real GCPs")


def realistic_precision_m(m: WindowMatch, cfg: SurfaceMatchConfig) -> float:
    """The precision a window's relief promises with the noise its correlation reveals, when
    that exceeds the reference's nominal noise (``cfg.height_noise_m``).

    A surface of relief ``r`` (std) seen through independent noise ``n`` correlates with the
    noise-free one at ``rho = r^2 / (r^2 + n^2)``, so the peak correlation measures the noise
    between the two surfaces, ``n = r sqrt(1 / rho - 1)``: the relative DEM's own noise, canopy,
    the reference's errors. On terrain of a few tens of metres of relief that noise, not SRTM's,
    decides (simulated tiny at 40 m pixels, relief scaled by 0.05: windows promising 10 m with
    the nominal noise, none of them correlating). A window refused before matching keeps the
    nominal prediction.
    """
    rho = m.correlation
    if not (np.isfinite(rho) and 0.0 < rho < 1.0 and np.isfinite(m.relief_m)):
        return m.predicted_precision_m
    noise = m.relief_m * float(np.sqrt(1.0 / rho - 1.0))
    return m.predicted_precision_m * max(noise / cfg.height_noise_m, 1.0)


def relief_sufficiency(matches: Sequence[WindowMatch], cfg: SurfaceMatchConfig,
                       n_needed: int, cell_m: float | None = None) -> ReliefVerdict:
    """The verdict on ``matches`` (windows matched or refused by :func:`match_window`), each
    judged by :func:`realistic_precision_m`; ``cell_m`` the lattice cell the windows were
    averaged on (``cfg.cell_m`` or the reference's), for the message."""
    def filled(m: WindowMatch) -> int:  # n_cells (with a reference height) <= n_dem_cells;
        return max(m.n_dem_cells, m.n_cells)  # windows.json of older runs lack the latter

    small = [m for m in matches if filled(m) < cfg.min_cells]
    voids = [m for m in matches if filled(m) >= cfg.min_cells
             and m.status in (WindowStatus.TOO_FEW_CELLS, WindowStatus.MASKED)]
    sized = [m for m in matches if filled(m) >= cfg.min_cells
             and m.status not in (WindowStatus.TOO_FEW_CELLS, WindowStatus.MASKED)
             and np.isfinite(m.relief_m)]
    precision = [realistic_precision_m(m, cfg) for m in sized]
    qualified = [m for m, p in zip(sized, precision, strict=True) if p <= cfg.max_precision_m]
    found = float(np.median([m.relief_m for m in sized])) if sized else 0.0
    need = [m.relief_m * p / cfg.max_precision_m for m, p in zip(sized, precision, strict=True)
            if np.isfinite(p) and m.relief_m > 0]
    needed = float(np.median(need)) if need else float("nan")
    return ReliefVerdict(
        len(matches), len(qualified), n_needed, found, needed, cfg.max_precision_m,
        n_small=len(small), n_voids=len(voids),
        best_dem_cells=max((filled(m) for m in matches), default=0),
        min_cells=cfg.min_cells,
        cell_m=float(cfg.cell_m if cfg.cell_m is not None else
                     (cell_m if cell_m is not None else float("nan"))),
        radius_m=cfg.radius_m)


# ------------------------------------------------------------------------- report figure


def correlation_surface(lon_deg: ArrayLike, lat_deg: ArrayLike, h_m: ArrayLike,
                        centre: tuple[float, float], reference: GeoDEM,
                        cfg: SurfaceMatchConfig = SurfaceMatchConfig()
                        ) -> tuple[FloatArray, FloatArray]:
    """The correlation of one window over the whole grid of shifts (Goncalves's Fig. 5).

    Same inputs as :func:`match_window`. Returns the shifts ``(n,)`` in arcseconds (the same
    for dlon and dlat: ``-cfg.shift_max_arcsec .. +cfg.shift_max_arcsec`` every
    ``cfg.shift_step_arcsec``) and the correlation ``(n, n)`` indexed ``[dlat, dlon]``, NaN
    where fewer than ``cfg.min_cells`` pairs are valid (all NaN for an empty window).
    """
    cell = cfg.cell_m if cfg.cell_m is not None else reference.cell_size_m()
    cells = window_cells(lon_deg, lat_deg, h_m, centre, cfg.radius_m, cell)
    grid = _grid(cfg.shift_max_arcsec, cfg.shift_step_arcsec)
    if np.count_nonzero(np.isfinite(cells.h_m)) < cfg.min_cells:
        return grid, np.full((grid.size, grid.size), np.nan)
    gx, gy = np.meshgrid(grid, grid)
    rho = _valid_rho(cells, reference, gx.ravel(), gy.ravel(), cfg.min_cells, cfg.detrend)
    return grid, rho.reshape(gx.shape)
