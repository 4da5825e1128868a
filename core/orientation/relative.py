"""Relative orientation: the right model adjusted to the fixed left one from tie points.

Step 1 of the chain (Goncalves 3.1). The observation of a tie point is its y-parallax: the
left pixel's line of sight projects into the right image as an epipolar curve
``E(h) = right.project(left.localize(col_l, row_l, h), h)``; the point's height is the one that
brings ``E`` closest to the matched right pixel, and what is left, across the curve, is the
y-parallax (the rays' miss distance expressed in right-image pixels). Gauss-Newton adjusts
the right model's corrections (through the SensorModel protocol: ``param_names``,
``with_params``, ``jacobian``) to minimise the y-parallaxes, Huber-weighted, then rejects the
points whose y-parallax departs from their neighbours' by over ``reject_k`` robust sigmas and
solves again until none is rejected. A y-parallax the neighbours share is the models' own
error, not a blunder: a lens the delivered models miss puts a pixel or more at the swath's
ends, and a test on the parallax alone rejected them all there (simulated ``hrs``, seed 1:
the outer 600-1000 columns on both sides, so no GCP there and the lens's cubic term
under-estimated by a third, -0.6 px at the east end). The absolute orientation, which can
model that error, takes those points.

Observability. A correction that moves image points along the epipolar curves is a height
change to the tie points and cannot be told from one: tie points see only the across part.
Directions of the parameter space whose image motion is almost all along the epipolar lines
(a generalised eigen-problem: the share of the motion across them below ``min_observable``)
are held at their starting values and reported; :func:`fix_along_epipolar` estimates them
from a reference DEM when one is given.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike, NDArray

from core.errors import ConvergenceError, InputError, InsufficientDataError
from core.geodesy import ARCSEC
from core.robust import RobustAdjustment, huber_weights, nmad
from core.sensors.base import CORRECTION_KINDS, CorrectionKind, SensorModel

FloatArray = NDArray[np.float64]
ARCSEC_PER_RAD = np.degrees(1.0) / ARCSEC
#: tie points whose y-parallaxes tell what a point's neighbourhood shares (the tie-point
#: search keeps about one per 2 km cell: 12 span about 7 km)
NEIGHBOURS = 12


@dataclass(frozen=True)
class RelativeConfig(RobustAdjustment):
    """Settings of :func:`relative_orientation`: the robust adjustment's
    (:class:`~core.robust.RobustAdjustment`, its defaults), then what is adjusted.

    ``corrections``: ``"linear"`` (pushbroom attitude biases and rates, RPC affine: archive
    attitudes drift, by ~2 px over a SPOT scene) or ``"offset"`` (biases only, RPC shift).
    ``huber_k`` is in robust sigmas of the y-parallax, ``reject_k`` of its departure from its
    neighbours' (:func:`local_value`), both never below ``sigma_floor_px``;
    ``min_observable`` is the smallest share of a parameter direction's image motion that must
    lie across the epipolar lines for the tie points to measure it.
    """

    corrections: CorrectionKind = "linear"
    min_points: int = 6
    min_observable: float = 0.02
    sigma_floor_px: float = 0.05
    height_step_m: float = 10.0

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.corrections not in CORRECTION_KINDS:
            raise InputError(f"corrections must be one of {CORRECTION_KINDS}, got "
                             f"{self.corrections!r}")
        if self.min_points < 3 or not 0 < self.min_observable < 1:
            raise InputError("need min_points >= 3 and 0 < min_observable < 1")


@dataclass(frozen=True, eq=False)
class EpipolarFit:
    """Each tie point on its epipolar curve in the right image (arrays of the points).

    ``h_m`` the height whose projection comes closest to the right pixel, ``lon_deg``/``lat_deg``
    the left ray's ground point there, ``parallax_px`` the signed distance across the curve,
    ``along_px`` the distance along it (about 0 once ``h_m`` is solved), ``tangent`` and
    ``normal`` unit vectors (col, row) along and across the curve, ``px_per_m`` how fast the
    curve moves with height.
    """

    h_m: FloatArray
    lon_deg: FloatArray
    lat_deg: FloatArray
    parallax_px: FloatArray
    along_px: FloatArray
    tangent: FloatArray
    normal: FloatArray
    px_per_m: FloatArray


def _curve(left: SensorModel, right: SensorModel, lc: FloatArray, lr: FloatArray,
           h: FloatArray, dh: float) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """E(h) (n, 2), dE/dh (n, 2) by a central difference, and the ground point (lon, lat)."""
    lon, lat = left.localize(np.concatenate([lc, lc, lc]), np.concatenate([lr, lr, lr]),
                             np.concatenate([h, h + dh, h - dh]))
    c, r = right.project(lon, lat, np.concatenate([h, h + dh, h - dh]))
    n = lc.size
    e = np.stack([c[:n], r[:n]], axis=1)
    d = np.stack([c[n:2 * n] - c[2 * n:], r[n:2 * n] - r[2 * n:]], axis=1) / (2 * dh)
    return e, d, lon[:n], lat[:n]


def epipolar_fit(left: SensorModel, right: SensorModel, left_col: ArrayLike,
                 left_row: ArrayLike, right_col: ArrayLike, right_row: ArrayLike,
                 h0_m: ArrayLike, *, dh_m: float = 10.0, max_iter: int = 10,
                 tol_m: float = 1e-3) -> EpipolarFit:
    """Each point's height along its left ray and its y-parallax in the right image."""
    lc, lr, rc, rr = (np.atleast_1d(np.asarray(a, dtype=np.float64))
                      for a in (left_col, left_row, right_col, right_row))
    h = np.broadcast_to(np.asarray(h0_m, dtype=np.float64), lc.shape).copy()
    obs = np.stack([rc, rr], axis=1)
    for _ in range(max_iter):
        e, d, _, _ = _curve(left, right, lc, lr, h, dh_m)
        step = np.einsum("ni,ni->n", d, obs - e) / np.einsum("ni,ni->n", d, d)
        h += step
        if np.max(np.abs(step)) < tol_m:
            break
    e, d, lon, lat = _curve(left, right, lc, lr, h, dh_m)
    speed = np.linalg.norm(d, axis=1)
    if np.any(speed < 1e-9):
        raise InputError("the two images look along the same direction at some tie points "
                         "(no parallax with height): they are not a stereo pair")
    t = d / speed[:, None]
    n = np.stack([-t[:, 1], t[:, 0]], axis=1)
    res = obs - e
    return EpipolarFit(h, lon, lat, np.einsum("ni,ni->n", n, res),
                       np.einsum("ni,ni->n", t, res), t, n, speed)


@dataclass(frozen=True)
class PointAngleStats:
    """The main parameter solved point by point (the paper's Table 1), in ``unit``."""

    name: str
    unit: str
    count: int
    min: float
    max: float
    mean: float
    std: float


@dataclass(frozen=True)
class Unobservable:
    """A direction of the parameter space the tie points cannot measure.

    ``direction`` is a unit vector over the parameters, each scaled by its RMS image motion
    (several such directions form an orthonormal basis of the unobservable span); ``step`` is
    the same direction in the parameters' own units; ``observable_share`` the share of the
    motion across the epipolar lines of the least observable direction of the span.
    """

    direction: dict[str, float]
    step: dict[str, float]
    observable_share: float


@dataclass(frozen=True, eq=False)
class RelativeOrientation:
    """What :func:`relative_orientation` did, with the adjusted right model.

    Parallaxes are in right-image pixels; ``parallax_px`` holds every tie point's y-parallax
    after the adjustment (the rejected ones too), ``inlier`` which were kept.
    """

    param_names: tuple[str, ...]
    param_units: tuple[str, ...]
    params_before: FloatArray
    params_after: FloatArray
    covariance: FloatArray
    sigma_px: float
    parallax_rms_before_px: float
    parallax_rms_after_px: float
    parallax_px: FloatArray
    inlier: NDArray[np.bool_]
    n_iterations: int
    converged: bool
    unobservable: tuple[Unobservable, ...]
    point_angle: PointAngleStats | None
    right_model: SensorModel = field(repr=False)

    @property
    def rejected(self) -> NDArray[np.intp]:
        return np.flatnonzero(~self.inlier)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (the adjusted model goes with the caller, as its own document)."""
        return {
            "param_names": list(self.param_names),
            "param_units": list(self.param_units),
            "params_before": self.params_before.tolist(),
            "params_after": self.params_after.tolist(),
            "covariance": self.covariance.tolist(),
            "sigma_px": self.sigma_px,
            "parallax_rms_before_px": self.parallax_rms_before_px,
            "parallax_rms_after_px": self.parallax_rms_after_px,
            "tie_points": int(self.inlier.sum()),
            "tie_points_rejected": int((~self.inlier).sum()),
            "rejected": [{"index": int(i), "parallax_px": float(self.parallax_px[i])}
                         for i in self.rejected],
            "n_iterations": self.n_iterations,
            "converged": self.converged,
            "unobservable": [vars(u) for u in self.unobservable],
            "point_angle": None if self.point_angle is None else vars(self.point_angle),
        }


def relative_from_dict(d: dict[str, Any], right_model: SensorModel,
                       parallax_px: ArrayLike, inlier: ArrayLike) -> RelativeOrientation:
    """Inverse of :meth:`RelativeOrientation.to_dict`, with the adjusted model and the
    per-point arrays (written beside it, in the tie-point file)."""
    try:
        pa = d["point_angle"]
        return RelativeOrientation(
            param_names=tuple(d["param_names"]), param_units=tuple(d["param_units"]),
            params_before=np.asarray(d["params_before"], dtype=np.float64),
            params_after=np.asarray(d["params_after"], dtype=np.float64),
            covariance=np.asarray(d["covariance"], dtype=np.float64),
            sigma_px=float(d["sigma_px"]),
            parallax_rms_before_px=float(d["parallax_rms_before_px"]),
            parallax_rms_after_px=float(d["parallax_rms_after_px"]),
            parallax_px=np.asarray(parallax_px, dtype=np.float64),
            inlier=np.asarray(inlier, dtype=bool), n_iterations=int(d["n_iterations"]),
            converged=bool(d["converged"]),
            unobservable=tuple(Unobservable(**u) for u in d["unobservable"]),
            point_angle=None if pa is None else PointAngleStats(**pa), right_model=right_model)
    except (KeyError, TypeError) as exc:
        raise InputError(f"relative orientation record lacks {exc}; give the 'adjustment' of "
                         "a rel.json") from exc


def _robust_sigma(y: FloatArray, floor: float) -> float:
    return max(nmad(y), floor)


def local_value(col: ArrayLike, row: ArrayLike, y: ArrayLike, use: ArrayLike,
                k: int = NEIGHBOURS, floor: float = RelativeConfig.sigma_floor_px
                ) -> FloatArray:
    """Per point, what ``y`` is there by its ``k`` nearest other points among ``use`` (image
    position ``col``, ``row``): a plane fitted to their values, less those beyond 3 robust
    sigmas (at least ``floor``) of their median, taken at the point, so a point at the image's
    edge, whose neighbours all lie inward, is compared with the trend they show and not with
    their median (on a cubic of 2 px at the ends that differs by 0.4 px); the median where the
    plane is undetermined. 0 everywhere with no more than ``k`` such points."""
    from scipy.spatial import cKDTree

    y = np.asarray(y, dtype=np.float64)
    idx = np.flatnonzero(np.asarray(use, dtype=bool))
    if idx.size <= k:
        return np.zeros_like(y)
    pos = np.column_stack([np.asarray(col, np.float64), np.asarray(row, np.float64)])
    _, nn = cKDTree(pos[idx]).query(pos, k=k + 1)
    nb = idx[nn]  # (n, k + 1): the point itself first when it is among ``use``
    own = nb == np.arange(y.size)[:, None]
    keep = np.where(own.any(axis=1, keepdims=True), ~own, np.arange(k + 1) < k)
    nb = nb[keep].reshape(y.size, k)
    yn = y[nb]
    med = np.median(yn, axis=1)
    w = (np.abs(yn - med[:, None]) <= 3.0 * max(nmad(yn - med[:, None]), floor)).astype(float)
    d = pos[nb] - pos[:, None, :]  # (n, k, 2)
    scale = np.maximum(np.sqrt(np.mean(np.sum(d**2, axis=2), axis=1)), 1e-9)[:, None, None]
    a = np.concatenate([np.ones(yn.shape + (1,)), d / scale], axis=2)  # (n, k, 3)
    n_mat = np.einsum("nk,nki,nkj->nij", w, a, a)
    rhs = np.einsum("nk,nki,nk->ni", w, a, yn)
    ok = np.linalg.cond(n_mat) < 1e6
    out = med.copy()
    out[ok] = np.linalg.solve(n_mat[ok], rhs[ok][..., None])[:, 0, 0]
    return out


def _subspace_solve(a: FloatArray, j: FloatArray, w: FloatArray, y: FloatArray,
                    min_share: float) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Weighted least squares of ``y ~ a dp`` within the observable directions.

    ``a`` (n, p): d(parallax)/dp; ``j`` (n, 2, p): the full image motion. Parameters are
    scaled by their RMS image motion; the generalised eigen-problem
    ``(a' W a) v = s (sum w J'J) v`` gives each direction's share s of motion across the
    epipolar lines. Returns dp, an orthonormal basis (columns, in the scaled parameters) of the
    directions whose share is below ``min_share``, their shares, and the pseudo-inverse normal
    matrix of the observable part (parameter units).
    """
    wsum = max(float(w.sum()), 1e-300)
    scale = np.sqrt(np.einsum("n,nip->p", w, j**2) / wsum)
    scale = np.where(scale > 0, scale, 1.0)
    a_s, j_s = a / scale, j / scale
    ma = a_s.T @ (w[:, None] * a_s) / wsum
    mj = np.einsum("n,nip,niq->pq", w, j_s, j_s) / wsum
    mj = mj + 1e-12 * np.eye(mj.shape[0])
    share, vec = scipy.linalg.eigh(ma, mj)  # vec' mj vec = I: 1 px RMS motion each
    share = np.clip(share, 0.0, 1.0)
    obs = share >= min_share
    v = vec[:, obs]
    c = (v.T @ (a_s.T @ (w * y))) / wsum / share[obs]
    normal_inv = (v @ np.diag(1.0 / share[obs]) @ v.T) / wsum
    null = vec[:, ~obs]
    basis = np.linalg.qr(null)[0] if null.shape[1] else null  # orthonormal, scaled space
    return ((v @ c) / scale, basis, share[~obs], normal_inv / np.outer(scale, scale))


def relative_orientation(
    left: SensorModel, right: SensorModel, left_col: ArrayLike, left_row: ArrayLike,
    right_col: ArrayLike, right_row: ArrayLike, h0_m: ArrayLike,
    config: RelativeConfig = RelativeConfig(),
) -> RelativeOrientation:
    """Adjust ``right`` (its corrections of ``config.corrections``) to ``left`` from tie points.

    ``h0_m`` is a first height per point (from a reference DEM) or one for all. Raises
    InsufficientDataError with fewer than ``config.min_points`` points (before or after
    rejection) and ConvergenceError when Gauss-Newton does not settle.
    """
    lc, lr, rc, rr = (np.atleast_1d(np.asarray(a, dtype=np.float64))
                      for a in (left_col, left_row, right_col, right_row))
    n = lc.size
    if not (lr.size == rc.size == rr.size == n):
        raise InputError("tie point arrays differ in length; give one left and one right "
                         "position per point")
    if n < config.min_points:
        raise InsufficientDataError(
            f"{n} tie points for the relative orientation, {config.min_points} needed; the "
            "images may not overlap, be cloudy or lack texture")
    model = right.with_corrections(config.corrections)
    p_before = model.params.copy()
    names, units = model.param_names, model.param_units
    h = np.broadcast_to(np.asarray(h0_m, dtype=np.float64), (n,)).copy()
    inlier = np.ones(n, dtype=bool)
    iterations, converged = 0, False
    for _ in range(config.max_rejection_rounds + 1):
        if inlier.sum() < config.min_points:
            raise InsufficientDataError(
                f"only {int(inlier.sum())} of {n} tie points agree with one another after "
                f"rejecting outliers ({config.min_points} needed); the matches are unreliable")
        converged = False
        for _ in range(config.max_iterations):
            iterations += 1
            fit = epipolar_fit(left, model, lc, lr, rc, rr, h, dh_m=config.height_step_m)
            h = fit.h_m
            jac = model.jacobian(fit.lon_deg, fit.lat_deg, h)
            a = -np.einsum("ni,nip->np", fit.normal, jac)  # d(parallax)/dp
            y = fit.parallax_px
            sigma = _robust_sigma(y[inlier], config.sigma_floor_px)
            w = np.where(inlier, huber_weights(y, config.huber_k * sigma), 0.0)
            dp, vec, share, normal_inv = _subspace_solve(a, jac, w, y, config.min_observable)
            model = model.with_params(model.params - dp)
            if np.max(np.abs(a[inlier] @ dp)) < config.tol_px:
                converged = True
                break
        if not converged:
            raise ConvergenceError(
                f"relative orientation did not converge in {config.max_iterations} iterations; "
                "the tie points may be wrong or the models far from each other")
        fit = epipolar_fit(left, model, lc, lr, rc, rr, h, dh_m=config.height_step_m)
        y = fit.parallax_px
        d = y - local_value(lc, lr, y, inlier, floor=config.sigma_floor_px)
        out = inlier & (np.abs(d) > config.reject_k * _robust_sigma(d[inlier],
                                                                    config.sigma_floor_px))
        if not out.any():
            break
        inlier &= ~out
    before = epipolar_fit(left, right.with_corrections(config.corrections), lc, lr, rc, rr, h,
                          dh_m=config.height_step_m)
    rms = float(np.sqrt(np.mean(y[inlier] ** 2)))
    dof = max(int(inlier.sum()) - int((share >= config.min_observable).sum()), 1)
    s0 = float(np.sqrt(np.sum(w * y**2) / dof))
    motion = np.sqrt(np.einsum("n,nip->p", w, jac**2) / max(float(w.sum()), 1e-300))
    motion = np.where(motion > 0, motion, 1.0)
    unobs = tuple(
        Unobservable(dict(zip(names, map(float, vec[:, k]), strict=True)),
                     dict(zip(names, map(float, vec[:, k] / motion), strict=True)),
                     float(share[k]))
        for k in range(vec.shape[1]))
    return RelativeOrientation(
        param_names=names, param_units=units, params_before=p_before,
        params_after=model.params.copy(), covariance=s0**2 * normal_inv, sigma_px=sigma,
        parallax_rms_before_px=float(np.sqrt(np.mean(before.parallax_px[inlier] ** 2))),
        parallax_rms_after_px=rms, parallax_px=y, inlier=inlier, n_iterations=iterations,
        converged=converged, unobservable=unobs,
        point_angle=_point_angle(a, y, inlier, model.params, names, units, jac, w),
        right_model=model,
    )


def _point_angle(a: FloatArray, y: FloatArray, inlier: NDArray[np.bool_], params: FloatArray,
                 names: tuple[str, ...], units: tuple[str, ...], jac: FloatArray,
                 w: FloatArray) -> PointAngleStats | None:
    """The main parameter solved from each point alone (others held): its value that zeroes
    that point's y-parallax. The main parameter is the offset (a parameter in the unit of the
    first: an attitude bias, an image shift) that moves the points most across the epipolar
    lines. Angles in arcsec, pixels as pixels."""
    if not names:
        return None
    across = np.einsum("n,np->p", w, a**2)
    total = np.einsum("n,nip->p", w, jac**2)
    score = across * across / np.maximum(total, 1e-300)  # effect x observable share
    score[np.array(units) != units[0]] = -1.0
    k = int(np.argmax(score))
    ok = inlier & (np.abs(a[:, k]) > 1e-12)
    values = params[k] - y[ok] / a[ok, k]
    scale, unit = (ARCSEC_PER_RAD, "arcsec") if units[k] == "rad" else (1.0, units[k])
    values = values * scale
    return PointAngleStats(names[k], unit, int(ok.sum()), float(values.min()),
                           float(values.max()), float(values.mean()), float(values.std()))


@dataclass(frozen=True)
class ImageCorrection:
    """How the adjustment moved the right image's projections (pixels, right image).

    ``col_shift_px``, ``row_shift_px``: at the image centre; ``epipolar_direction``: the unit
    (col, row) vector of the epipolar line there; the shift split along and across it;
    ``affine``: the 2x3 matrix ``[[a, b, c], [d, e, f]]`` with ``d_col = a col + b row + c``
    (same for rows) that best fits the shift over the image, and the RMS misfit of that affine.
    """

    col_shift_px: float
    row_shift_px: float
    epipolar_direction: tuple[float, float]
    along_epipolar_px: float
    across_epipolar_px: float
    affine: tuple[tuple[float, float, float], tuple[float, float, float]]
    affine_rms_px: float


def image_correction(left: SensorModel, right_before: SensorModel, right_after: SensorModel,
                     n_cols: int, n_rows: int, h_m: float) -> ImageCorrection:
    """The shift ``right_after`` adds to ``right_before``'s projections at height ``h_m``."""
    c, r = np.meshgrid(np.linspace(0, n_cols - 1, 11), np.linspace(0, n_rows - 1, 11))
    c, r = c.ravel(), r.ravel()
    lon, lat = right_before.localize(c, r, np.full(c.size, h_m))
    c2, r2 = right_after.project(lon, lat, np.full(c.size, h_m))
    design = np.stack([c, r, np.ones_like(c)], axis=1)
    coef, *_ = np.linalg.lstsq(design, np.stack([c2 - c, r2 - r], axis=1), rcond=None)
    misfit = design @ coef - np.stack([c2 - c, r2 - r], axis=1)
    cc, rc = 0.5 * (n_cols - 1), 0.5 * (n_rows - 1)
    lon0, lat0 = right_before.localize(cc, rc, h_m)
    c0, r0 = right_after.project(lon0, lat0, h_m)
    lc, lr = left.project(lon0, lat0, h_m)
    fit = epipolar_fit(left, right_before, lc, lr, cc, rc, h_m)
    t, nrm = fit.tangent[0], fit.normal[0]
    shift = np.array([float(c0) - cc, float(r0) - rc])
    return ImageCorrection(
        col_shift_px=float(shift[0]), row_shift_px=float(shift[1]),
        epipolar_direction=(float(t[0]), float(t[1])),
        along_epipolar_px=float(t @ shift), across_epipolar_px=float(nrm @ shift),
        affine=(tuple(float(v) for v in coef[:, 0]), tuple(float(v) for v in coef[:, 1])),
        affine_rms_px=float(np.sqrt(np.mean(np.sum(misfit**2, axis=1)))),
    )


@dataclass(frozen=True)
class AlongEpipolar:
    """The unobservable part of the relative orientation, set from a reference DEM or not.

    ``observable`` says whether it was estimated (from the tie points' heights against the
    reference); ``shift_px`` is the shift along the epipolar line at the right image centre that
    the estimate added (0 when held), ``sigma_px`` its uncertainty from ``reference_sigma_m`` (the
    reference's error common to the scene) and the height scatter, ``height_offset_m`` the median
    tie-point height minus the reference before the estimate.
    """

    observable: bool
    shift_px: float = 0.0
    sigma_px: float | None = None
    height_offset_m: float | None = None
    reference_sigma_m: float | None = None
    n_points: int = 0


def fix_along_epipolar(
    left: SensorModel, relative: RelativeOrientation, left_col: ArrayLike, left_row: ArrayLike,
    right_col: ArrayLike, right_row: ArrayLike, h_reference_m: ArrayLike, n_cols: int,
    n_rows: int, reference_sigma_m: float = 5.0,
) -> tuple[SensorModel, AlongEpipolar]:
    """Set the directions the tie points cannot see so that the tie points' heights agree with a
    reference DEM (``h_reference_m``: the reference's ellipsoidal height under each tie point,
    NaN where it has none). Robust (Huber) least squares over the inlier tie points."""
    model = relative.right_model
    if not relative.unobservable:
        return model, AlongEpipolar(observable=True)
    lc, lr, rc, rr = (np.atleast_1d(np.asarray(v, dtype=np.float64))
                      for v in (left_col, left_row, right_col, right_row))
    href = np.asarray(h_reference_m, dtype=np.float64)
    fit = epipolar_fit(left, model, lc, lr, rc, rr, np.where(np.isfinite(href), href, 0.0))
    use = relative.inlier & np.isfinite(href)
    if use.sum() < 3:
        return model, AlongEpipolar(observable=False)
    jac = model.jacobian(fit.lon_deg[use], fit.lat_deg[use], fit.h_m[use])
    dirs = np.array([[u.step[n] for n in relative.param_names]
                     for u in relative.unobservable]).T  # (p, k): 1 px of motion each
    # moving the right image along the curve by t px moves the height by -t / (px per m)
    along = np.einsum("ni,nip,pk->nk", fit.tangent[use], jac, dirs)
    c = -along / fit.px_per_m[use, None]
    d = href[use] - fit.h_m[use]
    w = np.ones(d.size)
    alpha = np.zeros(dirs.shape[1])
    for _ in range(10):  # redundant directions barely move the heights: rcond drops them
        alpha, *_ = np.linalg.lstsq(c * w[:, None] ** 0.5, d * w**0.5, rcond=1e-3)
        res = d - c @ alpha
        s = _robust_sigma(res, 0.5)
        w = 1.0 / np.maximum(np.abs(res) / (1.5 * s), 1.0)
    new = model.with_params(model.params + dirs @ alpha)
    h_mid = float(np.median(fit.h_m[use]))
    centre = image_correction(left, model, new, n_cols, n_rows, h_mid)
    # a height error common to the reference moves the result along the epipolar line by that
    # error times the parallax rate; the tie points' scatter adds its standard error
    sigma_m = float(np.hypot(reference_sigma_m, s / np.sqrt(use.sum())))
    return new, AlongEpipolar(
        observable=True, shift_px=centre.along_epipolar_px,
        sigma_px=sigma_m * float(np.median(fit.px_per_m[use])),
        height_offset_m=float(np.median(-d)), reference_sigma_m=reference_sigma_m,
        n_points=int(use.sum()),
    )
