"""Tie points inside the absolute orientation: the images' relative geometry as equations on
the models' parameters alone.

A tie point is one ground point seen in several images, whose ground position is unknown: with
``m`` images it gives ``2 m`` measurements for 3 unknowns, so ``2 m - 3`` equations on the
models' parameters (one for a stereo pair: its parallax across the epipolar lines). In a block
a point is seen in some of the images only (NaN in the others): its equations are those of the
images that see it, the points grouped by the images they are seen in. Those
equations are found per point without building the ground unknowns into the adjustment: the
point is first intersected with the current models (Gauss-Newton on its ground position,
measurements weighted by their sigma), then its whitened measurement equations are projected
onto the left null space of their ground design (``u' B = 0``), which removes the ground
unknowns exactly: ``u' A dp = u' r`` with unit variance. The normal equations of those rows
are the Schur complement of the ground unknowns in the full bundle's (the reduced normal
equations of a bundle adjustment), so a lens or bow term that shows in the tie points'
parallax is estimated from them, whatever the reference DEM's errors (the GCPs carry those;
the tie points never see the reference).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.errors import GeometryError, InputError
from core.geodesy import metres_per_degree
from core.orientation.uncertainty import ground_jacobian
from core.sensors.base import SensorModel

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class TieObservations:
    """Tie points measured in two or more of the images: ``col``/``row`` (n, n_img), 0-based
    pixel centres, NaN where an image does not see the point; a starting ground position each (``lon_deg``, ``lat_deg``, ellipsoidal ``h_m``, e.g. the
    relative orientation's intersection: it is refined in every iteration); ``sigma_px`` the
    matching precision (px, a-priori: the adjustment calibrates it as a variance component)."""

    col: FloatArray
    row: FloatArray
    lon_deg: FloatArray
    lat_deg: FloatArray
    h_m: FloatArray
    sigma_px: float = 0.2

    def __post_init__(self) -> None:
        col, row = np.asarray(self.col, np.float64), np.asarray(self.row, np.float64)
        if col.ndim != 2 or col.shape != row.shape or col.shape[1] < 2:
            raise InputError(f"tie points need (n, n_images >= 2) columns and rows, got "
                             f"{col.shape} and {row.shape}")
        n = col.shape[0]
        for name in ("lon_deg", "lat_deg", "h_m"):
            if np.shape(getattr(self, name)) != (n,):
                raise InputError(f"tie point {name} has shape {np.shape(getattr(self, name))}, "
                                 f"expected ({n},)")
        if not self.sigma_px > 0:
            raise InputError(f"tie point sigma_px must be > 0, got {self.sigma_px}")
        seen = np.isfinite(col) & np.isfinite(row)
        ok = ((seen.sum(axis=1) >= 2) & np.isfinite(self.lon_deg) & np.isfinite(self.lat_deg)
              & np.isfinite(self.h_m))
        for name, v in (("col", col), ("row", row), ("lon_deg", self.lon_deg),
                        ("lat_deg", self.lat_deg), ("h_m", self.h_m)):
            object.__setattr__(self, name, np.asarray(v, np.float64)[ok])

    @property
    def n(self) -> int:
        return int(self.col.shape[0])

    @property
    def n_images(self) -> int:
        return int(self.col.shape[1])

    @property
    def seen(self) -> NDArray[np.bool_]:
        """(n, n_img): the images that see each point."""
        return np.isfinite(self.col) & np.isfinite(self.row)

    @property
    def complete(self) -> bool:
        """Every point seen in every image (a stereo pair's tie points)."""
        return bool(self.seen.all())

    @property
    def n_equations(self) -> int:
        """Equations on the parameters: ``2 m - 3`` per tie point seen in ``m`` images."""
        return int(np.sum(2 * self.seen.sum(axis=1) - 3))

    def ground(self) -> FloatArray:
        return np.stack([self.lon_deg, self.lat_deg, self.h_m])


@dataclass(frozen=True, eq=False)
class TieRows:
    """The tie points' reduced equations at the current models: ``a`` (n_eq, n_params) and
    ``r`` (n_eq,) whitened (unit a-priori variance; in units of ``sigma_px``), ``point`` the tie
    point of each row, and the refined ground positions (3, n)."""

    a: FloatArray
    r: FloatArray
    point: NDArray[np.intp]
    ground: FloatArray
    design: FloatArray


def _project_all(models: Sequence[SensorModel], ground: FloatArray,
                 seen: NDArray[np.bool_] | None = None) -> FloatArray:
    """(n, 2 m): the ground points' (col, row) in every model that sees them (``seen`` (n, m),
    default all), image by image; 0 elsewhere."""
    n = ground.shape[1]
    out = np.zeros((n, 2 * len(models)))
    for k, model in enumerate(models):
        s = np.ones(n, dtype=bool) if seen is None else seen[:, k]
        if s.any():
            c, r = model.project(ground[0][s], ground[1][s], ground[2][s])
            out[s, 2 * k], out[s, 2 * k + 1] = c, r
    return out


def _ground_design(models: Sequence[SensorModel], ground: FloatArray,
                   seen: NDArray[np.bool_] | None = None) -> FloatArray:
    """(n, 2 m, 3): d(col, row)/d(east, north, up) in every model that sees the points, px
    per metre; 0 elsewhere."""
    n = ground.shape[1]
    out = np.zeros((n, 2 * len(models), 3))
    for k, model in enumerate(models):
        s = np.ones(n, dtype=bool) if seen is None else seen[:, k]
        if s.any():
            out[s, 2 * k:2 * k + 2] = ground_jacobian(model, ground[0][s], ground[1][s],
                                                      ground[2][s])
    return out


def _measured(ties: TieObservations) -> FloatArray:
    """(n, 2 m) the measurements, image by image (col, row), 0 where not seen."""
    return np.nan_to_num(np.stack([ties.col, ties.row], axis=2).reshape(ties.n, -1))


def _seen2(ties: TieObservations) -> NDArray[np.bool_]:
    """(n, 2 m): the measurements taken (col and row of each image that sees the point)."""
    return np.repeat(ties.seen, 2, axis=1)


def refine_ground(models: Sequence[SensorModel], ties: TieObservations, ground: ArrayLike,
                  design: FloatArray | None = None, iterations: int = 4
                  ) -> tuple[FloatArray, FloatArray]:
    """The tie points' ground positions (3, n) that best fit their measurements under
    ``models`` (Gauss-Newton from ``ground``, equal weights: one sigma for every image), and
    the ground design (n, 2 m, 3) used: ``design`` when given (a previous iteration's: the
    rays' directions hardly move between iterations), else computed at ``ground``."""
    g = np.array(ground, dtype=np.float64)
    seen = ties.seen
    b = _ground_design(models, g, seen) if design is None else design
    meas = _measured(ties)
    btb_inv = np.linalg.inv(np.einsum("nki,nkj->nij", b, b))
    for _ in range(iterations):
        r = np.where(_seen2(ties), meas - _project_all(models, g, seen), 0.0)
        d = np.einsum("nij,nkj,nk->ni", btb_inv, b, r)
        m_lon, m_lat = metres_per_degree(g[1])
        g = g + np.stack([d[:, 0] / m_lon, d[:, 1] / m_lat, d[:, 2]])
        if np.max(np.abs(d), initial=0.0) < 0.01:
            break
    return g, b


def tie_rows(models: Sequence[SensorModel], ties: TieObservations, ground: ArrayLike,
             offsets: NDArray[np.intp], jacobian: bool = True,
             design: FloatArray | None = None) -> TieRows:
    """The tie points' equations on the parameters of ``models`` (columns ``offsets[k]`` to
    ``offsets[k+1]`` are model k's), the ground unknowns removed (module docstring).
    ``jacobian=False`` gives the residuals alone (``a`` zeros), with the ground design
    ``design`` of a previous call when given (it defines the equations: a step is judged on the
    same ones)."""
    if ties.n_images != len(models):
        raise InputError(f"tie points measured in {ties.n_images} images for "
                         f"{len(models)} models")
    g, b_px = refine_ground(models, ties, ground, design)
    seen = ties.seen
    b = b_px / ties.sigma_px
    r = (_measured(ties) - _project_all(models, g, seen)) / ties.sigma_px
    n_par = int(offsets[-1])
    a_parts, r_parts, p_parts = [], [], []
    # the points grouped by the images that see them (one group for a pair's tie points)
    patterns, which = np.unique(seen, axis=0, return_inverse=True)
    jac_of: list[FloatArray] = []  # image m's Jacobian at every point it sees, one call each
    if jacobian:
        slot_of = np.cumsum(seen, axis=0) - 1  # a point's place among those its image sees
        for m, model in enumerate(models):
            gm = g[:, seen[:, m]]
            jac_of.append(np.asarray(model.jacobian(gm[0], gm[1], gm[2]), np.float64)
                          if gm.shape[1] else np.zeros((0, 2, offsets[m + 1] - offsets[m])))
    for q, pattern in enumerate(patterns):
        idx = np.flatnonzero(which.ravel() == q)
        images = np.flatnonzero(pattern)
        cols = np.ravel(np.stack([2 * images, 2 * images + 1], axis=1))
        u_full, s, _ = np.linalg.svd(b[np.ix_(idx, cols)], full_matrices=True)
        if np.any(s[:, -1] <= 1e-9 * s[:, 0]):
            raise GeometryError("a tie point's rays are parallel: the images do not form a "
                                "stereo pair there")
        u = u_full[:, :, 3:]  # (p, 2k, 2k - 3): the left null space of the ground design
        r_parts.append(np.einsum("nck,nc->nk", u, r[np.ix_(idx, cols)]).reshape(-1))
        p_parts.append(np.repeat(idx, u.shape[2]))
        if jacobian:  # on the parameters of the pattern's images only, then placed
            local = np.concatenate([np.arange(offsets[m], offsets[m + 1]) for m in images])
            a = np.zeros((idx.size, cols.size, local.size))
            at = 0
            for slot, m in enumerate(images):
                size = int(offsets[m + 1] - offsets[m])
                a[:, 2 * slot:2 * slot + 2, at:at + size] = jac_of[m][slot_of[idx, m]] / ties.sigma_px
                at += size
            rows = np.zeros((idx.size * u.shape[2], n_par))
            rows[:, local] = np.einsum("nck,ncp->nkp", u, a).reshape(-1, local.size)
            a_parts.append(rows)
    rr, point = np.concatenate(r_parts), np.concatenate(p_parts)
    order = np.argsort(point, kind="stable")  # point by point, as the points were given
    rr, point = rr[order], point[order]
    ar = np.vstack(a_parts)[order] if jacobian else np.zeros((rr.size, n_par))
    return TieRows(ar, rr, point, g, b_px)


def tie_residuals(models: Sequence[SensorModel], ties: TieObservations
                  ) -> tuple[FloatArray, FloatArray]:
    """The tie points' residuals (measured - projected, px; (n, m, 2)) at their ground
    positions refined under ``models``, and the ground design there ((n, m, 2, 3), px per
    metre east, north, up): what :func:`core.orientation.uncertainty.parallax_covariance`
    takes."""
    g, b = refine_ground(models, ties, ties.ground())
    v = np.where(_seen2(ties), _measured(ties) - _project_all(models, g, ties.seen), np.nan)
    m = len(models)
    return b.reshape(ties.n, m, 2, 3), v.reshape(ties.n, m, 2)
