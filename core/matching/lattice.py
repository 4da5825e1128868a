"""The relative DEM in a surface-matching window, on a lattice of about the reference's cell
size (:func:`window_cells`), and without its spikes (:func:`despike`): the cells
:func:`core.matching.surface.match_window` correlates with the reference (:func:`correlations`)
about their plane or, where they are curved (:func:`curvature_m`), their quadratic surface
(:func:`surface_basis`), the place their shift holds at (:func:`site`), and their relief
(:func:`relief_m`). No I/O here.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numba
import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from numpy.typing import ArrayLike, NDArray

from core.dem import GeoDEM
from core.geodesy import ARCSEC, metres_per_degree
from core.robust import nmad, robust_fit

FloatArray = NDArray[np.float64]

#: a lattice cell further from its 5 x 5 neighbourhood's median than this many robust spreads
#: of those departures is a spike of the relative DEM (:func:`despike`)
DESPIKE_K = 3.0


@dataclass(frozen=True, eq=False)
class WindowCells:
    """The relative DEM in a window, averaged on a lattice: height ``h_m`` of each lattice cell
    (NaN when no valid relative cell fell in it) and where it is, lon/lat (degrees) and x/y (m
    from the centre): the mean position of the cells averaged (the lattice cell's centre when
    none), ``cell_m`` its size."""

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
    complete input receives a value whatever the grids' orientations. A lattice cell's height is
    placed where the cells it averages are, not at its centre: a lattice cell of 113 m holds 1-4
    of tiny's 80 m cells, off its centre by up to half a cell, and at the DEM's edge only its
    inner part (a window cut there then measured the terrain up to 3 m off, 1.2 m RMS whole)."""
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
    count = np.bincount(idx[good], minlength=n_side * n_side)
    gx = (np.arange(n_side) + 0.5) * cell_m - n_side * cell_m / 2
    xx, yy = (g.ravel() for g in np.meshgrid(gx, gx))
    in_disk = np.hypot(xx, yy) <= radius_m
    has = count > 0
    mean = np.full(n_side * n_side, np.nan)
    for out, value in ((mean, hv), (xx, x[inside][keep]), (yy, y[inside][keep])):
        total = np.bincount(idx[good], weights=value[good], minlength=n_side * n_side)
        out[has] = total[has] / count[has]  # a cell's mean height is where its inputs are
    mean = np.where(in_disk, mean, np.nan)
    return WindowCells(centre[0] + xx / float(m_lon), centre[1] + yy / float(m_lat),
                       mean, xx, yy, float(cell_m), (n_side, n_side),
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


def site(cells: WindowCells) -> int:
    """The lattice cell a window's shift is placed at: the one with a height nearest to the
    centroid of those with heights (the window's centre when they surround it).

    A window measures the relative DEM's deformation where its cells are, and where the
    deformation varies (a lens the delivered models miss makes it steepest at the swath's
    ends, 15 m/km on simulated tiny with ``--lens``) a window the DEM's edge cuts measures it
    up to 2 km inward of its tie point. Placed at the tie point, the swath's end GCPs were 10-17
    m off east, which the lens terms extrapolated to the image's edges. Kept point-symmetric
    about the tie point instead (a window the edge cuts losing the cells whose reflection has
    no height: about half of them), the 168 cut windows of the eight tiny scenes of
    ``bench/validation/uncertainty_sweep.py`` were 11.1 m RMS off per horizontal axis (stated precision
    8.5 m); matched whole and placed at the tie point, 8.4 m; placed here, 7.3 m (4.1 m
    stated). The centroid weighted by the squared slopes (the correlation's sensitivity) gave
    7.2 m."""
    ok = np.isfinite(cells.h_m)
    if not ok.any():
        return int(np.argmin(np.hypot(cells.x_m, cells.y_m)))
    cx, cy = float(np.mean(cells.x_m[ok])), float(np.mean(cells.y_m[ok]))
    d = np.where(ok, np.hypot(cells.x_m - cx, cells.y_m - cy), np.inf)
    return int(np.argmin(d))


def despike(cells: WindowCells, k: float = DESPIKE_K, size: int = 5) -> WindowCells:
    """The window's lattice without its spikes: cells whose height departs from the median of
    their ``size`` x ``size`` neighbourhood by more than ``k`` robust spreads (:func:`nmad`) of
    those departures over the window become NaN (mismatched). Dense matching leaves gross
    blunders in the relative DEM (patches tens to hundreds of metres off, clustered next to
    mismatched cells); they inflate the heights' spread and pull the least-squares correlation
    off the true shift (1.8 px of bias in columns on a low-relief simulated pair)."""
    n = size // 2
    h = cells.h_m.reshape(cells.shape)
    if np.count_nonzero(np.isfinite(h)) < 2 * size * size:
        return cells
    padded = np.pad(h, n, constant_values=np.nan)
    hoods = sliding_window_view(padded, (size, size)).reshape(h.size, size * size)
    some = np.isfinite(hoods).any(axis=1)  # an all-NaN neighbourhood has no median
    local = np.full(h.size, np.nan)
    local[some] = np.nanmedian(hoods[some], axis=1)
    local = local.reshape(h.shape)
    dev = h - local
    fin = np.isfinite(dev)
    scale = nmad(dev[fin], centre=0.0)
    if not scale > 0:
        return cells
    spike = fin & (np.abs(dev) > k * scale)
    if not spike.any():
        return cells
    return replace(cells, h_m=np.where(spike.ravel(), np.nan, cells.h_m))


def surface_basis(cells: WindowCells, ok: NDArray[np.bool_], detrend: int) -> FloatArray:
    """Regressors removed from the cells ``ok`` before they are compared with the reference: a
    constant; with ``detrend`` >= 1 (True) a plane, with 2 a quadratic surface (x, y in
    kilometres from the centre, for conditioning; the constant is the value at the centre).

    The relative DEM of a pair whose delivered models miss a lens or a look-angle error is
    curved across the swath (simulated tiny with ``--lens``: the windows' vertical shift +80 m
    at one end, 0 in the middle, -68 m at the other, 5 m/km2 near the ends). About a plane
    that curvature biased the window's height at the centre by the curvature times R^2 / 4
    (the GCPs' height errors followed the vertical shift, +4 to -5 m across the swath) and,
    where the terrain shares it, its horizontal shift (-6 to -14 m east at the swath's end,
    which the lens terms extrapolated to -0.45 px of check-point columns beyond the last GCP).
    A quadratic also takes the terrain's own large-scale shape out of the comparison (the
    window relief at relief x 0.15, 23.5 m about planes, is 19 m about quadratics), so windows
    go quadratic only where they are curved (:func:`core.matching.surface.match_window`).
    """
    return basis_at(cells.x_m[ok], cells.y_m[ok], detrend)


def basis_at(x_m: ArrayLike, y_m: ArrayLike, detrend: int) -> FloatArray:
    """:func:`surface_basis`'s regressors at the points ``x_m``, ``y_m`` (m from the centre)."""
    x = np.atleast_1d(np.asarray(x_m, dtype=np.float64)) / 1000.0
    y = np.atleast_1d(np.asarray(y_m, dtype=np.float64)) / 1000.0
    one = np.ones(x.size)
    if not detrend:
        return one[:, None]
    if int(detrend) < 2:
        return np.stack([one, x, y], axis=1)
    return np.stack([one, x, y, x * x, x * y, y * y], axis=1)


def correlations(cells: WindowCells, reference: GeoDEM, shifts_deg: FloatArray,
                 detrend: bool | int = True) -> tuple[FloatArray, FloatArray]:
    """Correlation coefficient (partial: about the best :func:`surface_basis` of ``detrend``,
    of each set over the pairs valid at that shift) and valid-pair count for each (dlon, dlat)
    shift (n, 2).

    The sums over the pairs valid at each shift come from one compiled pass over the shifts
    and cells (:func:`_pair_sums`, the reference sampled bilinearly as
    :func:`core.dem.sample_bilinear` samples it: NaN outside or next to a void), the small
    normal equations of each shift are then solved together."""
    ok = np.isfinite(cells.h_m)
    lon, lat = cells.lon_deg[ok], cells.lat_deg[ok]
    h0 = float(np.mean(cells.h_m[ok]))  # near the reference's heights: conditioning only
    h = cells.h_m[ok] - h0
    b = np.ascontiguousarray(surface_basis(cells, ok, detrend))
    n, k = len(shifts_deg), b.shape[1]
    gram, bh, br = np.zeros((n, k, k)), np.zeros((n, k)), np.zeros((n, k))
    sums = np.zeros((n, 4))  # h h, r r, r h, count
    x0, y0, dx, dy = (float(a) for a in reference.axes)
    _pair_sums(np.ascontiguousarray(lon), np.ascontiguousarray(lat), np.ascontiguousarray(h),
               b, np.ascontiguousarray(reference.values), x0, y0, dx, dy, h0,
               np.ascontiguousarray(shifts_deg, dtype=np.float64), gram, bh, br, sums)
    with np.errstate(invalid="ignore", divide="ignore"):
        try:
            sol_h = np.linalg.solve(gram, bh[:, :, None])[:, :, 0]
            sol_r = np.linalg.solve(gram, br[:, :, None])[:, :, 0]
        except np.linalg.LinAlgError:  # a shift with too few pairs: solve one by one
            sol_h, sol_r = _lstsq_each(gram, bh), _lstsq_each(gram, br)
        hh = sums[:, 0] - np.sum(bh * sol_h, axis=1)
        rr = sums[:, 1] - np.sum(br * sol_r, axis=1)
        hr = sums[:, 2] - np.sum(bh * sol_r, axis=1)
        rho = hr / np.sqrt(hh * rr)
    return rho, sums[:, 3]


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _pair_sums(lon: FloatArray, lat: FloatArray, h: FloatArray, b: FloatArray,
               z: NDArray[np.floating], x0: float, y0: float, dx: float, dy: float, h0: float,
               shifts: FloatArray, gram: FloatArray, bh: FloatArray, br: FloatArray,
               sums: FloatArray) -> None:
    """For each shift ``s`` (dlon, dlat degrees), over the cells whose shifted position has a
    reference height ``r`` (bilinear in ``z``, its node ``(x0, y0)``, steps ``dx``, ``dy``;
    ``r - h0``): sum of ``b b'`` into ``gram[s]``, of ``b h`` into ``bh[s]``, of ``b r`` into
    ``br[s]``, and of ``h h``, ``r r``, ``r h`` and the count into ``sums[s]``."""
    nr, nc = z.shape
    k = b.shape[1]
    for s in range(shifts.shape[0]):
        for c in range(lon.size):
            fi = (lat[c] + shifts[s, 1] - y0) / dy
            fj = (lon[c] + shifts[s, 0] - x0) / dx
            if not (fi >= 0 and fi <= nr - 1 and fj >= 0 and fj <= nc - 1):
                continue
            i0, j0 = int(np.floor(fi)), int(np.floor(fj))
            i1, j1 = min(i0 + 1, nr - 1), min(j0 + 1, nc - 1)
            wi, wj = fi - i0, fj - j0
            r = ((1.0 - wi) * ((1.0 - wj) * z[i0, j0] + wj * z[i0, j1])
                 + wi * ((1.0 - wj) * z[i1, j0] + wj * z[i1, j1]))
            if not np.isfinite(r):
                continue
            r -= h0
            hc = h[c]
            for p in range(k):
                bp = b[c, p]
                bh[s, p] += bp * hc
                br[s, p] += bp * r
                for q in range(p, k):  # the upper triangle; mirrored below
                    gram[s, p, q] += bp * b[c, q]
            sums[s, 0] += hc * hc
            sums[s, 1] += r * r
            sums[s, 2] += r * hc
            sums[s, 3] += 1.0
        for p in range(k):
            for q in range(p):
                gram[s, p, q] = gram[s, q, p]


def _lstsq_each(gram: FloatArray, rhs: FloatArray) -> FloatArray:
    return np.stack([np.linalg.lstsq(g, y, rcond=None)[0] for g, y in zip(gram, rhs,
                                                                            strict=True)])


def inflation_at(cells: WindowCells, detrend: int, x_m: float, y_m: float) -> float:
    """How many times the variance of the difference surface's value at (``x_m``, ``y_m``)
    exceeds that of a mean over the same cells (``n b' (B'B)^-1 b``, ``b`` the regressors
    there; 1 with a constant, or a plane at the cells' centroid, about 4 with a quadratic at
    a disk's centre)."""
    ok = np.isfinite(cells.h_m)
    b = surface_basis(cells, ok, detrend)
    if b.shape[0] <= b.shape[1]:
        return 1.0
    at = basis_at(x_m, y_m, detrend)[0]
    return float(b.shape[0] * at @ np.linalg.pinv(b.T @ b) @ at)


def differences(cells: WindowCells, reference: GeoDEM, sx_arcsec: float, sy_arcsec: float
                ) -> tuple[NDArray[np.bool_], FloatArray]:
    """The reference's heights less the window's, the window moved by (``sx_arcsec``,
    ``sy_arcsec``): the lattice cells where both have a height, and the differences there."""
    valid = np.isfinite(cells.h_m)
    diff = reference.height_m(cells.lon_deg[valid] + sx_arcsec * ARCSEC,
                              cells.lat_deg[valid] + sy_arcsec * ARCSEC) - cells.h_m[valid]
    both = valid.copy()
    both[valid] = np.isfinite(diff)
    return both, diff[np.isfinite(diff)]


def curvature_m(cells: WindowCells, reference: GeoDEM, sx_arcsec: float, sy_arcsec: float,
                height_noise_m: float, n_eff: int) -> tuple[float, float]:
    """(RMS of the quadratic part, beyond their plane, of the height :func:`differences` at
    (``sx_arcsec``, ``sy_arcsec``); the RMS their noise alone would give it: their robust spread
    over the ``n_eff`` independent patches)."""
    both, diff = differences(cells, reference, sx_arcsec, sy_arcsec)
    b = surface_basis(cells, both, 2)
    coef, spread = robust_fit(diff, b, mode_scale_m=height_noise_m)
    q = b[:, 3:] @ coef[3:]
    q = q - b[:, :3] @ np.linalg.lstsq(b[:, :3], q, rcond=None)[0]
    return float(np.sqrt(np.mean(q**2))), float(spread * np.sqrt(3.0 / max(n_eff, 1)))


def relief_m(cells: WindowCells, detrend: int) -> float:
    """Standard deviation of the window's heights about their best-fit :func:`surface_basis`
    (a constant, a plane or a quadratic with ``detrend`` 0, 1, 2)."""
    ok = np.isfinite(cells.h_m)
    if ok.sum() < 4:
        return 0.0
    b = surface_basis(cells, ok, detrend)
    coef, *_ = np.linalg.lstsq(b, cells.h_m[ok], rcond=None)
    return float(np.std(cells.h_m[ok] - b @ coef))
