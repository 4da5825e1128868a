"""Absolute orientation: every image's model adjusted to ground control points (GCPs).

Step 4 of the chain (Goncalves 4.1). Each GCP has ground coordinates (lon, lat, ellipsoidal h)
and its measured position in some images; the models' corrections (through the SensorModel
protocol: ``param_names``, ``with_params``, ``jacobian``) are adjusted by iteratively
reweighted Gauss-Newton so that the GCPs project where they were measured. Each observation is
weighted by its expected error in pixels: the matching precision and the GCP's ground
precision carried into the image (horizontal error over the ground sampling, vertical error
times the tangent of the incidence). Blunders: Huber weights, then the GCPs whose normalised
residual exceeds ``reject_k`` are removed, one round at a time, with their residual given as
the reason. Lens self-calibration (:func:`self_calibrate`) adds radial and decentering terms and
keeps those whose estimate is significant against its sigma.

Each GCP belongs to a frame (:mod:`core.orientation.frames`): the source it came from (the
reference DEM, a SAR scene), whose common shift is an unknown of the adjustment held by its
prior. The parameters' covariance then carries what the frames' registrations do to the
images, and a prediction is split into what the method achieves given the frames (the
relative part) and what the frames themselves carry (the reference part).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from core.errors import ConvergenceError, GeometryError, InputError, InsufficientDataError
from core.geodesy import geodetic_to_ecef
from core.orientation.equations import GROUPS, Equations, System, prior_rows
from core.orientation.frames import (
    REFERENCE,
    FrameLayout,
    FramePrior,
)
from core.orientation.observations import Observations
from core.orientation.result import AbsoluteOrientation, ImageResiduals
from core.orientation.ties import TieObservations
from core.orientation.uncertainty import (
    VarianceComponents,
    components_differ,
    neighbour_covariance,
    normal_matrix,
    solve_with_components,
    sparse_when_worth_it,
)
from core.robust import RobustAdjustment, huber_weights, nmad
from core.sensors.base import SensorModel

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class AbsoluteConfig(RobustAdjustment):
    """Settings of :func:`absolute_orientation`: the robust adjustment's
    (:class:`~core.robust.RobustAdjustment`; ``huber_k`` and ``reject_k`` in normalised
    residuals, wider than the relative orientation's, and a rejection round per blunder), the
    matching precision of the image measurements (px) and the fewest GCPs to solve with.

    ``variance_components``: once the blunders are out, the GCPs' a-priori sigmas are
    calibrated on their residuals, one factor for the columns and one for the rows
    (:mod:`core.orientation.uncertainty`), merged into one when the F test at ``split_alpha``
    finds them alike; the parameters and their covariance are then those of that weighting.
    The GCPs of each frame (SRTM windows, SAR points) get factors of their own when
    ``components_by_frame`` (else one set for all): right when a source's scatter differs
    from what it states (200 SAR points stating 3 m, scattering 15 m: factors 0.5 and 8-11,
    check points 0.10 px against 0.16 with one set), but not the default: where the SAR's
    error is systematic (a timing error over relief, which a frame's shift does not follow)
    its residuals stay small, its own factor lower, and it pulls more (simulated tiny, SAR
    44 / 21 m off: right columns 0.64 px against 0.60 with one set). Variance components
    off: today's robust solution and its covariance scaled by the robust ``sigma0``.
    ``reference_sigma_m``: the reference's registration error (east, north, up; m, 1 sigma),
    common to every GCP and so invisible in their residuals: the prior of the reference's
    frame when no frames are given (:mod:`core.orientation.frames`), which the predicted
    check-point RMS carries (:meth:`AbsoluteOrientation.predict`); 5 m as the relative
    orientation assumes.
    ``prior_px``, ``prior_terms``: the adjusted parameters named in ``prior_terms`` (the
    additional parameters of self-calibration: lens, look-angle scale, bow) are constrained to
    their delivered values, their joint effect on the image beyond what the attitude absorbs
    worth ``prior_px`` pixels RMS, 1 sigma (:func:`core.orientation.equations.prior_rows`):
    a calibration error the producer left larger than that would have been
    seen, and a term the GCPs cannot determine stays put instead of running away."""

    huber_k: float = 2.0
    reject_k: float = 3.5
    max_rejection_rounds: int = 200
    matching_sigma_px: float = 0.3
    min_gcps: int = 4
    variance_components: bool = True
    components_by_frame: bool | None = None  # None (unset, as before the option): off
    split_alpha: float = 0.01
    reference_sigma_m: tuple[float, float, float] = (5.0, 5.0, 5.0)
    prior_px: float = 2.0
    prior_terms: tuple[str, ...] = ("focal_scale", "k1", "k3", "p1", "p2")

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.matching_sigma_px <= 0 or self.min_gcps < 1:
            raise InputError("need matching_sigma_px > 0 and min_gcps >= 1")
        if len(self.reference_sigma_m) != 3 or min(self.reference_sigma_m) < 0:
            raise InputError("reference_sigma_m is (east, north, up) in metres, each >= 0")
        if not self.prior_px > 0:
            raise InputError(f"prior_px is a sigma in pixels, > 0; got {self.prior_px}")
        if not 0.0 < self.split_alpha < 1.0:
            raise InputError(f"split_alpha is a probability in (0, 1), got {self.split_alpha}")


def observation_sigmas_px(models: Sequence[SensorModel], obs: Observations,
                          matching_sigma_px: float) -> FloatArray:
    """(n_gcp, n_img) expected error of each measurement: matching plus the GCP's ground error
    seen from that image (horizontal over the GSD, vertical times tan(incidence) over it); NaN
    where an image does not measure the GCP (never projected there: in a block it may lie far
    outside that image)."""
    out = np.full(np.shape(obs.col), np.nan)
    seen = np.isfinite(np.asarray(obs.col)) & np.isfinite(np.asarray(obs.row))
    for m, model in enumerate(models):
        s = seen[:, m]
        if not s.any():
            continue
        lon, lat, h = obs.lon_deg[s], obs.lat_deg[s], obs.h_m[s]
        g = np.stack(geodetic_to_ecef(lon, lat, h), axis=1)
        c, r = model.project(lon, lat, h)
        lon1, lat1 = model.localize(c + 1.0, r, h)
        gsd = np.linalg.norm(np.stack(geodetic_to_ecef(lon1, lat1, h), axis=1) - g, axis=1)
        lon_up, lat_up = model.localize(c, r, h + 100.0)
        shift = np.linalg.norm(np.stack(geodetic_to_ecef(lon_up, lat_up, h), axis=1) - g,
                               axis=1) / 100.0  # tan(incidence)
        out[s, m] = np.sqrt(matching_sigma_px**2 + (obs.sigma_xy_m[s]**2
                                                    + (obs.sigma_h_m[s] * shift) ** 2) / gsd**2)
    return out


def _damped_step(models: list[SensorModel], frame_x: FloatArray, dp: FloatArray,
                 offsets: NDArray[np.intp], obs: Observations, frames: FrameLayout,
                 use: NDArray[np.bool_], max_halvings: int = 10
                 ) -> tuple[list[SensorModel], FloatArray]:
    """The models and frame parameters moved by ``dp``, halved while the step sends GCPs
    behind a camera (a Gauss-Newton step far from the solution, e.g. lens terms tried on a
    poor start). ``use``: (n_gcp, n_model), the GCPs each model must still project."""
    for _ in range(max_halvings + 1):
        moved = [model.with_params(model.params + dp[offsets[m]:offsets[m + 1]])
                 for m, model in enumerate(models)]
        fx = frame_x + dp[offsets[-1]:]
        o = obs.shifted(frames, fx)
        try:
            for m, model in enumerate(moved):
                u = use[:, m]
                model.project(o.lon_deg[u], o.lat_deg[u], o.h_m[u])
            return moved, fx
        except (GeometryError, ConvergenceError):  # behind a camera, or no image position
            dp = 0.5 * dp
    raise ConvergenceError("absolute orientation diverged: every step sends GCPs outside the "
                           "images' geometry; the GCPs or the starting models are wrong")


def frame_layout(frames: Sequence[FramePrior] | None, obs: Observations,
                 config: AbsoluteConfig) -> FrameLayout:
    """The frames of an adjustment: ``frames`` as given, or the reference's alone with
    ``config.reference_sigma_m`` (considered, not estimated); every GCP's frame index must
    name one of them."""
    priors = tuple(frames) if frames else (FramePrior(
        REFERENCE, config.reference_sigma_m, source="reference_sigma_m", estimated=False),)
    layout = FrameLayout.of(priors)
    f = np.asarray(obs.frame)
    if f.size and f.max() >= len(priors):
        raise InputError(f"a GCP names frame {int(f.max())} of {len(priors)} frames")
    return layout


def absolute_orientation(models: Sequence[SensorModel], obs: Observations,
                         names: Sequence[str] | None = None,
                         config: AbsoluteConfig = AbsoluteConfig(),
                         ties: TieObservations | None = None,
                         frames: Sequence[FramePrior] | None = None) -> AbsoluteOrientation:
    """Adjust every model's current parameters and the frames' shifts (``frames``, each GCP's
    frame ``obs.frame``; default the reference's alone, :func:`frame_layout`) to the GCPs
    (robust, with blunder rejection), and to the tie points ``ties`` when given (their ground
    unknowns removed: :mod:`core.orientation.ties`), the additional parameters held by their
    priors (``config.prior_terms``), the frames by theirs.

    Levenberg-Marquardt on the parameters scaled to their effect in pixels (each column of the
    design over its weighted norm), the robust weights of each iteration fixed while its step is
    searched: a step is taken only when it lowers the weighted squares.

    Raises InsufficientDataError with fewer than ``config.min_gcps`` GCPs kept and
    ConvergenceError when the adjustment does not settle.
    """
    models = list(models)
    names = tuple(names) if names is not None else tuple(f"image{i}" for i in range(len(models)))
    col, row = np.asarray(obs.col, dtype=np.float64), np.asarray(obs.row, dtype=np.float64)
    n_gcp, n_img = col.shape
    if n_img != len(models) or len(names) != n_img:
        raise InputError(f"{n_img} image columns of GCP measurements for {len(models)} models")
    if n_gcp < config.min_gcps:
        raise InsufficientDataError(f"{n_gcp} GCPs, {config.min_gcps} needed at least")
    layout = frame_layout(frames, obs, config)
    sizes = [len(m.params) for m in models]
    offsets = np.concatenate([[0], np.cumsum(sizes)])
    before = tuple(m.params.copy() for m in models)
    sigma = observation_sigmas_px(models, obs, config.matching_sigma_px)
    seen = np.isfinite(col) & np.isfinite(row)
    inlier = seen.any(axis=1)
    eqs = Equations(obs, col, row, sigma, seen, offsets, ties,
                    prior_rows(models, obs, config.prior_px, config.prior_terms), layout)
    fx = np.zeros(layout.n)
    active = np.concatenate([np.ones(int(offsets[-1]), dtype=bool), layout.estimated])
    reasons: dict[int, str] = {}
    iterations, converged = 0, False
    lam = 1e-4
    for _ in range(config.max_rejection_rounds + 1):
        if inlier.sum() < config.min_gcps:
            raise InsufficientDataError(
                f"only {int(inlier.sum())} of {n_gcp} GCPs agree with one another "
                f"({config.min_gcps} needed); the GCPs are unreliable")
        converged = False
        system = eqs.build(models, fx, inlier)
        for _ in range(config.max_iterations):
            iterations += 1
            a, r = system.a[:, active], system.r
            w0 = 1.0 / system.q
            w = w0 * huber_weights(np.abs(r) * np.sqrt(w0), config.huber_k)
            w[system.group == GROUPS.index("frame")] = 1.0  # a prior, not an observation
            scale = np.sqrt(np.sum(a**2 * w[:, None], axis=0))
            scale = np.where(scale > 0, scale, 1.0)
            a_s = sparse_when_worth_it(a / scale)  # a block's: CSR, linear in its images
            normal = normal_matrix(a_s, w)
            grad = a_s.T @ (w * r)
            cost = float(np.sum(w * r**2))
            for _ in range(12):  # Levenberg-Marquardt: damp until the step lowers the cost
                damped = normal + lam * np.diag(np.diag(normal))
                dp = np.zeros(active.size)
                dp[active] = np.linalg.lstsq(damped, grad, rcond=1e-12)[0] / scale
                trial, trial_fx = _damped_step(models, fx, dp, offsets, obs, layout,
                                               inlier[:, None] & seen)
                trial_system = eqs.build(trial, trial_fx, inlier, jacobian=False)
                if float(np.sum(w * trial_system.r**2)) <= cost * (1.0 + 1e-9):
                    lam = max(lam / 10.0, 1e-9)
                    break
                lam *= 10.0
            else:  # no step lowers the cost: at its minimum
                converged = True
                break
            models[:], fx = trial, trial_fx
            eqs.accept(trial_system)
            if np.max(np.abs(system.a @ dp)) < config.tol_px:
                converged = True
                break
            system = eqs.build(models, fx, inlier)
        if not converged:
            raise ConvergenceError(
                f"absolute orientation did not converge in {config.max_iterations} iterations; "
                "the GCPs may be wrong or too few for the parameters")
        here = obs.shifted(layout, fx)
        worst = np.zeros(n_gcp)
        for m, model in enumerate(models):
            use = seen[:, m]
            pc, pr = model.project(here.lon_deg[use], here.lat_deg[use], here.h_m[use])
            zc = np.abs(col[use, m] - pc) / sigma[use, m]
            zr = np.abs(row[use, m] - pr) / sigma[use, m]
            worst[use] = np.maximum(worst[use], np.maximum(zc, zr))
        s0 = _sigma0(models, here, col, row, sigma, seen, inlier, offsets[-1])
        limit = config.reject_k * max(s0, 1.0)
        candidates = np.flatnonzero(inlier & (worst > limit))
        if candidates.size == 0:
            break
        # one blunder at a time (a blunder bends the fit and raises its neighbours' residuals),
        # but those beyond three times the limit all at once: they are blunders whatever the rest
        gross = candidates[worst[candidates] > 3.0 * limit]
        for k in (gross if gross.size else [int(candidates[np.argmax(worst[candidates])])]):
            inlier[k] = False
            reasons[int(k)] = (f"normalised residual {worst[k]:.1f} over {limit:.1f} "
                               f"({config.reject_k} x sigma0 {max(s0, 1.0):.2f})")
    s0 = _sigma0(models, obs.shifted(layout, fx), col, row, sigma, seen, inlier, offsets[-1])
    comps = None
    if config.variance_components:
        models[:], fx, cov, comps = _calibrated(models, fx, eqs, inlier, offsets, obs, seen,
                                                config, active)
        iterations += comps.n_iterations
    else:
        system = eqs.build(models, fx, inlier)
        w0 = 1.0 / system.q
        scale = np.sqrt(np.sum(system.a**2 * w0[:, None], axis=0))
        scale = np.where(scale > 0, scale, 1.0)
        a_s = system.a / scale
        cov = s0**2 * np.linalg.pinv(a_s.T @ (a_s * w0[:, None])) / np.outer(scale, scale)
    here = obs.shifted(layout, fx)
    residuals = []
    for m, model in enumerate(models):
        use = inlier & seen[:, m]
        pc, pr = model.project(here.lon_deg[use], here.lat_deg[use], here.h_m[use])
        dc, dr = col[use, m] - pc, row[use, m] - pr
        residuals.append(ImageResiduals(
            names[m], int(use.sum()), _rms(dc), _rms(dr), float(np.mean(dc)) if dc.size else 0.0,
            float(np.mean(dr)) if dr.size else 0.0, dc, dr,
            float(np.sqrt(neighbour_covariance(col[use, m], row[use, m], dc))),
            float(np.sqrt(neighbour_covariance(col[use, m], row[use, m], dr)))))
    n_ties, tie_rms = 0, None
    if ties is not None and ties.n:
        final = eqs.build(models, fx, inlier, jacobian=False)
        n_ties = ties.n
        tie_rms = _rms(final.r[final.group == 2]) * ties.sigma_px
    return AbsoluteOrientation(
        models=tuple(models), names=names, param_names=tuple(m.param_names for m in models),
        params_before=before, params_after=tuple(m.params.copy() for m in models),
        covariance=cov, sigma0=s0, residuals=tuple(residuals), inlier=inlier, reasons=reasons,
        n_iterations=iterations, converged=converged, components=comps, n_ties=n_ties,
        tie_rms_px=tie_rms, frame_layout=layout, frame_params=fx.copy())


def _calibrated(models: list[SensorModel], frame_x: FloatArray, eqs: Equations,
                inlier: NDArray[np.bool_], offsets: NDArray[np.intp], obs: Observations,
                seen: NDArray[np.bool_], config: AbsoluteConfig, active: NDArray[np.bool_]
                ) -> tuple[list[SensorModel], FloatArray, FloatArray, VarianceComponents]:
    """The models re-adjusted on the GCPs kept (and the tie points and priors) with their
    sigmas calibrated by variance components: GCP columns and rows apart when the F test
    separates them, else one factor; the GCPs of each frame their own when they belong to
    several (SRTM windows and SAR points are different instruments: one factor for both let
    347 SAR points bend the shape 39 windows gave, :func:`gcp_factors`); the tie points their
    own; the priors (the additional parameters' and the frames') fixed; the ``active``
    parameters solved for (a frame only considered is held, its prior in the covariance). The
    frame parameters, the covariance of every parameter under those components, and the
    components."""
    use = inlier[:, None] & seen
    taken = inlier & seen.any(axis=1)
    sources = np.unique(np.asarray(obs.frame)[taken])
    per_source = sources.size > 1 and bool(config.components_by_frame)
    frame_names = eqs.frames.names
    tags = [f":{frame_names[int(f)]}" for f in sources] if per_source else [""]
    # the other groups there are rows of: tie points, priors and frames if given
    others = ([2] if eqs.ties is not None and eqs.ties.n else []) + (
        [3] if eqs.prior.shape[0] else []) + ([4] if eqs.frames.n else [])

    def solve(split: bool) -> tuple[list[SensorModel], FloatArray, FloatArray,
                                    VarianceComponents]:
        moved, fx, factors, n_it = list(models), frame_x.copy(), None, 0
        gcp_names = [n + t for t in tags for n in (("gcp_col", "gcp_row") if split else ("gcp",))]
        names = tuple(gcp_names) + tuple(GROUPS[k] for k in others)

        def grouped(system: System) -> NDArray[np.intp]:
            g = system.group
            out = np.zeros_like(g)
            gcp = g <= 1
            src = (np.searchsorted(sources, system.source[gcp]) if per_source
                   else np.zeros(int(gcp.sum()), np.intp))
            out[gcp] = src * 2 + g[gcp] if split else src
            for j, k in enumerate(others):
                out[g == k] = len(gcp_names) + j
            return out

        for _ in range(config.max_iterations):
            sys_ = eqs.build(moved, fx, inlier)
            sol = solve_with_components(sys_.a[:, active], sys_.r, sys_.q, grouped(sys_),
                                        names, factors, fixed=("prior", "frame"))
            factors, n_it = sol.components.factors, n_it + sol.components.n_iterations
            dx = np.zeros(active.size)
            dx[active] = sol.dx
            moved, fx = _damped_step(moved, fx, dx, offsets, obs, eqs.frames, use)
            eqs.accept(sys_)
            if np.max(np.abs(sys_.a @ dx)) < config.tol_px:
                break
        sys_ = eqs.build(moved, fx, inlier)
        sol = solve_with_components(sys_.a[:, active], sys_.r, sys_.q, grouped(sys_),
                                    names, factors, fixed=("prior", "frame"))
        cov = sol.covariance
        if not active.all():  # every parameter's, the considered frames' with their priors
            cov = solve_with_components(sys_.a, sys_.r, sys_.q, grouped(sys_), names,
                                        sol.components.factors, fixed=names).covariance
        return moved, fx, cov, replace(sol.components, n_iterations=n_it)

    split = solve(True)
    c = split[3]
    pairs = [(2 * k, 2 * k + 1) for k in range(len(tags))]
    factors = ", ".join(f"{c.factors[i]:.3g} and {c.factors[j]:.3g}{tags[i // 2]}"
                        for i, j in pairs)
    if any(components_differ(c, i, j, config.split_alpha) for i, j in pairs):
        return split[0], split[1], split[2], replace(
            c, split=f"columns and rows apart: factors {factors} differ (F test at "
                     f"{config.split_alpha:g})")
    one = solve(False)
    return one[0], one[1], one[2], replace(
        one[3], split=f"one factor: columns and rows {factors} alike (F test at "
                      f"{config.split_alpha:g})")


def gcp_factors(components: VarianceComponents | None, frame: str) -> tuple[float, float]:
    """The variance factors of the columns and rows of the GCPs of ``frame`` in
    ``components`` (:func:`_calibrated`'s names: ``gcp_col:FRAME`` / ``gcp:FRAME`` when the
    GCPs of several frames were calibrated apart, else ``gcp_col`` / ``gcp``); 1 without."""
    if components is None:
        return 1.0, 1.0
    for tag in (f":{frame}", ""):
        if f"gcp{tag}" in components.names:
            f = components.factor_of(f"gcp{tag}")
            return f, f
        if f"gcp_col{tag}" in components.names:
            return (components.factor_of(f"gcp_col{tag}"),
                    components.factor_of(f"gcp_row{tag}"))
    return 1.0, 1.0


def _rms(v: FloatArray) -> float:
    return float(np.sqrt(np.mean(v**2))) if v.size else float("nan")


def _sigma0(models: Sequence[SensorModel], obs: Observations, col: FloatArray, row: FloatArray,
            sigma: FloatArray, seen: NDArray[np.bool_], inlier: NDArray[np.bool_],
            n_params: int) -> float:
    """Robust a-posteriori sigma of unit weight over the kept GCPs (``obs``: their ground in
    the frames as adjusted)."""
    z = []
    for m, model in enumerate(models):
        use = inlier & seen[:, m]
        pc, pr = model.project(obs.lon_deg[use], obs.lat_deg[use], obs.h_m[use])
        z.append((col[use, m] - pc) / sigma[use, m])
        z.append((row[use, m] - pr) / sigma[use, m])
    zz = np.concatenate(z)
    if zz.size <= n_params:
        return 1.0
    return nmad(zz, centre=0.0) * float(np.sqrt(zz.size / (zz.size - n_params)))
