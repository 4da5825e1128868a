"""SRTM surface matching (step 3 of the chain, Goncalves 3.3): simulated GCPs from the
reference DEM alone. How GCPs are made is here, from the windows to the points.

**One window** (:func:`match_window`). Around a tie point, the relative DEM's cells within a
radius (heights ``h'``, ellipsoidal, in the frame the relative orientation left them) are
compared with the reference DEM (SRTM + EGM96, ellipsoidal) shifted by ``(dlon, dlat)`` over a
grid of shifts (default -20" .. +20" every 1"): the correlation coefficient of the two height
sets is computed for every shift at once, its peak refined to a fraction of an arcsecond by a
quadratic fit (:func:`core.matching.peaks.quadratic_peak`; then, optionally, a finer grid
around it), and the vertical shift is the robust mean of the height differences at the refined
position (:func:`core.robust.robust_fit`). The window's local 3-D shift moves the tie point's
relative ground coordinates onto the reference.

Cells are first averaged onto a lattice of about the reference's cell size (finer detail is
absent from SRTM and would only cost time; :mod:`core.matching.lattice`). The correlation is
least squares and follows the relative DEM's gross blunders (dense matching leaves some 8 % of
cells tens to hundreds of metres off, in clusters), so they are kept out of it: spikes before
the search, then the cells far from the reference at the peak, and the peak searched again
without them. Quality of a window: peak correlation, the peak's sharpness turned into a
horizontal precision in metres, the relief (std of the ``h'`` correlated), the number of cells,
the share of the window masked (mismatched cells or reference voids), and a precision predicted
from the relief before matching (relief sufficiency): with RMS slope ``g`` and height noise
``s`` over ``N`` independent patches (the window's area over the squared correlation length of
the reference's errors) the shift is known to about ``s / (g sqrt(N))``.

**The scene.** :func:`choose_windows` puts one window per ground cell on the best tie point;
:func:`search_windows` searches the first :data:`FIRST_PASS` windows over the whole shift range,
the others around the shift an affine fit of those predicts (:func:`shift_prior`), and a window
whose peak falls on the border of its prior box again over the whole range;
:func:`gcps_from_windows` makes a GCP of every good window. Whether the scene's relief can
orient it at all is :mod:`core.matching.relief`. No I/O here: the task reads the windows' cells
and runs them on Dask threads.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from enum import IntEnum
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.dem import GeoDEM
from core.errors import InputError
from core.geodesy import ARCSEC, geodetic_to_enu, metres_per_degree
from core.matching.lattice import (
    WindowCells,
    basis_at,
    correlations,
    curvature_m,
    despike,
    differences,
    inflation_at,
    relief_m,
    site,
    surface_basis,
    window_cells,
)
from core.matching.peaks import peak_hessian, quadratic_peak
from core.matching.tiepoints import best_per_cell
from core.points import ControlPoint, ImagePoint
from core.robust import nmad, robust_fit

FloatArray = NDArray[np.float64]
Locate = Callable[[float, float, float], Mapping[str, tuple[float, float]]]  # -> (col, row)

#: a window whose height differences from the reference at its peak depart from their plane
#: by a quadratic of this RMS (m) at least, and by 3 times its noise, is compared about
#: quadratics (about 1.7 times this at the centre the plane would put into its GCP's height)
CURVED_M = 1.0
#: at the peak, a cell further from the reference than this many robust spreads is a blunder,
#: and the peak is searched again without the blunders at most ``BLUNDER_ROUNDS`` times
BLUNDER_K = 3.0
BLUNDER_ROUNDS = 2


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
    exceeds ``max_precision_m``: 20 m, because on a low-relief simulated pair (26 m of relief
    per window) the windows' honest precisions were 10-20 m, their GCPs' errors matching them,
    and 30 of them oriented the pair to 0.3 px where a 10 m limit left 2; each GCP is weighted
    by its own precision, the limit only refuses windows too vague to help. ``detrend``:
    compare the two surfaces about their best-fit planes (the relative DEM may be tilted: an
    along-epipolar drift that tie points cannot see tilts it by metres per kilometre), and
    about quadratics where the window is curved (:data:`CURVED_M`: a lens the delivered models
    miss, :func:`core.matching.lattice.surface_basis`), the vertical shift then being that
    surface's height at the window's centre; 2: quadratics everywhere; False: constants.
    """

    radius_m: float = 4000.0
    shift_max_arcsec: float = 20.0
    shift_step_arcsec: float = 1.0
    cell_m: float | None = None
    refine_step_arcsec: float | None = 0.1
    min_cells: int = 100
    max_masked_share: float = 0.5
    min_correlation: float = 0.6
    max_precision_m: float = 20.0
    height_noise_m: float = 5.0
    error_length_m: float = 300.0
    detrend: bool | int = True

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
    a reference height too): a scene smaller than a window fills few of them. ``at_lon_deg``,
    ``at_lat_deg``, ``at_h_m``: the relative point the shift holds at, the lattice cell
    nearest the centroid of the cells matched (:func:`core.matching.lattice.site`; the tie
    point's neighbourhood unless the DEM's edge cuts the window), the vertical shift being
    the difference surface's height there.
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
    at_lon_deg: float = float("nan")
    at_lat_deg: float = float("nan")
    at_h_m: float = float("nan")

    @property
    def ok(self) -> bool:
        return self.status == WindowStatus.OK

    def to_dict(self) -> dict[str, Any]:
        """The fields as a GCP's ``provenance`` holds them (status by name, NaN as None);
        windows.json is written by :data:`tasks.absolute.surface_match.WINDOWS`."""
        d = dict(vars(self))
        d["status"] = self.status.name
        return {k: (None if isinstance(v, float) and not np.isfinite(v) else v)
                for k, v in d.items()}


def _valid_rho(cells: WindowCells, reference: GeoDEM, sx_arcsec: FloatArray,
               sy_arcsec: FloatArray, min_cells: int, detrend: bool | int) -> FloatArray:
    """Correlations at shifts (arcsec), NaN where fewer than ``min_cells`` pairs are valid."""
    rho, count = correlations(cells, reference, np.stack([sx_arcsec, sy_arcsec], 1) * ARCSEC,
                               detrend)
    return np.where(count >= min_cells, rho, np.nan)


def _grid(half: float, step: float) -> FloatArray:
    n = int(round(half / step))
    return np.arange(-n, n + 1) * step


def predicted_precision_m(cells: WindowCells, cfg: SurfaceMatchConfig) -> tuple[float, float,
                                                                                 float, int]:
    """(precision m, relief m, RMS slope, independent patches) the window's relief promises.

    With ``cfg.detrend`` the relief and the slopes are those of the heights about their
    best-fit plane (or quadratic, :func:`core.matching.lattice.surface_basis`): it carries no
    information once the window's tilt (and curvature) are free.
    """
    h = cells.h_m.copy()
    ok = np.isfinite(h)
    if cfg.detrend and ok.sum() > 6:
        b = surface_basis(cells, ok, cfg.detrend)
        h[ok] -= b @ np.linalg.lstsq(b, h[ok], rcond=None)[0]
    gy, gx = np.gradient(h.reshape(cells.shape), cells.cell_m)
    g2 = gx**2 + gy**2
    ok = np.isfinite(g2)
    relief = relief_m(cells, cfg.detrend)
    if ok.sum() < 3:
        return float("inf"), relief, 0.0, 0
    slope = float(np.sqrt(np.mean(g2[ok])))
    area = ok.sum() * cells.cell_m**2
    n_eff = max(int(area / max(cfg.error_length_m, cells.cell_m) ** 2), 1)
    if slope <= 0:
        return float("inf"), relief, slope, n_eff
    return cfg.height_noise_m / (slope * np.sqrt(n_eff)), relief, slope, n_eff


@dataclass(frozen=True)
class _Peak:
    """The correlation peak of a search: shift (arcsec), Hessian per arcsec squared, the best
    correlation; or why there is none (``status``, with the best correlation when known)."""

    status: WindowStatus
    sx: float = float("nan")
    sy: float = float("nan")
    hess: FloatArray | None = None
    correlation: float = float("nan")


def _search(cells: WindowCells, reference: GeoDEM, cfg: SurfaceMatchConfig,
            prior: tuple[float, float, float] | None) -> _Peak:
    """The correlation peak over the shift grid (within the ``prior`` box if any): every other
    step first, then every step around the best, and a quadratic fit (:func:`_refined` then
    refines it on the fine grid)."""
    grid = _grid(cfg.shift_max_arcsec, cfg.shift_step_arcsec)
    gx, gy = np.meshgrid(grid, grid)
    rho = np.full(gx.shape, np.nan)
    box = np.ones(gx.shape, dtype=bool)
    if prior is not None:
        box = (np.abs(gx - prior[0]) <= prior[2]) & (np.abs(gy - prior[1]) <= prior[2])
        if not box.any():
            return _Peak(WindowStatus.EDGE_PEAK)
    coarse = np.zeros(gx.shape, dtype=bool)
    coarse[::2, ::2] = True
    coarse &= box
    rho[coarse] = _valid_rho(cells, reference, gx[coarse], gy[coarse], cfg.min_cells,
                              cfg.detrend)
    if not np.isfinite(rho).any():
        return _Peak(WindowStatus.MASKED)
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
        return _Peak(WindowStatus.EDGE_PEAK, correlation=float(rho[iy, ix]))
    patch = rho[iy - 1:iy + 2, ix - 1:ix + 2]
    if not np.all(np.isfinite(patch)):
        return _Peak(WindowStatus.MASKED)
    (dx,), (dy,) = quadratic_peak(patch)
    step = cfg.shift_step_arcsec
    sx, sy = grid[ix] + dx * step, grid[iy] + dy * step
    hess = peak_hessian(patch)[0] / step**2  # per arcsec squared
    return _Peak(WindowStatus.OK, float(sx), float(sy), hess, float(np.nanmax(rho)))


def _refined(cells: WindowCells, reference: GeoDEM, cfg: SurfaceMatchConfig,
             peak: _Peak) -> _Peak:
    """The peak refined on the fine grid (``cfg.refine_step_arcsec``, none: as it is) over the
    half step around it the quadratic fit on the search grid is good to (0.2")."""
    if cfg.refine_step_arcsec is None or peak.status != WindowStatus.OK:
        return peak
    fine = _grid(0.5 * cfg.shift_step_arcsec, cfg.refine_step_arcsec)
    fx, fy = np.meshgrid(peak.sx + fine, peak.sy + fine)
    rf, _ = correlations(cells, reference, np.stack([fx.ravel(), fy.ravel()], 1) * ARCSEC,
                          cfg.detrend)
    rf = rf.reshape(fx.shape)
    if not np.isfinite(rf).all():
        return peak
    jy, jx = np.unravel_index(int(np.argmax(rf)), rf.shape)
    jy = int(np.clip(jy, 1, rf.shape[0] - 2))
    jx = int(np.clip(jx, 1, rf.shape[1] - 2))
    (ddx,), (ddy,) = quadratic_peak(rf[jy - 1:jy + 2, jx - 1:jx + 2])
    return replace(peak, sx=float(fx[jy, jx] + ddx * cfg.refine_step_arcsec),
                   sy=float(fy[jy, jx] + ddy * cfg.refine_step_arcsec))


def _vertical(cells: WindowCells, reference: GeoDEM, peak: _Peak, cfg: SurfaceMatchConfig,
              at: tuple[float, float] = (0.0, 0.0)) -> tuple[float, float, NDArray[np.bool_]]:
    """(vertical shift at ``at`` (m from the centre), robust spread, blunders) of the height
    differences at the peak's shift (:func:`core.matching.lattice.differences`): their robust
    :func:`core.matching.lattice.surface_basis` (plane, quadratic or constant) moved to their
    dominant mode (:func:`core.robust.robust_fit`), and the lattice cells further than
    :data:`BLUNDER_K` spreads from it."""
    both, diff = differences(cells, reference, peak.sx, peak.sy)
    basis = surface_basis(cells, both, cfg.detrend)
    coef, spread = robust_fit(diff, basis, mode_scale_m=cfg.height_noise_m)
    far = np.zeros(cells.h_m.size, dtype=bool)
    far[both] = np.abs(diff - basis @ coef) > BLUNDER_K * max(spread, cfg.height_noise_m)
    return float(basis_at(*at, cfg.detrend)[0] @ coef), float(spread), far


def _without_blunders(cells: WindowCells, reference: GeoDEM, cfg: SurfaceMatchConfig,
                      prior: tuple[float, float, float] | None
                      ) -> tuple[WindowCells, _Peak, float, float]:
    """(cells kept, their peak, vertical shift, spread): the peak searched, then, at most
    :data:`BLUNDER_ROUNDS` times, searched again around it without the cells :func:`_vertical`
    finds far from the reference there (over the whole range when the blunders had moved the
    first peak further than the box around it), until it moves less than a tenth of a step;
    refined on the fine grid once, at the end."""
    peak = _search(cells, reference, cfg, prior)
    if peak.status != WindowStatus.OK:
        return cells, peak, float("nan"), float("nan")
    far = _vertical(cells, reference, peak, cfg)[2]
    box = 2.5 * cfg.shift_step_arcsec
    for _ in range(BLUNDER_ROUNDS):
        kept = replace(cells, h_m=np.where(far, np.nan, cells.h_m))
        if not far.any() or np.count_nonzero(np.isfinite(kept.h_m)) < cfg.min_cells:
            break
        again = _search(kept, reference, cfg, (peak.sx, peak.sy, box))
        if again.status != WindowStatus.OK:  # the peak left the box (or its edge)
            again = _search(kept, reference, cfg, prior)
        if again.status != WindowStatus.OK:
            break
        moved = float(np.hypot(again.sx - peak.sx, again.sy - peak.sy))
        cells, peak = kept, again
        if moved < 0.1 * cfg.shift_step_arcsec:  # the blunders did not hold the peak
            break
        far = _vertical(cells, reference, peak, cfg)[2]
    peak = _refined(cells, reference, cfg, peak)
    k = site(cells)
    dz, spread, _ = _vertical(cells, reference, peak, cfg, (cells.x_m[k], cells.y_m[k]))
    return cells, peak, dz, spread


def match_window(lon_deg: ArrayLike, lat_deg: ArrayLike, h_m: ArrayLike,
                 centre: tuple[float, float], reference: GeoDEM,
                 cfg: SurfaceMatchConfig = SurfaceMatchConfig(),
                 prior: tuple[float, float, float] | None = None) -> WindowMatch:
    """The local 3-D shift of the relative DEM around ``centre`` (lon, lat degrees) onto the
    reference. ``lon_deg``, ``lat_deg``, ``h_m``: the relative DEM's cells (NaN heights: cells
    the matching could not fill), at least those within ``cfg.radius_m``.

    ``prior``: (dlon, dlat, half-width) in arcseconds, the shift expected from other windows:
    only shifts within the half-width of it are searched (inside the ``cfg`` range); a peak
    on the border of that box is ``EDGE_PEAK`` (search again without the prior).

    Blunders of the relative DEM are kept out of the correlation, which is least squares and
    follows them: spikes first (:func:`despike`), then, at the peak, cells further than
    :data:`BLUNDER_K` robust spreads from the reference (at least ``cfg.height_noise_m``), and
    the peak is searched again around the first one without them (at most
    :data:`BLUNDER_ROUNDS` times). The relief is the spread of the heights correlated. The
    shift holds where the cells matched are (``at_*``: :func:`core.matching.lattice.site`),
    not at ``centre`` when the DEM's edge cuts the window."""
    m_lon, m_lat = (float(v) for v in metres_per_degree(centre[1]))
    cell = cfg.cell_m if cfg.cell_m is not None else reference.cell_size_m()
    raw = window_cells(lon_deg, lat_deg, h_m, centre, cfg.radius_m, cell)
    return _matched(raw, reference, cfg, prior, (m_lon, m_lat))[0]


def _matched(raw: WindowCells, reference: GeoDEM, cfg: SurfaceMatchConfig,
             prior: tuple[float, float, float] | None, m_per_deg: tuple[float, float]
             ) -> tuple[WindowMatch, WindowCells, SurfaceMatchConfig]:
    """:func:`match_window` on the window's lattice ``raw``, with the cells it correlated last
    (despiked, without the blunders) and the configuration it used (its ``detrend``: plane or
    quadratic)."""
    m_lon, m_lat = m_per_deg
    valid = np.isfinite(raw.h_m)
    paired = valid.copy()  # and a reference height there
    paired[valid] = np.isfinite(reference.height_m(raw.lon_deg[valid], raw.lat_deg[valid]))
    masked = 1.0 - paired.sum() / max(raw.n_disk, 1)  # mismatched cells or reference voids
    cells = despike(raw)
    valid = np.isfinite(cells.h_m)
    n_pairs = int(np.count_nonzero(paired & valid))
    pred, relief, slope, n_eff = predicted_precision_m(cells, cfg)
    base = dict(relief_m=relief, rms_slope=slope, n_cells=n_pairs, masked_share=masked,
                predicted_precision_m=pred, n_dem_cells=int(valid.sum()))
    if n_pairs < cfg.min_cells:
        return WindowMatch(WindowStatus.TOO_FEW_CELLS, **base), cells, cfg
    if masked > cfg.max_masked_share:
        return WindowMatch(WindowStatus.MASKED, **base), cells, cfg
    if not pred <= cfg.max_precision_m:
        return WindowMatch(WindowStatus.LOW_RELIEF, **base), cells, cfg
    start = cells
    cells, peak, dz, spread = _without_blunders(cells, reference, cfg, prior)
    if cfg.detrend == 1 and peak.status == WindowStatus.OK:  # planes (True): curved?
        q, noise = curvature_m(cells, reference, peak.sx, peak.sy, cfg.height_noise_m, n_eff)
        if q > max(CURVED_M, 3.0 * noise):
            cfg = replace(cfg, detrend=2)
            cells, peak, dz, spread = _without_blunders(start, reference, cfg, prior)
    if peak.status != WindowStatus.OK:
        return WindowMatch(peak.status, correlation=peak.correlation, **base), cells, cfg
    relief = relief_m(cells, cfg.detrend)
    # precision: near its peak rho(s) ~ 1 - k s^2 / 2 with k = slope^2 / relief^2 along the
    # flattest direction (the peak's curvature, per m^2); least squares then knows the shift to
    # spread / (slope sqrt(N)) = spread / (relief sqrt(k N)) over N independent patches
    scale = np.diag([1.0 / (ARCSEC * m_lon), 1.0 / (ARCSEC * m_lat)])  # arcsec per metre
    curv = float(np.min(np.abs(np.linalg.eigvalsh(scale @ peak.hess @ scale))))
    precision = (float(spread / (relief * np.sqrt(curv * n_eff))) if curv > 0 and relief > 0
                 else float("inf"))
    k = site(cells)
    result = WindowMatch(
        WindowStatus.OK, shift_lon_arcsec=peak.sx, shift_lat_arcsec=peak.sy,
        shift_h_m=dz, shift_east_m=float(peak.sx * ARCSEC * m_lon),
        shift_north_m=float(peak.sy * ARCSEC * m_lat), correlation=peak.correlation,
        precision_m=precision, precision_h_m=float(spread * np.sqrt(inflation_at(
            cells, cfg.detrend, cells.x_m[k], cells.y_m[k]) / max(n_eff, 1))),
        spread_m=float(spread), at_lon_deg=float(cells.lon_deg[k]),
        at_lat_deg=float(cells.lat_deg[k]), at_h_m=float(cells.h_m[k]),
        **{**base, "relief_m": relief})
    if peak.correlation < cfg.min_correlation:
        result = WindowMatch(**{**vars(result), "status": WindowStatus.LOW_CORRELATION})
    elif not precision <= cfg.max_precision_m:
        result = WindowMatch(**{**vars(result), "status": WindowStatus.IMPRECISE})
    return result, cells, cfg


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
    scatter = nmad(res - np.median(res, axis=0), centre=0.0)  # each axis about its median
    half = max(min_half_arcsec, 4.0 * scatter + 1.0)
    ln, lt = np.asarray(lon_new, float), np.asarray(lat_new, float)
    b = np.stack([np.ones(ln.size), ln.ravel() - lon0, lt.ravel() - lat0], axis=1)
    pred = b @ coef
    return np.column_stack([pred, np.full(len(pred), half)])


#: windows searched over the whole shift range before the others are searched around the shift
#: those predict (:func:`search_windows`)
FIRST_PASS = 24
#: the least vertical precision a GCP states (m): a window's robust spread over many patches
#: can promise centimetres that the reference's own errors do not allow
MIN_GCP_SIGMA_H_M = 0.5
#: ``match(indices, priors)``: the windows ``indices`` matched, with ``priors`` (n, 3) as
#: :func:`match_window`'s ``prior`` (None: the whole range), in that order
MatchWindows = Callable[[NDArray[np.intp], FloatArray | None], Sequence[WindowMatch]]


def choose_windows(lon_deg: ArrayLike, lat_deg: ArrayLike, h_m: ArrayLike, score: ArrayLike,
                   spacing_m: float) -> NDArray[np.intp]:
    """Window centres: indices of the tie points (relative ground lon, lat, h) that are the
    best (highest ``score``) of their ``spacing_m`` ground cell, so that the windows spread over
    the overlap without overlapping much."""
    lon, lat, h = (np.asarray(v, dtype=np.float64) for v in (lon_deg, lat_deg, h_m))
    origin = (float(np.median(lon)), float(np.median(lat)), float(np.median(h)))
    e, n, _ = geodetic_to_enu(lon, lat, h, origin)
    return best_per_cell(e, n, score, spacing_m)


def first_pass_mask(n_windows: int, first_pass: int = FIRST_PASS) -> NDArray[np.bool_]:
    """The windows :func:`search_windows` searches over the whole range first: ``first_pass``
    of them spread evenly over the list (which :func:`choose_windows` orders by ground cell)."""
    first = np.zeros(n_windows, dtype=bool)
    first[np.unique(np.linspace(0, n_windows - 1, min(first_pass, n_windows))
                    .round().astype(int))] = True
    return first


def search_windows(lon_deg: ArrayLike, lat_deg: ArrayLike, match: MatchWindows,
                   first_pass: int = FIRST_PASS) -> list[WindowMatch]:
    """Every window (centres at ``lon_deg``, ``lat_deg``) matched in two passes: the
    :func:`first_pass_mask` windows over the whole shift range, then the others around the
    shift an affine fit of the first ones' predicts (:func:`shift_prior`; the whole range when
    too few of them matched), and a window whose peak falls on the border of its prior box
    (``EDGE_PEAK``) again over the whole range. ``match`` runs the windows (:data:`MatchWindows`).
    """
    lon, lat = np.asarray(lon_deg, dtype=np.float64), np.asarray(lat_deg, dtype=np.float64)
    first = first_pass_mask(lon.size, first_pass)
    head, rest = np.flatnonzero(first), np.flatnonzero(~first)
    found = dict(zip(head.tolist(), match(head, None), strict=True))
    if rest.size:
        priors = shift_prior(lon[head], lat[head], [found[k] for k in head.tolist()],
                             lon[rest], lat[rest])
        found.update(zip(rest.tolist(), match(rest, priors), strict=True))
        if priors is not None:
            again = np.array([k for k in rest.tolist()
                              if found[k].status == WindowStatus.EDGE_PEAK], dtype=np.intp)
            if again.size:
                found.update(zip(again.tolist(), match(again, None), strict=True))
    return [found[k] for k in range(lon.size)]


def gcps_from_windows(centres: ArrayLike, matches: Sequence[WindowMatch], lon_deg: ArrayLike,
                      lat_deg: ArrayLike, h_m: ArrayLike,
                      image_points: Mapping[str, tuple[ArrayLike, ArrayLike]],
                      locate: Locate | None = None) -> tuple[ControlPoint, ...]:
    """A GCP of every good window: the relative point its shift holds at (``at_*``) moved by
    its 3-D shift, measured where its centre tie point (index into ``lon_deg``, ``lat_deg``,
    ``h_m``, the relative ground coordinates) is in each image (``image_points``: image name
    -> (col, row) arrays indexed like the tie points) moved by what ``locate`` (the models the
    relative DEM was made with) says of the way from the tie point to that point: their own
    parallax (a lens they miss) stays out of it, which the point they project carries (20 m of
    miss at the swath's end of simulated hrs with ``--lens``). Without ``locate`` (or ``at_*``:
    an older file), the tie point. With the window's precisions (the vertical one at least
    :data:`MIN_GCP_SIGMA_H_M`) and figures (``provenance``)."""
    lon, lat, h = (np.asarray(v, dtype=np.float64) for v in (lon_deg, lat_deg, h_m))
    pts = {name: (np.asarray(c, dtype=np.float64), np.asarray(r, dtype=np.float64))
           for name, (c, r) in image_points.items()}
    gcps: list[ControlPoint] = []
    for i, m in zip(np.asarray(centres, dtype=np.intp), matches, strict=True):
        if m.status != WindowStatus.OK:
            continue
        p = (lon[i], lat[i], h[i])
        seen = {name: (float(c[i]), float(r[i])) for name, (c, r) in pts.items()}
        if locate is not None and np.isfinite([m.at_lon_deg, m.at_lat_deg, m.at_h_m]).all():
            at, tie = locate(m.at_lon_deg, m.at_lat_deg, m.at_h_m), locate(*p)  # see above
            seen = {n: (cr[0] + at[n][0] - tie[n][0], cr[1] + at[n][1] - tie[n][1])
                    for n, cr in seen.items()}
            p = (m.at_lon_deg, m.at_lat_deg, m.at_h_m)
        gcps.append(ControlPoint(
            id=len(gcps) + 1,
            lon_deg=float(p[0] + m.shift_lon_arcsec * ARCSEC),
            lat_deg=float(p[1] + m.shift_lat_arcsec * ARCSEC),
            h_m=float(p[2] + m.shift_h_m),
            image_points={name: ImagePoint(*cr) for name, cr in seen.items()},
            sigma_xy_m=m.precision_m, sigma_h_m=max(m.precision_h_m, MIN_GCP_SIGMA_H_M),
            source="srtm_surface_match", provenance={"tie_point": int(i), **m.to_dict()}))
    return tuple(gcps)


def correlation_surface(lon_deg: ArrayLike, lat_deg: ArrayLike, h_m: ArrayLike,
                        centre: tuple[float, float], reference: GeoDEM,
                        cfg: SurfaceMatchConfig = SurfaceMatchConfig()
                        ) -> tuple[FloatArray, FloatArray]:
    """The correlation of one window over the whole grid of shifts (Goncalves's Fig. 5).

    Same inputs as :func:`match_window`, and the same cells and comparison: despiked, without
    the blunders found at the peak (searched over the whole range), about planes or quadratics
    as the window was. Returns the shifts ``(n,)`` in
    arcseconds (the same for dlon and dlat: ``-cfg.shift_max_arcsec ..
    +cfg.shift_max_arcsec`` every ``cfg.shift_step_arcsec``) and the correlation ``(n, n)``
    indexed ``[dlat, dlon]``, NaN where fewer than ``cfg.min_cells`` pairs are valid (all NaN
    for an empty window).
    """
    cell = cfg.cell_m if cfg.cell_m is not None else reference.cell_size_m()
    raw = window_cells(lon_deg, lat_deg, h_m, centre, cfg.radius_m, cell)
    grid = _grid(cfg.shift_max_arcsec, cfg.shift_step_arcsec)
    if np.count_nonzero(np.isfinite(raw.h_m)) < cfg.min_cells:
        return grid, np.full((grid.size, grid.size), np.nan)
    m_lon, m_lat = (float(v) for v in metres_per_degree(centre[1]))
    _, cells, cfg = _matched(raw, reference, cfg, None, (m_lon, m_lat))
    gx, gy = np.meshgrid(grid, grid)
    rho = _valid_rho(cells, reference, gx.ravel(), gy.ravel(), cfg.min_cells, cfg.detrend)
    return grid, rho.reshape(gx.shape)
