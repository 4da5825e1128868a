"""The GCPs' errors as their residuals show them, taken into an adjustment's uncertainty: the
model's own error where the residuals show one their ground cannot have made, the GCPs' ground
error correlated over kilometres (:mod:`core.orientation.ground_field`) in the parameters'
covariance, and the error that follows the time of imaging from the tie points."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from core.geodesy import metres_per_degree
from core.orientation.absolute import AbsoluteConfig, gcp_factors, observation_sigmas_px
from core.orientation.ground_field import (
    NO_CORRELATION,
    CorrelatedGroundError,
    correlated_covariance,
    correlated_ground_error,
)
from core.orientation.observations import Observations
from core.orientation.result import AbsoluteOrientation
from core.orientation.ties import TieObservations, tie_residuals
from core.orientation.uncertainty import (
    along_track_covariance,
    parallax_covariance,
)

FloatArray = NDArray[np.float64]


def with_gcp_errors_as_they_are(adj: AbsoluteOrientation, obs: Observations,
                                kept: np.ndarray, config: AbsoluteConfig,
                                ties: TieObservations | None = None
                                ) -> tuple[AbsoluteOrientation, CorrelatedGroundError]:
    """``adj`` with the uncertainties the GCPs measured in two images or more support: the model's own
    error only where their residuals show one their ground cannot have made (``uncertainty.
    parallax_covariance``; the smooth part of the raw residuals is mostly the reference's
    error, correlated over kilometres), that correlated ground error propagated into the
    parameters' covariance (``correlated_covariance``) instead; with the tie points ``ties``,
    the model's error that follows the time of imaging (jitter faster than the GCPs' spacing)
    from their parallax at points nearest in time (``along_track_covariance``). Unchanged
    with fewer than 3 such GCPs. Returned with the correlated ground error found."""
    taken = np.isfinite(np.asarray(obs.col)) & np.isfinite(np.asarray(obs.row))
    use = np.asarray(kept, dtype=bool) & (taken.sum(axis=1) >= 2)
    if use.sum() < 3:
        return adj, NO_CORRELATION
    sub = obs.subset(use)
    col, row, seen = np.asarray(sub.col), np.asarray(sub.row), taken[use]
    models = adj.models
    jac, ground = adj.gcp_design(sub, seen)
    here = sub.shifted(adj.frame_layout, adj.frame_params)
    lon, lat, h = here.lon_deg, here.lat_deg, here.h_m
    v = np.zeros(col.shape + (2,))
    for k, model in enumerate(models):
        s = seen[:, k]
        if s.any():
            pc, pr = model.project(lon[s], lat[s], h[s])
            v[s, k, 0], v[s, k, 1] = col[s, k] - pc, row[s, k] - pr
    m_lon, m_lat = metres_per_degree(float(np.mean(lat)))
    east, north = (lon - lon.mean()) * m_lon, (lat - lat.mean()) * m_lat
    sigma = np.repeat(observation_sigmas_px(models, sub, config.matching_sigma_px)[..., None],
                      2, axis=2)
    comps = adj.components
    if comps is None:
        sigma = sigma * max(adj.sigma0, 1e-12)
    else:  # each GCP's frame's factors (one pair for all when calibrated together)
        factors = np.array([gcp_factors(comps, name) for name in adj.frame_layout.names])
        sigma = sigma * np.sqrt(factors[np.asarray(sub.frame)])[:, None, :]
    sigma = np.where(seen[..., None], sigma, np.inf)  # a block's GCP: its own images only
    error = correlated_ground_error(ground, v, east, north,
                                    absorbed=(jac, sigma, adj.covariance))
    cov = correlated_covariance(adj.covariance, jac, sigma, ground, east, north, error)
    if seen.all():
        mu2 = parallax_covariance(ground, v, col[:, 0], row[:, 0])
    else:
        mu2 = _parallax_by_images(ground, v, seen, east, north)
    if ties is not None and ties.n >= 3 and ties.n_images == len(models) and ties.complete:
        tie_ground, tie_v = tie_residuals(models, ties)
        mu2 += along_track_covariance(tie_ground, tie_v, ties.row)
    mu = float(np.sqrt(mu2))
    residuals = tuple(replace(r, unmodelled_col_px=mu, unmodelled_row_px=mu)
                      for r in adj.residuals)
    return replace(adj, covariance=cov, residuals=residuals), error


def _parallax_by_images(ground: FloatArray, v: FloatArray, seen: NDArray[np.bool_],
                        east_m: FloatArray, north_m: FloatArray) -> float:
    """:func:`~core.orientation.uncertainty.parallax_covariance` of a block's GCPs, each group
    of GCPs seen by the same images on its own (neighbours sought on the ground, east and
    north), weighted by the group's size; 0 with no group of 3."""
    patterns, which = np.unique(seen, axis=0, return_inverse=True)
    total, weight = 0.0, 0
    for q, pattern in enumerate(patterns):
        idx = np.flatnonzero(which.ravel() == q)
        images = np.flatnonzero(pattern)
        if idx.size < 3 or images.size < 2:
            continue
        mu2 = parallax_covariance(ground[np.ix_(idx, images)], v[np.ix_(idx, images)],
                                  east_m[idx], north_m[idx])
        total, weight = total + mu2 * idx.size, weight + idx.size
    return total / weight if weight else 0.0
