"""Tie points inside the absolute orientation: the images' relative geometry as equations on
the models' parameters alone.

A tie point is one ground point seen in several images, whose ground position is unknown: with
``m`` images it gives ``2 m`` measurements for 3 unknowns, so ``2 m - 3`` equations on the
models' parameters (one for a stereo pair: its parallax across the epipolar lines). Those
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
    """Tie points measured in every image: ``col``/``row`` (n, n_img), 0-based pixel centres;
    a starting ground position each (``lon_deg``, ``lat_deg``, ellipsoidal ``h_m``, e.g. the
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
        ok = (np.isfinite(col).all(axis=1) & np.isfinite(row).all(axis=1)
              & np.isfinite(self.lon_deg) & np.isfinite(self.lat_deg) & np.isfinite(self.h_m))
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
    def n_equations(self) -> int:
        """Equations on the parameters: ``2 n_img - 3`` per tie point."""
        return self.n * (2 * self.n_images - 3)

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


def _project_all(models: Sequence[SensorModel], ground: FloatArray) -> FloatArray:
    """(n, 2 m): the ground points' (col, row) in every model, image by image."""
    out = []
    for model in models:
        c, r = model.project(ground[0], ground[1], ground[2])
        out += [np.asarray(c, np.float64), np.asarray(r, np.float64)]
    return np.stack(out, axis=1)


def _ground_design(models: Sequence[SensorModel], ground: FloatArray) -> FloatArray:
    """(n, 2 m, 3): d(col, row)/d(east, north, up) in every model, px per metre."""
    return np.concatenate([ground_jacobian(m, ground[0], ground[1], ground[2])
                           for m in models], axis=1)


def _measured(ties: TieObservations) -> FloatArray:
    return np.stack([ties.col, ties.row], axis=2).reshape(ties.n, -1)


def refine_ground(models: Sequence[SensorModel], ties: TieObservations, ground: ArrayLike,
                  design: FloatArray | None = None, iterations: int = 4
                  ) -> tuple[FloatArray, FloatArray]:
    """The tie points' ground positions (3, n) that best fit their measurements under
    ``models`` (Gauss-Newton from ``ground``, equal weights: one sigma for every image), and
    the ground design (n, 2 m, 3) used: ``design`` when given (a previous iteration's: the
    rays' directions hardly move between iterations), else computed at ``ground``."""
    g = np.array(ground, dtype=np.float64)
    b = _ground_design(models, g) if design is None else design
    meas = _measured(ties)
    btb_inv = np.linalg.inv(np.einsum("nki,nkj->nij", b, b))
    for _ in range(iterations):
        r = meas - _project_all(models, g)
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
    b = b_px / ties.sigma_px
    r = (_measured(ties) - _project_all(models, g)) / ties.sigma_px
    u_full, s, _ = np.linalg.svd(b, full_matrices=True)
    if np.any(s[:, -1] <= 1e-9 * s[:, 0]):
        raise GeometryError("a tie point's rays are parallel: the images do not form a stereo "
                            "pair there")
    u = u_full[:, :, 3:]  # (n, 2m, 2m - 3): the left null space of the ground design
    n, k = ties.n, u.shape[2]
    rr = np.einsum("nck,nc->nk", u, r).reshape(-1)
    point = np.repeat(np.arange(n), k)
    if not jacobian:
        return TieRows(np.zeros((rr.size, int(offsets[-1]))), rr, point, g, b_px)
    a = np.zeros((n, 2 * len(models), int(offsets[-1])))
    for m, model in enumerate(models):
        jac = np.asarray(model.jacobian(g[0], g[1], g[2]), np.float64)  # (n, 2, p_m)
        a[:, 2 * m:2 * m + 2, offsets[m]:offsets[m + 1]] = jac / ties.sigma_px
    ar = np.einsum("nck,ncp->nkp", u, a).reshape(-1, int(offsets[-1]))
    return TieRows(ar, rr, point, g, b_px)


def tie_residuals(models: Sequence[SensorModel], ties: TieObservations
                  ) -> tuple[FloatArray, FloatArray]:
    """The tie points' residuals (measured - projected, px; (n, m, 2)) at their ground
    positions refined under ``models``, and the ground design there ((n, m, 2, 3), px per
    metre east, north, up): what :func:`core.orientation.uncertainty.parallax_covariance`
    takes."""
    g, b = refine_ground(models, ties, ties.ground())
    v = _measured(ties) - _project_all(models, g)
    m = len(models)
    return b.reshape(ties.n, m, 2, 3), v.reshape(ties.n, m, 2)
