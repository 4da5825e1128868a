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
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.errors import ConvergenceError, GeometryError, InputError, InsufficientDataError
from core.geodesy import geodetic_to_ecef, metres_per_degree
from core.orientation.equations import GROUPS, Equations, prior_rows
from core.orientation.ground_field import (
    NO_CORRELATION,
    CorrelatedGroundError,
    correlated_covariance,
    correlated_ground_error,
)
from core.orientation.ties import TieObservations, tie_residuals
from core.orientation.uncertainty import (
    PredictedAccuracy,
    VarianceComponents,
    along_track_covariance,
    components_differ,
    ground_jacobian,
    image_grid,
    neighbour_covariance,
    parallax_covariance,
    solve_with_components,
)
from core.points import ControlPoint
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
    Off: today's robust solution and its covariance scaled by the robust ``sigma0``.
    ``reference_sigma_m``: the reference's registration error (east, north, up; m, 1 sigma),
    common to every GCP and so invisible in their residuals, which the predicted check-point
    RMS adds (:meth:`AbsoluteOrientation.predict`); 5 m as the relative orientation assumes.
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


@dataclass(frozen=True, eq=False)
class Observations:
    """GCP measurements in the images: ``col``/``row`` (n_gcp, n_img) with NaN where a GCP is
    not measured in an image; GCP ground coordinates (n_gcp,); ground precisions (m)."""

    lon_deg: FloatArray
    lat_deg: FloatArray
    h_m: FloatArray
    col: FloatArray
    row: FloatArray
    sigma_xy_m: FloatArray
    sigma_h_m: FloatArray

    def __post_init__(self) -> None:
        n = np.asarray(self.lon_deg).size
        for name in ("lat_deg", "h_m", "sigma_xy_m", "sigma_h_m"):
            if np.asarray(getattr(self, name)).shape != (n,):
                raise InputError(f"GCP {name} has shape {np.shape(getattr(self, name))}, "
                                 f"expected ({n},)")
        if np.shape(self.col) != np.shape(self.row) or np.shape(self.col)[0] != n:
            raise InputError("GCP image coordinates must be (n_gcp, n_images), cols and rows "
                             "alike")

    @classmethod
    def from_control_points(cls, points: Sequence[ControlPoint],
                            names: Sequence[str]) -> Observations:
        """The measurements of ``points`` in the images ``names`` (NaN where a point is not
        measured in an image)."""
        col = np.full((len(points), len(names)), np.nan)
        row = np.full_like(col, np.nan)
        for i, p in enumerate(points):
            for j, name in enumerate(names):
                if name in p.image_points:
                    col[i, j], row[i, j] = p.image_points[name].col, p.image_points[name].row

        def arr(attr: str) -> FloatArray:
            return np.array([getattr(p, attr) for p in points], dtype=np.float64)

        return cls(arr("lon_deg"), arr("lat_deg"), arr("h_m"), col, row, arr("sigma_xy_m"),
                   arr("sigma_h_m"))


@dataclass(frozen=True, eq=False)
class ImageResiduals:
    """Residuals (measured - projected, px) of one image at the GCPs kept: ``rms_col_px`` is the
    paper's P, ``rms_row_px`` its L; ``unmodelled_*_px`` the part of them smooth across the
    image, the model's own error (:func:`core.orientation.uncertainty.neighbour_covariance`,
    square-rooted)."""

    name: str
    n: int
    rms_col_px: float
    rms_row_px: float
    mean_col_px: float
    mean_row_px: float
    col_px: FloatArray = field(repr=False)
    row_px: FloatArray = field(repr=False)
    unmodelled_col_px: float = 0.0
    unmodelled_row_px: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "n": self.n, "rms_col_px": self.rms_col_px,
                "rms_row_px": self.rms_row_px, "mean_col_px": self.mean_col_px,
                "mean_row_px": self.mean_row_px}


@dataclass(frozen=True, eq=False)
class AbsoluteOrientation:
    """The adjusted models and how well they fit the GCPs.

    ``rejected`` lists the GCP indices removed, with the normalised residual that condemned
    each (``reasons``); ``covariance`` is over the concatenated parameters of all images (in
    each model's parameter units), under the GCP sigmas calibrated on the data
    (``components``; without them, the a-priori sigmas times ``sigma0``); ``sigma0`` the robust
    a-posteriori standard deviation of unit weight under the a-priori sigmas.
    """

    models: tuple[SensorModel, ...]
    names: tuple[str, ...]
    param_names: tuple[tuple[str, ...], ...]
    params_before: tuple[FloatArray, ...]
    params_after: tuple[FloatArray, ...]
    covariance: FloatArray
    sigma0: float
    residuals: tuple[ImageResiduals, ...]
    inlier: NDArray[np.bool_]
    reasons: dict[int, str]
    n_iterations: int
    converged: bool
    components: VarianceComponents | None = None
    n_ties: int = 0
    tie_rms_px: float | None = None

    @property
    def rejected(self) -> NDArray[np.intp]:
        return np.flatnonzero(~self.inlier)

    def image_covariance(self, k: int) -> FloatArray:
        """The covariance of image ``k``'s parameters (its block of ``covariance``)."""
        start = sum(len(p) for p in self.param_names[:k])
        stop = start + len(self.param_names[k])
        return self.covariance[start:stop, start:stop]

    def predict(self, k: int, lon_deg: ArrayLike, lat_deg: ArrayLike, h_m: ArrayLike,
                reference_sigma_m: tuple[float, float, float], noise_px: float = 0.0
                ) -> PredictedAccuracy:
        """Predicted RMS (col, row; px) of check points at these ground points in image ``k``:
        the parameters' covariance propagated through the model's partial derivatives there,
        the reference's registration error (``reference_sigma_m``: east, north, up) through
        the ground's, the model's own error the GCP residuals show (their part smooth across
        the image) and the check points' own measurement noise ``noise_px``."""
        model, res = self.models[k], self.residuals[k]
        return PredictedAccuracy.at(model.jacobian(lon_deg, lat_deg, h_m),
                                    self.image_covariance(k),
                                    ground_jacobian(model, lon_deg, lat_deg, h_m),
                                    reference_sigma_m,
                                    (res.unmodelled_col_px, res.unmodelled_row_px), noise_px)

    def predict_over_image(self, k: int, size: tuple[int, int], heights_m: ArrayLike,
                           reference_sigma_m: tuple[float, float, float], n_side: int = 9
                           ) -> PredictedAccuracy:
        """:meth:`predict` over a regular ``n_side`` x ``n_side`` grid of image ``k``'s pixels
        (``size``: cols, rows) at each of ``heights_m``: what error-free check points spread
        evenly over the image at those heights would show."""
        c, r = image_grid(size[0], size[1], n_side)
        model = self.models[k]
        lon, lat, h = [], [], []
        for hk in np.asarray(heights_m, dtype=np.float64).ravel():
            lo, la = model.localize(c, r, np.full(c.shape, hk))
            lon.append(lo)
            lat.append(la)
            h.append(np.full(c.shape, hk))
        return self.predict(k, np.concatenate(lon), np.concatenate(lat), np.concatenate(h),
                            reference_sigma_m)

    def sigmas(self) -> tuple[FloatArray, ...]:
        """Standard deviation of each image's parameters."""
        sd = np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))
        out, k = [], 0
        for names in self.param_names:
            out.append(sd[k:k + len(names)])
            k += len(names)
        return tuple(out)

    def to_dict(self) -> dict[str, Any]:
        return {
            "images": {
                n: {"param_names": list(pn), "params_before": pb.tolist(),
                    "params_after": pa.tolist(), "sigmas": s.tolist(), **r.to_dict()}
                for n, pn, pb, pa, s, r in zip(self.names, self.param_names, self.params_before,
                                               self.params_after, self.sigmas(), self.residuals,
                                               strict=True)},
            "sigma0": self.sigma0, "n_gcps": int(self.inlier.sum()),
            "rejected": [{"index": int(i), "reason": self.reasons[int(i)]}
                         for i in self.rejected],
            "n_iterations": self.n_iterations, "converged": self.converged,
            "tie_points": ({"n": self.n_ties, "rms_px": self.tie_rms_px} if self.n_ties
                           else None),
            "variance_components": (self.components.to_dict() if self.components is not None
                                    else None),
        }


def observation_sigmas_px(models: Sequence[SensorModel], obs: Observations,
                          matching_sigma_px: float) -> FloatArray:
    """(n_gcp, n_img) expected error of each measurement: matching plus the GCP's ground error
    seen from that image (horizontal over the GSD, vertical times tan(incidence) over it)."""
    out = np.full(np.shape(obs.col), np.nan)
    lon, lat, h = obs.lon_deg, obs.lat_deg, obs.h_m
    g = np.stack(geodetic_to_ecef(lon, lat, h), axis=1)
    for m, model in enumerate(models):
        c, r = model.project(lon, lat, h)
        lon1, lat1 = model.localize(c + 1.0, r, h)
        gsd = np.linalg.norm(np.stack(geodetic_to_ecef(lon1, lat1, h), axis=1) - g, axis=1)
        lon_up, lat_up = model.localize(c, r, h + 100.0)
        shift = np.linalg.norm(np.stack(geodetic_to_ecef(lon_up, lat_up, h), axis=1) - g,
                               axis=1) / 100.0  # tan(incidence)
        out[:, m] = np.sqrt(matching_sigma_px**2 + (obs.sigma_xy_m**2
                                                    + (obs.sigma_h_m * shift) ** 2) / gsd**2)
    return out


def _damped_step(models: list[SensorModel], dp: FloatArray, offsets: NDArray[np.intp],
                 obs: Observations, use: NDArray[np.bool_], max_halvings: int = 10
                 ) -> list[SensorModel]:
    """The models moved by ``dp``, halved while the step sends GCPs behind a camera (a
    Gauss-Newton step far from the solution, e.g. lens terms tried on a poor start). ``use``:
    (n_gcp, n_model), the GCPs each model must still project."""
    for _ in range(max_halvings + 1):
        moved = [model.with_params(model.params + dp[offsets[m]:offsets[m + 1]])
                 for m, model in enumerate(models)]
        try:
            for m, model in enumerate(moved):
                u = use[:, m]
                model.project(obs.lon_deg[u], obs.lat_deg[u], obs.h_m[u])
            return moved
        except (GeometryError, ConvergenceError):  # behind a camera, or no image position
            dp = 0.5 * dp
    raise ConvergenceError("absolute orientation diverged: every step sends GCPs outside the "
                           "images' geometry; the GCPs or the starting models are wrong")


def absolute_orientation(models: Sequence[SensorModel], obs: Observations,
                         names: Sequence[str] | None = None,
                         config: AbsoluteConfig = AbsoluteConfig(),
                         ties: TieObservations | None = None) -> AbsoluteOrientation:
    """Adjust every model's current parameters to the GCPs (robust, with blunder rejection),
    and to the tie points ``ties`` when given (their ground unknowns removed:
    :mod:`core.orientation.ties`), the additional parameters held by their priors
    (``config.prior_terms``).

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
    sizes = [len(m.params) for m in models]
    offsets = np.concatenate([[0], np.cumsum(sizes)])
    before = tuple(m.params.copy() for m in models)
    sigma = observation_sigmas_px(models, obs, config.matching_sigma_px)
    seen = np.isfinite(col) & np.isfinite(row)
    inlier = seen.any(axis=1)
    eqs = Equations(obs, col, row, sigma, seen, offsets, ties,
                     prior_rows(models, obs, config.prior_px, config.prior_terms))
    reasons: dict[int, str] = {}
    iterations, converged = 0, False
    lam = 1e-4
    for _ in range(config.max_rejection_rounds + 1):
        if inlier.sum() < config.min_gcps:
            raise InsufficientDataError(
                f"only {int(inlier.sum())} of {n_gcp} GCPs agree with one another "
                f"({config.min_gcps} needed); the GCPs are unreliable")
        converged = False
        system = eqs.build(models, inlier)
        for _ in range(config.max_iterations):
            iterations += 1
            a, r = system.a, system.r
            w0 = 1.0 / system.q
            w = w0 * huber_weights(np.abs(r) * np.sqrt(w0), config.huber_k)
            scale = np.sqrt(np.sum(a**2 * w[:, None], axis=0))
            scale = np.where(scale > 0, scale, 1.0)
            normal = (a / scale).T @ ((a / scale) * w[:, None])
            grad = (a / scale).T @ (w * r)
            cost = float(np.sum(w * r**2))
            for _ in range(12):  # Levenberg-Marquardt: damp until the step lowers the cost
                damped = normal + lam * np.diag(np.diag(normal))
                dp = np.linalg.lstsq(damped, grad, rcond=1e-12)[0] / scale
                trial = _damped_step(models, dp, offsets, obs, inlier[:, None] & seen)
                trial_system = eqs.build(trial, inlier, jacobian=False)
                if float(np.sum(w * trial_system.r**2)) <= cost * (1.0 + 1e-9):
                    lam = max(lam / 10.0, 1e-9)
                    break
                lam *= 10.0
            else:  # no step lowers the cost: at its minimum
                converged = True
                break
            models[:] = trial
            eqs.accept(trial_system)
            if np.max(np.abs(a @ dp)) < config.tol_px:
                converged = True
                break
            system = eqs.build(models, inlier)
        if not converged:
            raise ConvergenceError(
                f"absolute orientation did not converge in {config.max_iterations} iterations; "
                "the GCPs may be wrong or too few for the parameters")
        worst = np.zeros(n_gcp)
        for m, model in enumerate(models):
            use = seen[:, m]
            pc, pr = model.project(obs.lon_deg[use], obs.lat_deg[use], obs.h_m[use])
            zc = np.abs(col[use, m] - pc) / sigma[use, m]
            zr = np.abs(row[use, m] - pr) / sigma[use, m]
            worst[use] = np.maximum(worst[use], np.maximum(zc, zr))
        s0 = _sigma0(models, obs, col, row, sigma, seen, inlier, offsets[-1])
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
    s0 = _sigma0(models, obs, col, row, sigma, seen, inlier, offsets[-1])
    comps = None
    if config.variance_components:
        models[:], cov, comps = _calibrated(models, eqs, inlier, offsets, obs, seen, config)
        iterations += comps.n_iterations
    else:
        system = eqs.build(models, inlier)
        w0 = 1.0 / system.q
        scale = np.sqrt(np.sum(system.a**2 * w0[:, None], axis=0))
        scale = np.where(scale > 0, scale, 1.0)
        a_s = system.a / scale
        cov = s0**2 * np.linalg.pinv(a_s.T @ (a_s * w0[:, None])) / np.outer(scale, scale)
    residuals = []
    for m, model in enumerate(models):
        use = inlier & seen[:, m]
        pc, pr = model.project(obs.lon_deg[use], obs.lat_deg[use], obs.h_m[use])
        dc, dr = col[use, m] - pc, row[use, m] - pr
        residuals.append(ImageResiduals(
            names[m], int(use.sum()), _rms(dc), _rms(dr), float(np.mean(dc)) if dc.size else 0.0,
            float(np.mean(dr)) if dr.size else 0.0, dc, dr,
            float(np.sqrt(neighbour_covariance(col[use, m], row[use, m], dc))),
            float(np.sqrt(neighbour_covariance(col[use, m], row[use, m], dr)))))
    n_ties, tie_rms = 0, None
    if ties is not None and ties.n:
        final = eqs.build(models, inlier, jacobian=False)
        n_ties = ties.n
        tie_rms = _rms(final.r[final.group == 2]) * ties.sigma_px
    return AbsoluteOrientation(
        models=tuple(models), names=names, param_names=tuple(m.param_names for m in models),
        params_before=before, params_after=tuple(m.params.copy() for m in models),
        covariance=cov, sigma0=s0, residuals=tuple(residuals), inlier=inlier, reasons=reasons,
        n_iterations=iterations, converged=converged, components=comps, n_ties=n_ties,
        tie_rms_px=tie_rms)


def _calibrated(models: list[SensorModel], eqs: Equations, inlier: NDArray[np.bool_],
                offsets: NDArray[np.intp], obs: Observations, seen: NDArray[np.bool_],
                config: AbsoluteConfig) -> tuple[list[SensorModel], FloatArray,
                                                  VarianceComponents]:
    """The models re-adjusted on the GCPs kept (and the tie points and priors) with their
    sigmas calibrated by variance components: GCP columns and rows apart when the F test
    separates them, else one factor; the tie points their own; the priors fixed. The covariance
    under those components, and the components."""
    use = inlier[:, None] & seen

    # the groups there are rows of: GCP columns and rows always, tie points and priors if given
    present = [0, 1] + ([2] if eqs.ties is not None and eqs.ties.n else []) + (
        [3] if eqs.prior.shape[0] else [])

    def solve(split: bool) -> tuple[list[SensorModel], FloatArray, VarianceComponents]:
        moved, factors, n_it = list(models), None, 0
        kept = [k for k in present if split or k != 1]  # one GCP group: rows join columns
        names = tuple(("gcp_col" if split else "gcp") if k == 0 else GROUPS[k] for k in kept)
        lookup = np.zeros(len(GROUPS), dtype=np.intp)
        lookup[kept] = np.arange(len(kept))
        if not split:
            lookup[1] = 0

        def grouped(g: NDArray[np.intp]) -> NDArray[np.intp]:
            return lookup[g]

        for _ in range(config.max_iterations):
            sys_ = eqs.build(moved, inlier)
            sol = solve_with_components(sys_.a, sys_.r, sys_.q, grouped(sys_.group), names,
                                        factors, fixed=("prior",))
            factors, n_it = sol.components.factors, n_it + sol.components.n_iterations
            moved = _damped_step(moved, sol.dx, offsets, obs, use)
            eqs.accept(sys_)
            if np.max(np.abs(sys_.a @ sol.dx)) < config.tol_px:
                break
        sys_ = eqs.build(moved, inlier)
        sol = solve_with_components(sys_.a, sys_.r, sys_.q, grouped(sys_.group), names, factors,
                                    fixed=("prior",))
        return moved, sol.covariance, replace(sol.components, n_iterations=n_it)

    split = solve(True)
    c = split[2]
    if components_differ(c, 0, 1, config.split_alpha):
        return split[0], split[1], replace(
            c, split=f"columns and rows apart: factors {c.factors[0]:.3g} and "
                     f"{c.factors[1]:.3g} differ (F test at {config.split_alpha:g})")
    one = solve(False)
    return one[0], one[1], replace(
        one[2], split=f"one factor: columns {c.factors[0]:.3g} and rows {c.factors[1]:.3g} "
                      f"alike (F test at {config.split_alpha:g})")


def _rms(v: FloatArray) -> float:
    return float(np.sqrt(np.mean(v**2))) if v.size else float("nan")


def _sigma0(models: Sequence[SensorModel], obs: Observations, col: FloatArray, row: FloatArray,
            sigma: FloatArray, seen: NDArray[np.bool_], inlier: NDArray[np.bool_],
            n_params: int) -> float:
    """Robust a-posteriori sigma of unit weight over the kept GCPs."""
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


# ------------------------------------------------- the GCPs' errors as the residuals show them


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
    lon, lat, h = obs.lon_deg[use], obs.lat_deg[use], obs.h_m[use]
    col, row = np.asarray(obs.col)[use], np.asarray(obs.row)[use]
    sub = Observations(lon, lat, h, col, row, obs.sigma_xy_m[use], obs.sigma_h_m[use])
    models = adj.models
    ground = np.stack([ground_jacobian(m, lon, lat, h) for m in models], axis=1)
    v = np.empty(col.shape + (2,))
    jac = np.zeros(col.shape + (2, adj.covariance.shape[0]))
    start = 0
    for k, model in enumerate(models):
        pc, pr = model.project(lon, lat, h)
        v[:, k, 0], v[:, k, 1] = col[:, k] - pc, row[:, k] - pr
        stop = start + len(adj.param_names[k])
        jac[:, k, :, start:stop] = model.jacobian(lon, lat, h)
        start = stop
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
    if ties is not None and ties.n >= 3 and ties.n_images == len(models):
        tie_ground, tie_v = tie_residuals(models, ties)
        mu2 += along_track_covariance(tie_ground, tie_v, ties.row)
    mu = float(np.sqrt(mu2))
    residuals = tuple(replace(r, unmodelled_col_px=mu, unmodelled_row_px=mu)
                      for r in adj.residuals)
    return replace(adj, covariance=cov, residuals=residuals), error


# ------------------------------------------------------------------------- check points


@dataclass(frozen=True)
class CheckPointStats:
    """The paper's Table 2 for one image: residuals (measured - projected, px) of independent
    check points in P (col) and L (row); beside the measured RMS, the RMS the adjustment
    predicts at those points (:class:`~core.orientation.uncertainty.PredictedAccuracy`), when
    one was made."""

    name: str
    n: int
    min_col_px: float
    max_col_px: float
    mean_col_px: float
    std_col_px: float
    rms_col_px: float
    min_row_px: float
    max_row_px: float
    mean_row_px: float
    std_row_px: float
    rms_row_px: float
    predicted_rms_col_px: float | None = None
    predicted_rms_row_px: float | None = None

    def to_dict(self) -> dict[str, Any]:
        """The figures (the predicted RMS only when there is one)."""
        return {k: v for k, v in vars(self).items()
                if v is not None or not k.startswith("predicted_")}


def check_point_stats(model: SensorModel, lon_deg: ArrayLike, lat_deg: ArrayLike,
                      h_m: ArrayLike, col: ArrayLike, row: ArrayLike,
                      name: str = "image") -> CheckPointStats:
    """Min, max, mean, std and RMS of the check points' residuals in one image."""
    pc, pr = model.project(lon_deg, lat_deg, h_m)
    dc = np.asarray(col, dtype=np.float64) - pc
    dr = np.asarray(row, dtype=np.float64) - pr
    if dc.size == 0:
        raise InsufficientDataError(f"no check point in image {name}")

    def five(v: FloatArray) -> tuple[float, ...]:
        return (float(v.min()), float(v.max()), float(v.mean()), float(v.std()), _rms(v))

    return CheckPointStats(name, int(dc.size), *five(dc), *five(dr))
