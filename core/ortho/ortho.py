"""Orthorectification by inverse mapping (step 5): for each cell of an output tile, its height
from a DEM, its image position through the sensor model, and the image resampled there.

The model is not evaluated at every cell. As GDAL's approximate transformer does, it is
evaluated on a sparse lattice of the tile's cells and interpolated, with the error checked on
extra points and the lattice refined until it is below ``tol_px``:

- the DEM's fractional grid indices of each cell (and the geoid undulation, when the DEM holds
  EGM96 heights) are interpolated bilinearly from the lattice nodes (smooth in the cell
  position), and the cell's height read from the DEM there (:func:`core.dem.sample_bilinear`);
- at each node the model projects the ground point at a few heights spanning the tile's
  heights (Chebyshev-Lobatto levels); the image position is a polynomial in the height
  whose coefficients are interpolated bilinearly between the nodes. The height part is exact
  wherever the DEM has kinks (a projected DSM at 1 m, SRTM cell edges): only the smooth
  dependence on the cell position is interpolated;
- the check compares the interpolated chain with the exact one (cell -> lon/lat -> DEM height
  -> ``model.project``) at the midpoints of the lattice's cells and edges, at the DEM height
  and at every level, and at each node between the levels. Above ``tol_px`` the polynomial
  degree is raised (height part) or the lattice spacing halved (position part), down to
  exact evaluation at every cell.

Image coordinates: (col, row), 0-based, pixel centres at integers; the image footprint is
``[-0.5, n - 0.5]``. Output cells: :class:`core.matching.grid.GridSpec` (north-west corner,
square cells, values at cell centres). Heights WGS84 ellipsoidal in metres. No I/O here: the
tasks read the DEM and image windows and hand the coordinate transformations in as callables.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.ndimage import maximum_filter

from core.choices import RESAMPLINGS, Resampling
from core.dem import GeoDEM, SurfaceGrid
from core.errors import InputError
from core.geoid import GeoidGrid
from core.matching.grid import GridSpec
from core.sensors.base import SensorModel

FloatArray = NDArray[np.float64]
LonLatOf = Callable[[FloatArray, FloatArray], tuple[FloatArray, FloatArray]]

KERNEL_RADIUS = {"nearest": 1, "bilinear": 1, "cubic": 2}  # taps beyond the centre pixel
MAX_CHECK_POINTS = 4096  # per check kind and refinement round


@dataclass(frozen=True)
class OrthoConfig:
    """Settings of the ortho kernel.

    ``resampling``: ``nearest``, ``bilinear`` or ``cubic`` (cubic convolution, Keys a = -0.5,
    GDAL's "cubic"); ``tol_px``: the largest interpolation error of the image position found
    on the check points; ``step_px``: first spacing of the model lattice, output cells;
    ``degree``: first degree of the polynomial in height (raised up to ``max_degree``);
    ``occlusion``: also mark the cells the relief hides from the sensor, with heights
    ``occlusion_tol_m`` above the line of sight counting as hiding it.
    """

    resampling: Resampling = "bilinear"
    tol_px: float = 0.01
    step_px: int = 64
    degree: int = 2
    max_degree: int = 6
    occlusion: bool = False
    occlusion_tol_m: float = 0.5

    def __post_init__(self) -> None:
        if self.resampling not in RESAMPLINGS:
            raise InputError(f"resampling {self.resampling!r} unknown; use one of {RESAMPLINGS}")
        if not self.tol_px > 0:
            raise InputError(f"the interpolation tolerance must be > 0 px, got {self.tol_px}")
        if self.step_px < 1:
            raise InputError(f"the lattice step must be >= 1 cell, got {self.step_px}")
        if not 1 <= self.degree <= self.max_degree:
            raise InputError(f"need 1 <= degree <= max_degree, got {self.degree}, "
                             f"{self.max_degree}")
        if not self.occlusion_tol_m >= 0:
            raise InputError(f"occlusion_tol_m must be >= 0 m, got {self.occlusion_tol_m}")


@dataclass(frozen=True, eq=False)
class TileDEM:
    """The heights an ortho tile reads.

    ``grid``: a lon/lat :class:`GeoDEM` or a projected :class:`SurfaceGrid`; for the latter
    ``from_lonlat`` maps WGS84 degrees to its CRS. ``geoid``: given when the grid holds EGM96
    orthometric heights (``h = H + N``); None for ellipsoidal heights.
    """

    grid: GeoDEM | SurfaceGrid
    from_lonlat: LonLatOf | None = None
    geoid: GeoidGrid | None = None

    def __post_init__(self) -> None:
        if isinstance(self.grid, SurfaceGrid) and self.from_lonlat is None:
            raise InputError("a projected DEM needs from_lonlat (WGS84 -> its CRS)")

    @property
    def z(self) -> NDArray[np.floating]:
        return self.grid.values

    def indices(self, lon: FloatArray, lat: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Fractional (row, col) grid indices of ground points."""
        if self.grid.geographic:
            return self.grid.indices(lon, lat)
        return self.grid.indices(*self.from_lonlat(lon, lat))  # type: ignore[misc]

    def undulation(self, lon: FloatArray, lat: FloatArray) -> FloatArray:
        """N to add to the grid's heights (zeros for an ellipsoidal grid)."""
        if self.geoid is None:
            return np.zeros(np.shape(lon))
        return self.geoid.undulation_m(lon, lat)

    def height(self, fi: FloatArray, fj: FloatArray, n_m: FloatArray) -> FloatArray:
        """Ellipsoidal height at grid indices, N given; NaN off the grid or next to a void
        (the rule of :func:`core.dem.sample_bilinear`, compiled)."""
        from core.ortho.kernels import bilinear  # imports Numba: only when a tile is computed

        return bilinear(self.z, fi, fj) + n_m


@dataclass(frozen=True, eq=False)
class TileGeometry:
    """Where each cell of a tile is in the image.

    ``col``, ``row``: image position (NaN where the DEM has no height); ``h_m``: the cell's
    ellipsoidal height; ``occluded``: cells hidden by the relief (None when not asked);
    ``step_px`` and ``degree``: the lattice and height polynomial used; ``max_error_px``: the
    largest error of the interpolated image position found on the check points (0 when every
    cell was projected exactly); ``n_evaluations``: points projected exactly.
    """

    col: FloatArray
    row: FloatArray
    h_m: FloatArray
    occluded: NDArray[np.bool_] | None
    step_px: int
    degree: int
    max_error_px: float
    n_evaluations: int


# ---------------------------------------------------------------------------- the lattice


def _keys_weights(t: FloatArray) -> tuple[FloatArray, ...]:
    """Cubic convolution weights (Keys, a = -0.5) of the taps at -1, 0, 1, 2 for t in [0, 1).
    Interpolating, and exact for quadratics."""
    t2, t3 = t * t, t * t * t
    return (0.5 * (-t3 + 2 * t2 - t), 0.5 * (3 * t3 - 5 * t2 + 2),
            0.5 * (-3 * t3 + 4 * t2 + t), 0.5 * (t3 - t2))


@dataclass(frozen=True, eq=False)
class _Axis:
    """Lattice nodes along one axis of ``n`` cells: every ``step`` cells from one step before
    the first cell to two steps past the last, so cubic convolution (4 taps) reaches every
    cell; cell ``k`` takes ``sum_a weights[k, a] * node_value[taps[k, a]]`` (both (n, 4))."""

    n: int
    step: int
    nodes: FloatArray
    taps: NDArray[np.intp]
    weights: FloatArray

    @classmethod
    def make(cls, n: int, step: int) -> _Axis:
        step = max(1, min(step, n))
        m = -(-(n - 1) // step)  # last regular node at or past the last cell
        nodes = step * np.arange(-1, m + 3, dtype=np.float64)
        taps, w = cls._taps(step, np.arange(n, dtype=np.float64))
        return cls(n, step, nodes, np.ascontiguousarray(np.stack(taps, axis=1)),
                   np.ascontiguousarray(np.stack(w, axis=1)))

    @staticmethod
    def _taps(step: int, t: FloatArray) -> tuple[list[NDArray[np.intp]], tuple[FloatArray, ...]]:
        """Node indices and weights of the 4 taps at (fractional) cells ``t``."""
        u = t / step
        q = np.floor(u)
        w = _keys_weights(u - q)
        q = q.astype(np.intp)
        return [q + k for k in range(4)], w  # node index of position (q - 1 + k) * step

    def midpoints(self) -> FloatArray:
        """Positions halfway between nodes, inside the cells ``0 .. n - 1``."""
        mid = self.nodes[:-1] + 0.5 * self.step
        return mid[(mid > 0) & (mid < self.n - 1)]

    def inner(self) -> FloatArray:
        """The node positions inside the cells."""
        return self.nodes[(self.nodes >= 0) & (self.nodes <= self.n - 1)]


def _upsample(node_values: FloatArray, rows: _Axis, cols: _Axis) -> FloatArray:
    """Node values (..., ny, nx) interpolated at every cell (..., n_rows, n_cols)."""
    from core.ortho.kernels import upsample

    v = np.asarray(node_values, dtype=np.float64)
    out = upsample(v.reshape(-1, *v.shape[-2:]), rows.taps, rows.weights, cols.taps,
                   cols.weights)
    return out.reshape(*v.shape[:-2], rows.n, cols.n)


def _cell_heights(dem: TileDEM, dem_nodes: tuple[FloatArray, FloatArray, FloatArray],
                  rows: _Axis, cols: _Axis) -> FloatArray:
    """Height of every cell: the DEM indices and undulation interpolated from the nodes, then
    :meth:`TileDEM.height` there (one compiled pass, :func:`core.ortho.kernels.cell_heights`)."""
    from core.ortho.kernels import cell_heights

    return cell_heights(np.stack(dem_nodes), rows.taps, rows.weights, cols.taps, cols.weights,
                        dem.z)


def _at_points(node_values: FloatArray, rows: _Axis, cols: _Axis, i: FloatArray,
               j: FloatArray) -> FloatArray:
    """Node values (..., ny, nx) interpolated at fractional cells (i, j), 1-D."""
    ti, wi = _Axis._taps(rows.step, i)
    tj, wj = _Axis._taps(cols.step, j)
    out = 0.0
    for a in range(4):
        for b in range(4):
            out = out + wi[a] * wj[b] * node_values[..., ti[a], tj[b]]
    return out


def _cell_xy(cells: GridSpec, i: FloatArray, j: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Projected coordinates of (fractional) cell centres."""
    return cells.x0_m + (j + 0.5) * cells.res_m, cells.y0_m - (i + 0.5) * cells.res_m


# ---------------------------------------------------------------------------- height polynomial


def _levels(degree: int) -> FloatArray:
    """Chebyshev-Lobatto points in [-1, 1]: ``degree + 1`` levels, both ends included."""
    return np.cos(np.pi * np.arange(degree + 1) / degree)


def _between_levels(degree: int) -> FloatArray:
    """Points between the levels (Chebyshev points of the first kind) for the height check."""
    return np.cos(np.pi * (np.arange(degree) + 0.5) / degree)


def _horner(coeffs: FloatArray, u: FloatArray) -> FloatArray:
    """sum_k c_k u^k; ``coeffs`` (d + 1, ...)."""
    acc = coeffs[-1]
    for k in range(len(coeffs) - 2, -1, -1):
        acc = acc * u + coeffs[k]
    return acc


@dataclass(frozen=True, eq=False)
class _Fit:
    """The model on the lattice: image (col, row) as polynomials in the normalised height
    ``u = (h - h_mid) / h_half``, coefficients (2, d + 1, ny, nx) at the nodes."""

    coeffs: FloatArray
    h_mid: float
    h_half: float

    def u(self, h: FloatArray) -> FloatArray:
        return (h - self.h_mid) / self.h_half

    @property
    def degree(self) -> int:
        return self.coeffs.shape[1] - 1


def _fit_levels(model: SensorModel, lon: FloatArray, lat: FloatArray, h_lo: float,
                h_hi: float, degree: int) -> _Fit:
    h_mid, h_half = 0.5 * (h_lo + h_hi), 0.5 * (h_hi - h_lo)
    u = _levels(degree)
    hs = h_mid + h_half * u
    shape = lon.shape
    c, r = model.project(np.broadcast_to(lon, (u.size, *shape)).ravel(),
                         np.broadcast_to(lat, (u.size, *shape)).ravel(),
                         np.repeat(hs, lon.size))
    values = np.stack([c.reshape(u.size, -1), r.reshape(u.size, -1)])  # (2, L, n)
    vander = np.vander(u, degree + 1, increasing=True)  # values = vander @ coeffs
    coeffs = np.linalg.solve(vander, values)  # broadcasts over (2, ...)
    return _Fit(coeffs.reshape(2, degree + 1, *shape), h_mid, h_half)


# ---------------------------------------------------------------------------- the kernel


def tile_geometry(model: SensorModel, cells: GridSpec, dem: TileDEM, to_lonlat: LonLatOf,
                  config: OrthoConfig = OrthoConfig()) -> TileGeometry:
    """Image position of every cell of ``cells`` (see the module docstring).

    ``to_lonlat`` maps the cells' projected coordinates (metres) to WGS84 degrees. Cells
    whose height is unknown (off the DEM, voids) get NaN. The interpolation error found on
    the check points is at most ``config.tol_px``, unless the height polynomial reached
    ``max_degree`` first (its error is then reported in ``max_error_px``). The lattice is
    refined along each axis separately (attitude jitter, for one, varies along the image
    rows only).
    """
    n_rows, n_cols = cells.shape
    steps, degree, n_eval = [config.step_px, config.step_px], config.degree, 0
    while True:
        rows, cols = _Axis.make(n_rows, steps[0]), _Axis.make(n_cols, steps[1])
        gi, gj = np.meshgrid(rows.nodes, cols.nodes, indexing="ij")
        lon_n, lat_n = (np.asarray(v, float) for v in to_lonlat(*_cell_xy(cells, gi, gj)))
        dem_nodes = (*dem.indices(lon_n, lat_n), dem.undulation(lon_n, lat_n))
        h = _cell_heights(dem, dem_nodes, rows, cols)
        finite = np.isfinite(h)
        if not finite.any():
            nan = np.full(cells.shape, np.nan)
            occluded = np.zeros(cells.shape, bool) if config.occlusion else None
            return TileGeometry(nan, nan.copy(), h, occluded, min(steps), degree, 0.0, n_eval)
        lo, hi = float(h[finite].min()), float(h[finite].max())
        pad = max(1.0, 0.01 * (hi - lo))
        while True:
            fit = _fit_levels(model, lon_n, lat_n, lo - pad, hi + pad, degree)
            err_h, k = _height_check(model, fit, lon_n, lat_n)
            n_eval += lon_n.size * (degree + 1) + k
            if err_h <= config.tol_px or degree >= config.max_degree:
                break
            degree += 1
        errs, k = _position_check(model, cells, dem, to_lonlat, fit, rows, cols, dem_nodes)
        n_eval += k
        refine = [errs[0] > config.tol_px and steps[0] > 1,
                  errs[1] > config.tol_px and steps[1] > 1]
        if errs[2] > config.tol_px and not any(refine):
            refine = [steps[0] > 1, steps[1] > 1]
        if not any(refine):
            break
        steps = [max(1, s // 2) if r else s for s, r in zip(steps, refine, strict=True)]
    from core.ortho.kernels import image_position

    col, row = image_position(fit.coeffs, rows.taps, rows.weights, cols.taps, cols.weights, h,
                              fit.h_mid, fit.h_half)
    occluded = None
    if config.occlusion:
        occluded = _occlusion(model, dem, fit, rows, cols, lon_n, lat_n, dem_nodes, h,
                              config.occlusion_tol_m)
    return TileGeometry(col, row, h, occluded, min(rows.step, cols.step), degree,
                        max(err_h, *errs), n_eval)


def _subsample(n: int, limit: int = MAX_CHECK_POINTS) -> NDArray[np.intp]:
    return np.arange(0, n, max(1, math.ceil(n / limit)), dtype=np.intp)


def _height_check(model: SensorModel, fit: _Fit, lon_n: FloatArray, lat_n: FloatArray
                  ) -> tuple[float, int]:
    """Largest error of the height polynomials between the levels, at (a subset of) nodes."""
    u = _between_levels(fit.degree)
    pick = _subsample(lon_n.size)
    lon, lat = lon_n.ravel()[pick], lat_n.ravel()[pick]
    coeffs = fit.coeffs.reshape(2, fit.degree + 1, -1)[:, :, pick]
    c, r = model.project(np.tile(lon, u.size), np.tile(lat, u.size),
                         np.repeat(fit.h_mid + fit.h_half * u, lon.size))
    uu = np.repeat(u, lon.size).reshape(u.size, -1)
    ci = _horner(coeffs[0][:, None, :], uu)
    ri = _horner(coeffs[1][:, None, :], uu)
    err = np.hypot(c.reshape(u.size, -1) - ci, r.reshape(u.size, -1) - ri)
    return float(np.nanmax(err, initial=0.0)), c.size


def _position_check(model: SensorModel, cells: GridSpec, dem: TileDEM, to_lonlat: LonLatOf,
                    fit: _Fit, rows: _Axis, cols: _Axis,
                    dem_nodes: tuple[FloatArray, FloatArray, FloatArray]
                    ) -> tuple[tuple[float, float, float], int]:
    """Largest errors of the interpolated image position halfway between nodes along the
    rows, along the columns and in both (lattice cell centres): at the DEM height (the whole
    chain, DEM indices included) and at every level height (the position part alone)."""
    sets = [np.meshgrid(rows.midpoints(), cols.inner(), indexing="ij"),
            np.meshgrid(rows.inner(), cols.midpoints(), indexing="ij"),
            np.meshgrid(rows.midpoints(), cols.midpoints(), indexing="ij")]
    errs, n = [], 0
    levels = fit.h_mid + fit.h_half * _levels(fit.degree)
    for gi, gj in sets:
        i, j = gi.ravel(), gj.ravel()
        if i.size == 0:
            errs.append(0.0)
            continue
        pick = _subsample(i.size)
        i, j = i[pick], j[pick]
        lon, lat = (np.asarray(v, float) for v in to_lonlat(*_cell_xy(cells, i, j)))
        fi, fj = dem.indices(lon, lat)
        h_exact = dem.height(fi, fj, dem.undulation(lon, lat))
        h_interp = dem.height(*(_at_points(v, rows, cols, i, j) for v in dem_nodes))
        h_all = np.concatenate([h_exact, np.repeat(levels, i.size)])
        h_model = np.concatenate([h_interp, np.repeat(levels, i.size)])
        ok = np.isfinite(h_all) & np.isfinite(h_model)
        reps = levels.size + 1
        c, r = model.project(np.tile(lon, reps)[ok], np.tile(lat, reps)[ok], h_all[ok])
        n += int(ok.sum())
        cf = np.tile(_at_points(fit.coeffs, rows, cols, i, j), (1, 1, reps))[:, :, ok]
        u = fit.u(h_model[ok])
        err = np.hypot(c - _horner(cf[0], u), r - _horner(cf[1], u))
        errs.append(float(np.max(err, initial=0.0)))
    return (errs[0], errs[1], errs[2]), n


# ---------------------------------------------------------------------------- occlusion


OCCLUSION_BLOCK = 8  # DEM cells per side of the blocks whose highest point lets rays skip


def _occlusion(model: SensorModel, dem: TileDEM, fit: _Fit, rows: _Axis, cols: _Axis,
               lon_n: FloatArray, lat_n: FloatArray,
               dem_nodes: tuple[FloatArray, FloatArray, FloatArray], h: FloatArray,
               tol_m: float) -> NDArray[np.bool_]:
    """Cells whose line of sight to the sensor passes under the DEM.

    The line of sight of each cell goes up from its ground point; its move in DEM grid
    indices per metre of height comes from the model at the nodes (ground point at the tile's
    middle height and ``dh`` above it on the same image point), interpolated to the cells.
    Each line is followed up in steps that move it at most half a DEM cell, or a whole block
    of ``OCCLUSION_BLOCK`` cells when it is above everything in the blocks around it, until
    it is above the highest DEM height or leaves the DEM; a DEM height more than ``tol_m``
    above it hides the cell.
    """
    dh = max(2.0 * fit.h_half, 100.0)
    c, r = model.project(lon_n, lat_n, np.full(lon_n.shape, fit.h_mid))
    lon2, lat2 = model.localize(c, r, np.full(lon_n.shape, fit.h_mid + dh))
    gi0, gj0 = dem.indices(lon_n, lat_n)
    gi1, gj1 = dem.indices(np.asarray(lon2, float), np.asarray(lat2, float))
    rays = list(_upsample(np.stack([*dem_nodes, (gi1 - gi0) / dh, (gj1 - gj0) / dh]), rows,
                          cols))
    from core.ortho.kernels import bilinear

    occluded = np.zeros(h.shape, bool)
    z = np.asarray(dem.z, dtype=np.float64)
    top = _block_tops(z, OCCLUSION_BLOCK)
    move = np.maximum(np.abs(rays[3]), np.abs(rays[4]))  # DEM cells per metre of height
    idx = np.flatnonzero(np.isfinite(h) & (move > 0))
    fi, fj, n_m, di, dj, move, hh = (a.ravel()[idx] for a in (*rays, move, h))
    z_top = float(np.max(top)) + float(np.max(n_m, initial=0.0))
    t = 0.5 / move
    while idx.size:
        pi, pj = fi + di * t, fj + dj * t
        ray = hh + t
        bi, bj = np.floor(pi / OCCLUSION_BLOCK), np.floor(pj / OCCLUSION_BLOCK)
        on = (bi >= 0) & (bi < top.shape[0]) & (bj >= 0) & (bj < top.shape[1])
        clear = np.zeros(idx.size, bool)
        clear[on] = ray[on] > top[bi[on].astype(np.intp), bj[on].astype(np.intp)] + n_m[on]
        hidden = np.zeros(idx.size, bool)
        look = on & ~clear
        zz = bilinear(z, pi[look], pj[look]) + n_m[look]
        hidden[look] = zz > ray[look] + tol_m
        occluded.ravel()[idx[hidden]] = True
        keep = on & ~hidden & (ray < z_top)
        keep[look] &= np.isfinite(zz)
        t = t + np.where(clear, OCCLUSION_BLOCK, 0.5) / move
        idx, fi, fj, n_m, di, dj, move, hh, t = (
            a[keep] for a in (idx, fi, fj, n_m, di, dj, move, hh, t))
    return occluded


def _block_tops(z: FloatArray, block: int) -> FloatArray:
    """Highest height of each ``block x block`` group of cells and its 8 neighbours (-inf
    where there is none)."""
    nr, nc = -(-z.shape[0] // block), -(-z.shape[1] // block)
    padded = np.full((nr * block, nc * block), -np.inf)
    padded[:z.shape[0], :z.shape[1]] = np.where(np.isnan(z), -np.inf, z)
    tops = padded.reshape(nr, block, nc, block).max(axis=(1, 3))
    return maximum_filter(tops, size=3, mode="nearest")


# ---------------------------------------------------------------------------- resampling


@dataclass(frozen=True)
class SourceWindow:
    """The image pixels a tile needs: columns ``col0 .. col0 + n_cols * factor`` and rows
    ``row0 .. row0 + n_rows * factor``, read as ``n_rows x n_cols`` samples each averaging
    ``factor x factor`` pixels (``factor`` > 1 when the output cells are at least twice the
    pixels: the image is read decimated, which also keeps the window's memory bounded)."""

    col0: int
    row0: int
    n_cols: int
    n_rows: int
    factor: int = 1

    @property
    def bounds(self) -> tuple[int, int, int, int]:
        """(col0, row0, col1, row1) of the full-resolution pixels."""
        return (self.col0, self.row0, self.col0 + self.n_cols * self.factor,
                self.row0 + self.n_rows * self.factor)


def source_window(col: FloatArray, row: FloatArray, image_size: tuple[int, int],
                  resampling: str) -> SourceWindow | None:
    """The window of the image (``image_size`` = (cols, rows)) the positions need, with the
    resampling kernel's margin; None when no position falls in the image."""
    from core.ortho.kernels import footprint_bounds

    n_inside, c_min, c_max, r_min, r_max = footprint_bounds(col, row, image_size)
    if n_inside == 0:
        return None
    factor = _decimation(col, row)
    margin = (KERNEL_RADIUS[resampling] + 1) * factor
    w, hgt = image_size
    c0 = max(0, math.floor(c_min) - margin)
    r0 = max(0, math.floor(r_min) - margin)
    c1 = min(w, math.ceil(c_max) + margin + 1)
    r1 = min(hgt, math.ceil(r_max) + margin + 1)
    n_c, n_r = max(1, (c1 - c0) // factor), max(1, (r1 - r0) // factor)
    return SourceWindow(c0, r0, n_c, n_r, factor)


def _decimation(col: FloatArray, row: FloatArray) -> int:
    """Image pixels per output cell, rounded down, when at least 2 (else 1)."""
    if col.shape[0] < 2 or col.shape[1] < 2:
        return 1
    k = max(1, min(col.shape) // 64)  # a sparse sample of cells is enough
    col, row = col[::k, ::k], row[::k, ::k]
    along_j = np.hypot(np.diff(col, axis=1), np.diff(row, axis=1)) / k
    along_i = np.hypot(np.diff(col, axis=0), np.diff(row, axis=0)) / k
    px = min(np.nanmedian(along_j) if np.isfinite(along_j).any() else 1.0,
             np.nanmedian(along_i) if np.isfinite(along_i).any() else 1.0)
    return int(px) if px >= 2.0 else 1


def resample(window: NDArray, win: SourceWindow, col: FloatArray, row: FloatArray,
             image_size: tuple[int, int], resampling: str,
             nodata: float | None = None) -> FloatArray:
    """Image values at (col, row) from ``window`` (the pixels of ``win``); NaN outside the
    image footprint, where the position is NaN, or where the kernel touches ``nodata``.

    ``nearest`` takes the pixel holding the point, ``bilinear`` the bilinear sampler of
    :func:`core.dem.sample_bilinear` (NaN next to a nodata pixel), ``cubic`` cubic
    convolution (Keys, a = -0.5). The window's edges repeat beyond it so the whole pixel
    footprint has values. One compiled pass over the cells
    (:func:`core.ortho.kernels.resample_window`).
    """
    from core.ortho.kernels import BILINEAR, CUBIC, NEAREST, resample_window

    kind = {"nearest": NEAREST, "bilinear": BILINEAR, "cubic": CUBIC}[resampling]
    return resample_window(np.asarray(window), col, row, (win.col0, win.row0), win.factor,
                           image_size, nodata, kind, KERNEL_RADIUS[resampling] + 1)


def to_dtype(values: FloatArray, dtype: np.dtype | str, nodata: float | None) -> NDArray:
    """Resampled values as the image's type: integers rounded and clipped to the type's
    range, a valid value equal to ``nodata`` moved one step off it (so it stays valid), NaN
    written as ``nodata``; floats as float32 (NaN kept, or ``nodata`` when it is a number)."""
    dtype = np.dtype(dtype)
    if dtype.kind in "iu":
        info = np.iinfo(dtype)
        if nodata is None or math.isnan(nodata) or info.min <= nodata <= info.max:
            from core.ortho.kernels import to_integer

            return to_integer(values, dtype, nodata)  # one compiled pass
        v = np.clip(np.rint(values), info.min, info.max)  # a nodata the type cannot hold
        return np.where(np.isnan(values), nodata, v).astype(dtype)
    out = values.astype(np.float32)
    if nodata is not None and not math.isnan(nodata):
        out[np.isnan(out)] = nodata
    return out
