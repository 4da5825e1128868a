"""The GCPs' errors as their residuals show them, taken into an adjustment's uncertainty: the
model's own error where the residuals show one their ground cannot have made, the GCPs' ground
error correlated over kilometres (:mod:`core.orientation.ground_field`) in the parameters'
covariance, and the error that follows the time of imaging from the tie points."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from core.geodesy import metres_per_degree
from core.orientation.absolute import AbsoluteConfig, observation_sigmas_px
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
    """``adj`` with the uncertainties the GCPs measured in both images support: the model's own
    error only where their residuals show one their ground cannot have made (``uncertainty.
    parallax_covariance``; the smooth part of the raw residuals is mostly the reference's
    error, correlated over kilometres), that correlated ground error propagated into the
    parameters' covariance (``correlated_covariance``) instead; with the tie points ``ties``,
    the model's error that follows the time of imaging (jitter faster than the GCPs' spacing)
    from their parallax at points nearest in time (``along_track_covariance``). Unchanged
    with fewer than 3 such GCPs. Returned with the correlated ground error found."""
    use = np.asarray(kept, dtype=bool) & np.isfinite(obs.col).all(axis=1) \
        & np.isfinite(obs.row).all(axis=1)
    if use.sum() < 3:
        return adj, NO_CORRELATION
    sub = obs.subset(use)
    col, row = np.asarray(sub.col), np.asarray(sub.row)
    models = adj.models
    jac, ground = adj.gcp_design(sub, np.ones(col.shape, dtype=bool))
    here = sub.shifted(adj.frame_layout, adj.frame_params)
    lon, lat, h = here.lon_deg, here.lat_deg, here.h_m
    v = np.empty(col.shape + (2,))
    for k, model in enumerate(models):
        pc, pr = model.project(lon, lat, h)
        v[:, k, 0], v[:, k, 1] = col[:, k] - pc, row[:, k] - pr
    m_lon, m_lat = metres_per_degree(float(np.mean(lat)))
    east, north = (lon - lon.mean()) * m_lon, (lat - lat.mean()) * m_lat
    sigma = np.repeat(observation_sigmas_px(models, sub, config.matching_sigma_px)[..., None],
                      2, axis=2)
    comps = adj.components
    if comps is None:
        sigma = sigma * max(adj.sigma0, 1e-12)
    elif "gcp" in comps.names:
        sigma = sigma * np.sqrt(comps.factor_of("gcp"))
    else:
        sigma = sigma * np.sqrt([comps.factor_of("gcp_col"), comps.factor_of("gcp_row")])
    error = correlated_ground_error(ground, v, east, north,
                                    absorbed=(jac, sigma, adj.covariance))
    cov = correlated_covariance(adj.covariance, jac, sigma, ground, east, north, error)
    mu2 = parallax_covariance(ground, v, col[:, 0], row[:, 0])
    if ties is not None and ties.n >= 3 and ties.n_images == len(models) and ties.complete:
        tie_ground, tie_v = tie_residuals(models, ties)
        mu2 += along_track_covariance(tie_ground, tie_v, ties.row)
    mu = float(np.sqrt(mu2))
    residuals = tuple(replace(r, unmodelled_col_px=mu, unmodelled_row_px=mu)
                      for r in adj.residuals)
    return replace(adj, covariance=cov, residuals=residuals), error
