"""The equations of the absolute orientation at any models: the GCPs' (their ground moved by
their frame's shift, :mod:`core.orientation.frames`), the tie points' (their ground unknowns
removed, :mod:`core.orientation.ties`), the priors on the additional parameters and on the
frames, with the group of each row for the variance components.

The unknowns are every model's parameters (model ``k``'s in columns ``offsets[k]`` to
``offsets[k+1]``) followed by the frames' (columns ``offsets[-1]`` on)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from core.orientation.frames import FrameLayout
from core.orientation.ties import TieObservations, tie_rows
from core.orientation.uncertainty import ground_jacobian, image_grid
from core.sensors.base import SensorModel

# the GCPs: a core.orientation.absolute.Observations (not imported: that module imports this)
Observations = Any

FloatArray = NDArray[np.float64]


GROUPS = ("gcp_col", "gcp_row", "tie", "prior", "frame")


@dataclass(frozen=True, eq=False)
class System:
    """Every equation of the adjustment at the current models: design ``a`` (n, n_params; empty
    when only residuals were asked), residuals ``r`` (measured - computed), a-priori variances
    ``q`` and group (index into :data:`GROUPS`) of each row; the tie points' ground; the frame
    of each GCP row (``source``, -1 on the other rows: the variance components of a GCP source
    apart from another's)."""

    a: FloatArray
    r: FloatArray
    q: FloatArray
    group: NDArray[np.intp]
    ground: FloatArray | None
    source: NDArray[np.intp] | None = None  # a GCP row's frame index (-1: not a GCP's)


class Equations:
    """The GCPs' (robust, with rejection), tie points' and priors' equations of one
    adjustment, built at any models."""

    def __init__(self, obs: Observations, col: FloatArray, row: FloatArray, sigma: FloatArray,
                 seen: NDArray[np.bool_], offsets: NDArray[np.intp],
                 ties: TieObservations | None, prior: FloatArray,
                 frames: FrameLayout) -> None:
        self.obs, self.col, self.row, self.sigma, self.seen = obs, col, row, sigma, seen
        self.offsets, self.ties, self.prior, self.frames = offsets, ties, prior, frames
        self.ground = ties.ground() if ties is not None else None
        self.design: FloatArray | None = None

    @property
    def n_params(self) -> int:
        return int(self.offsets[-1]) + self.frames.n

    def build(self, models: Sequence[SensorModel], frame_x: FloatArray,
              inlier: NDArray[np.bool_], jacobian: bool = True) -> System:
        """Every equation at ``models`` and the frame parameters ``frame_x``."""
        n_par, n_mod = self.n_params, int(self.offsets[-1])
        use = inlier[:, None] & self.seen
        obs = self.obs.shifted(self.frames, frame_x)
        a, r, q, axis = linearise(models, obs, self.col, self.row, self.sigma, use,
                                   self.offsets, jacobian)
        a = np.hstack([a, np.zeros((a.shape[0], self.frames.n))])
        if jacobian and self.frames.n:
            a[:, n_mod:] = frame_design(models, obs, use, self.frames)
        a_parts, r_parts, q_parts, g_parts = [a], [r], [q], [axis]
        frame = np.asarray(self.obs.frame)
        source = np.concatenate([np.repeat(frame[use[:, m]], 2) for m in range(len(models))]
                                + [np.zeros(0, np.intp)])
        ground = None
        if self.ties is not None and self.ties.n:
            # the rays' ground design of the first build serves every later one: the
            # corrections move the rays by microradians, the design hardly at all
            t = tie_rows(models, self.ties, self.ground, self.offsets, jacobian, self.design)
            ground, self.design = t.ground, t.design
            a_parts.append(np.hstack([t.a, np.zeros((t.a.shape[0], self.frames.n))]))
            r_parts.append(t.r)
            q_parts.append(np.ones(t.r.size))
            g_parts.append(np.full(t.r.size, 2))
        if self.prior.size:  # whitened: the delivered values (corrections 0) are the target
            p = np.concatenate([m.params for m in models])
            a_parts.append(np.hstack([self.prior, np.zeros((self.prior.shape[0],
                                                            self.frames.n))]))
            r_parts.append(-self.prior @ p)
            q_parts.append(np.ones(self.prior.shape[0]))
            g_parts.append(np.full(self.prior.shape[0], 3))
        if self.frames.n:  # whitened: no shift is the target
            rows = np.zeros((self.frames.n, n_par))
            rows[:, n_mod:] = self.frames.prior_rows()
            a_parts.append(rows)
            r_parts.append(-self.frames.prior_rows() @ frame_x)
            q_parts.append(np.ones(self.frames.n))
            g_parts.append(np.full(self.frames.n, 4))
        groups = np.concatenate(g_parts).astype(np.intp)
        rows = np.full(groups.size, -1, dtype=np.intp)
        rows[:source.size] = source
        return System(np.vstack(a_parts), np.concatenate(r_parts), np.concatenate(q_parts),
                      groups, ground, rows)

    def accept(self, system: System) -> None:
        """Start the next tie-point intersections from this system's ground."""
        if system.ground is not None:
            self.ground = system.ground


def frame_design(models: Sequence[SensorModel], obs: Observations, use: NDArray[np.bool_],
                 frames: FrameLayout) -> FloatArray:
    """The GCP equations' partial derivatives by the frame parameters (rows as
    :func:`linearise` orders them; px per m): each GCP's ground Jacobian in each image, in the
    columns of its frame's east, north and up."""
    blocks = []
    for m, model in enumerate(models):
        u = use[:, m]
        g = ground_jacobian(model, obs.lon_deg[u], obs.lat_deg[u], obs.h_m[u])  # (k, 2, 3)
        out = np.zeros((int(u.sum()), 2, frames.n))
        idx = frames.index[np.asarray(obs.frame)[u]]  # (k, 3)
        for c in range(3):
            has = idx[:, c] >= 0
            out[np.flatnonzero(has), :, idx[has, c]] = g[has, :, c]
        blocks.append(out.reshape(-1, frames.n))
    return np.vstack(blocks) if blocks else np.zeros((0, frames.n))


def prior_rows(models: Sequence[SensorModel], obs: Observations, prior_px: float,
               prior_terms: Sequence[str], ridge: float = 1e4) -> FloatArray:
    """Whitened prior equations (k, n_params) on the parameters named in ``prior_terms``
    (``rows @ params`` has unit variance; zero columns for the others), two kinds per image:

    - what the image sees: the RMS over the image of the terms' joint effect that the other
      parameters (the attitude) cannot absorb is ``prior_px``, 1 sigma (their partial
      derivatives over a 9 x 9 grid of the whole image at the GCPs' median height, less their
      least-squares fit by the other parameters' partials; at the GCPs for a model that does
      not say its image size). A camera whose look angles include a steering mirror's 25
      degrees puts most of a radial term into a bias and a scale of the line: only the rest
      is a calibration error, and nearly collinear terms are held together, not one by one;
    - each term alone within ``ridge`` times ``prior_px`` of its largest raw effect, so a
      combination the attitude absorbs whole cannot run away either.
    """
    blocks = []
    h0 = float(np.median(obs.h_m))
    n_params = sum(len(m.params) for m in models)
    start = 0
    for model in models:
        wanted = [j for j, n in enumerate(model.param_names) if n in prior_terms]
        if wanted:
            size = (getattr(model, "n_cols", None), getattr(model, "n_rows", None))
            if None not in size:
                c, r = image_grid(int(size[0]), int(size[1]), 9)
                lon, lat = model.localize(c, r, np.full(c.shape, h0))
                h = np.full(c.shape, h0)
            else:
                lon, lat, h = obs.lon_deg, obs.lat_deg, obs.h_m
            jac = np.asarray(model.jacobian(lon, lat, h), np.float64)  # (n, 2, p)
            flat = jac.reshape(-1, jac.shape[2])
            raw = np.max(np.abs(flat[:, wanted]), axis=0)
            others = [j for j in range(flat.shape[1]) if j not in wanted]
            seen = flat[:, wanted]
            if others:
                base = flat[:, others]
                seen = seen - base @ np.linalg.lstsq(base, seen, rcond=None)[0]
            rms = np.linalg.qr(seen / np.sqrt(jac.shape[0]), mode="r") / prior_px
            rows = np.zeros((2 * len(wanted), n_params))
            rows[:len(wanted), start + np.array(wanted)] = rms
            rows[len(wanted) + np.arange(len(wanted)), start + np.array(wanted)] = (
                np.where(raw > 0, raw, 1.0) / (ridge * prior_px))
            blocks.append(rows)
        start += len(model.params)
    return np.vstack(blocks) if blocks else np.zeros((0, n_params))


def linearise(models: Sequence[SensorModel], obs: Observations, col: FloatArray,
               row: FloatArray, sigma: FloatArray, use: NDArray[np.bool_],
               offsets: NDArray[np.intp], jacobian: bool = True
               ) -> tuple[FloatArray, FloatArray, FloatArray, NDArray[np.intp]]:
    """The GCP equations of every model at its current parameters: the design (2 rows per
    measurement, col then row, over all images' parameters; empty when ``jacobian`` is False),
    the residuals (measured - projected, px), their a-priori variances (px^2) and the axis of
    each row (0 col, 1 row). ``use``: (n_gcp, n_model) the measurements taken."""
    a_blocks, res, var = [], [], []
    for m, model in enumerate(models):
        u = use[:, m]
        pc, pr = model.project(obs.lon_deg[u], obs.lat_deg[u], obs.h_m[u])
        if jacobian:
            jac = model.jacobian(obs.lon_deg[u], obs.lat_deg[u], obs.h_m[u])
            full = np.zeros((u.sum(), 2, offsets[-1]))
            full[:, :, offsets[m]:offsets[m + 1]] = jac
            a_blocks.append(full.reshape(-1, offsets[-1]))
        res.append(np.stack([col[u, m] - pc, row[u, m] - pr], axis=1).ravel())
        var.append(np.repeat(sigma[u, m] ** 2, 2))
    r = np.concatenate(res)
    a = np.vstack(a_blocks) if jacobian else np.zeros((r.size, int(offsets[-1])))
    return a, r, np.concatenate(var), np.tile([0, 1], r.size // 2)
