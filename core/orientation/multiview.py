"""Joint relative orientation of N images: one image fixed, every other image's corrections
adjusted at once to the tie points of every overlapping pair, the tie points' ground eliminated
point by point.

A tie point (a *track*) is seen in two or more of the images. Its ground lies on the line of
sight of one of them, its *source* (the fixed image when it sees the point, else the first that
does): ``G(h) = source.localize(col, row, h)``, whose projections into the other views (its
*targets*) are the epipolar curves ``E_j(h)``. The height ``h`` that brings the curves closest
to the measured pixels, together (least squares over the targets), eliminates the point's
ground; of the ``2 k`` residuals left in its ``k`` targets, one combination moves with ``h``
and is spent on it, the other ``2 k - 1`` are the point's equations on the corrections:

- ``k`` y-parallaxes, one per target, the residual across its epipolar curve (a stereo pair's
  observation, :mod:`core.orientation.relative`);
- ``k - 1`` along-curve equations: the residuals along the curves, in the combinations that a
  change of ``h`` does not move. They say that the heights each view gives the point agree:
  the pairs of a triplet whose rays all lie in the orbit's plane see their along-track
  disagreement here and nowhere else (no y-parallax can show it), so each pair's DSM on its own
  sits at its own height (the Pleiades Marseille triplet: 5 m between two of its pairs).

With ``k = 1`` (a stereo pair) this is exactly :func:`core.orientation.relative.
relative_orientation`, which calls it. The equations are whitened by one robust sigma (pixels),
Huber-weighted, solved by Gauss-Newton in the parameter directions the tie points observe
(:func:`core.orientation.relative._subspace_solve`: for N images the common height of them all,
and its tilts, stays unobservable and is held or set from a reference DEM,
:func:`fix_along_joint`), then tracks whose equations depart from their neighbours' are
rejected and the solve repeated.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from itertools import combinations

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike, NDArray

from core.errors import ConvergenceError, InputError, InsufficientDataError
from core.geodesy import ARCSEC
from core.orientation.epipolar import SIGMA_FLOOR_PX, epipolar_fit, image_correction, local_value
from core.orientation.tracks import (
    GroupFit,
    TrackGroup,
    Tracks,
    equations_of,
    fit_group,
    motion,
    track_groups,
)
from core.robust import RobustAdjustment, huber_weights, nmad
from core.sensors.base import CORRECTION_KINDS, CorrectionKind, SensorModel

FloatArray = NDArray[np.float64]
ARCSEC_PER_RAD = np.degrees(1.0) / ARCSEC


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
    sigma_floor_px: float = SIGMA_FLOOR_PX
    height_step_m: float = 10.0

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.corrections not in CORRECTION_KINDS:
            raise InputError(f"corrections must be one of {CORRECTION_KINDS}, got "
                             f"{self.corrections!r}")
        if self.min_points < 3 or not 0 < self.min_observable < 1:
            raise InputError("need min_points >= 3 and 0 < min_observable < 1")


DEFAULT_CONFIG = RelativeConfig()


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


@dataclass(frozen=True)
class ViewPairFit:
    """The y-parallax (pixels of image ``images[1]``, the ray from ``images[0]``) of the
    inlier tracks that both images see, before and after the adjustment."""

    images: tuple[int, int]
    n_points: int
    parallax_rms_before_px: float
    parallax_rms_after_px: float


@dataclass(frozen=True, eq=False)
class JointOrientation:
    """What :func:`joint_relative_orientation` did.

    ``models`` the N models (the ``fixed`` one as given, the others adjusted, with their
    corrections); the parameter vector is the adjusted images' parameters one image after the
    other (``param_image`` says whose, ``param_names`` are ``"<image>:<name>"``);
    ``parallax_px`` (n, N) each track's y-parallax in each of its targets after the
    adjustment (NaN elsewhere), ``inlier`` the tracks kept, ``h_m`` their heights; the RMS of
    all equations before and after; ``pairs`` the y-parallax of each pair of images;
    ``point_angle`` per image (None for the fixed one).
    """

    fixed: int
    models: tuple[SensorModel, ...] = field(repr=False)
    param_names: tuple[str, ...]
    param_units: tuple[str, ...]
    param_image: NDArray[np.intp]
    params_before: FloatArray
    params_after: FloatArray
    covariance: FloatArray
    sigma_px: float
    rms_before_px: float
    rms_after_px: float
    parallax_px: FloatArray
    inlier: NDArray[np.bool_]
    h_m: FloatArray
    source: NDArray[np.intp]
    n_iterations: int
    converged: bool
    unobservable: tuple[Unobservable, ...]
    point_angle: tuple[PointAngleStats | None, ...]
    pairs: tuple[ViewPairFit, ...]
    n_equations: int

    @property
    def rejected(self) -> NDArray[np.intp]:
        return np.flatnonzero(~self.inlier)


def _robust_sigma(y: FloatArray, floor: float) -> float:
    return max(nmad(y), floor)


def _subspace_solve(a: FloatArray, w: FloatArray, y: FloatArray, j: FloatArray,
                    wj: FloatArray, min_share: float
                    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Weighted least squares of ``y ~ a dp`` within the observable directions.

    ``a`` (n, p): d(equation)/dp, weights ``w``; ``j`` (m, 2, p): the full image motion of the
    points the equations measure, weights ``wj`` (a stereo pair: one equation, the parallax,
    per point and motion). Parameters are scaled by their RMS image motion; the generalised
    eigen-problem ``(a' W a) v = s (sum wj J'J) v`` gives each direction's share s of motion
    the equations see. Returns dp, an orthonormal basis (columns, in the scaled parameters) of
    the directions whose share is below ``min_share``, their shares, and the pseudo-inverse
    normal matrix of the observable part (parameter units).
    """
    wsum = max(float(w.sum()), 1e-300)
    scale = np.sqrt(np.einsum("n,nip->p", wj, j**2) / max(float(wj.sum()), 1e-300))
    scale = np.where(scale > 0, scale, 1.0)
    a_s, j_s = a / scale, j / scale
    ma = a_s.T @ (w[:, None] * a_s) / wsum
    mj = np.einsum("n,nip,niq->pq", wj, j_s, j_s) / wsum
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


def _point_angle(a: FloatArray, y: FloatArray, inlier: NDArray[np.bool_], params: FloatArray,
                 names: tuple[str, ...], units: tuple[str, ...], jac: FloatArray,
                 w: FloatArray, wj: FloatArray) -> PointAngleStats | None:
    """The main parameter solved from each point alone (others held): its value that zeroes
    that point's equation (``a``, ``y``, weights ``w``; image motion ``jac``, weights ``wj``).
    The main parameter is the offset (a parameter in the unit of the first: an attitude bias,
    an image shift) that moves the points most across the epipolar lines. Angles in arcsec,
    pixels as pixels."""
    if not names:
        return None
    across = np.einsum("n,np->p", w, a**2)
    total = np.einsum("n,nip->p", wj, jac**2)
    score = across * across / np.maximum(total, 1e-300)  # effect x observable share
    score[np.array(units) != units[0]] = -1.0
    k = int(np.argmax(score))
    ok = inlier & (np.abs(a[:, k]) > 1e-12)
    values = params[k] - y[ok] / a[ok, k]
    scale, unit = (ARCSEC_PER_RAD, "arcsec") if units[k] == "rad" else (1.0, units[k])
    values = values * scale
    return PointAngleStats(names[k], unit, int(ok.sum()), float(values.min()),
                           float(values.max()), float(values.mean()), float(values.std()))


@dataclass(frozen=True, eq=False)
class _System:
    """Every group's fit, equations and motions at the current models, stacked."""

    fits: list[GroupFit]
    a: FloatArray  # (n_eq, P)
    y: FloatArray  # (n_eq,)
    point: NDArray[np.intp]  # track of each equation
    kind: NDArray[np.intp]  # group-wise equation index (for the neighbour test)
    j: FloatArray  # (n_motion, 2, P)
    j_point: NDArray[np.intp]  # track of each motion row


def _build(models: Sequence[SensorModel], groups: list[TrackGroup], tracks: Tracks,
           h: FloatArray, offsets: dict[int, tuple[int, int]], n_params: int, dh_m: float,
           jacobian: bool = True) -> _System:
    fits, a, y, point, kind, j, j_point = [], [], [], [], [], [], []
    base = 0
    for g in groups:
        fit = fit_group(models, g, tracks.col, tracks.row, h[g.idx], dh_m=dh_m)
        fits.append(fit)
        n_eq = 2 * g.k - 1
        y.append(fit.y.ravel())
        point.append(np.repeat(g.idx, n_eq))
        kind.append(np.tile(np.arange(n_eq) + base, g.idx.size))
        base += n_eq
        if jacobian:
            m = motion(models, g, fit, offsets, n_params)
            a.append(equations_of(fit, m).reshape(-1, n_params))
            j.append(m.reshape(-1, 2, n_params))
            j_point.append(np.repeat(g.idx, g.k))
    cat = np.concatenate
    return _System(fits, cat(a) if a else np.zeros((0, n_params)), cat(y), cat(point),
                   cat(kind), cat(j) if j else np.zeros((0, 2, n_params)),
                   cat(j_point) if j_point else np.zeros(0, np.intp))


def _heights(groups: list[TrackGroup], fits: list[GroupFit], n: int) -> FloatArray:
    h = np.empty(n)
    for g, fit in zip(groups, fits, strict=True):
        h[g.idx] = fit.h_m
    return h


def _parallax_table(groups: list[TrackGroup], fits: list[GroupFit], n: int, n_images: int
                    ) -> FloatArray:
    out = np.full((n, n_images), np.nan)
    for g, fit in zip(groups, fits, strict=True):
        out[np.ix_(g.idx, list(g.targets))] = fit.y[:, :g.k]
    return out


def _reject(sys: _System, tracks: Tracks, source: NDArray[np.intp], inlier: NDArray[np.bool_],
            config: RelativeConfig) -> NDArray[np.bool_]:
    """The inlier tracks one of whose equations departs from what its neighbours' (same
    images, same equation) say there by over ``reject_k`` robust sigmas."""
    out = np.zeros(inlier.size, dtype=bool)
    col = tracks.col[np.arange(tracks.n), source]
    row = tracks.row[np.arange(tracks.n), source]
    for k in np.unique(sys.kind):
        rows = np.flatnonzero(sys.kind == k)
        p = sys.point[rows]
        y = sys.y[rows]
        use = inlier[p]
        d = y - local_value(col[p], row[p], y, use, floor=config.sigma_floor_px)
        bad = use & (np.abs(d) > config.reject_k * _robust_sigma(d[use], config.sigma_floor_px))
        out[p[bad]] = True
    return out


def _offsets(models: Sequence[SensorModel], fixed: int) -> tuple[dict[int, tuple[int, int]],
                                                                  int]:
    offsets, n = {}, 0
    for m, model in enumerate(models):
        if m != fixed:
            offsets[m] = (n, n + len(model.params))
            n += len(model.params)
    return offsets, n


def _with_params(models: Sequence[SensorModel], offsets: dict[int, tuple[int, int]],
                 p: FloatArray) -> list[SensorModel]:
    return [model.with_params(p[offsets[m][0]:offsets[m][1]]) if m in offsets else model
            for m, model in enumerate(models)]


def joint_relative_orientation(models: Sequence[SensorModel], tracks: Tracks,
                               config: RelativeConfig = DEFAULT_CONFIG, fixed: int = 0
                               ) -> JointOrientation:
    """Adjust every model but ``models[fixed]`` (their corrections of ``config.corrections``)
    to the tie points ``tracks`` at once (module docstring).

    Raises InsufficientDataError with fewer than ``config.min_points`` tracks (before or after
    rejection) and ConvergenceError when Gauss-Newton does not settle.
    """
    n_img = len(models)
    if tracks.n_images != n_img or not 0 <= fixed < n_img:
        raise InputError(f"tie points over {tracks.n_images} images for {n_img} models "
                         f"(fixed image {fixed}); give one column per model")
    n = tracks.n
    if n < config.min_points:
        raise InsufficientDataError(
            f"{n} tie points for the relative orientation, {config.min_points} needed; the "
            "images may not overlap, be cloudy or lack texture")
    start = [m if i == fixed else m.with_corrections(config.corrections)
             for i, m in enumerate(models)]
    offsets, n_p = _offsets(start, fixed)
    p0 = np.concatenate([start[m].params for m in offsets]) if offsets else np.zeros(0)
    groups = track_groups(tracks, fixed)
    source = np.empty(n, np.intp)
    for g in groups:
        source[g.idx] = g.source
    cur, p = list(start), p0.copy()
    h = tracks.h0_m.copy()
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
            sys = _build(cur, groups, tracks, h, offsets, n_p, config.height_step_m)
            h = _heights(groups, sys.fits, n)
            use_eq = inlier[sys.point]
            sigma = _robust_sigma(sys.y[use_eq], config.sigma_floor_px)
            w = np.where(use_eq, huber_weights(sys.y, config.huber_k * sigma), 0.0)
            wj = _motion_weights(w, sys)
            dp, vec, share, normal_inv = _subspace_solve(sys.a, w, sys.y, sys.j, wj,
                                                         config.min_observable)
            p = p - dp
            cur = _with_params(cur, offsets, p)
            if np.max(np.abs(sys.a[use_eq] @ dp)) < config.tol_px:
                converged = True
                break
        if not converged:
            raise ConvergenceError(
                f"relative orientation did not converge in {config.max_iterations} iterations; "
                "the tie points may be wrong or the models far from each other")
        final = _build(cur, groups, tracks, h, offsets, n_p, config.height_step_m, False)
        out = _reject(final, tracks, source, inlier, config)
        if not out.any():
            break
        inlier &= ~out
    return _result(start, cur, fixed, groups, tracks, h, inlier, source, sys, final, w, wj,
                   share, vec, normal_inv, p0, p, offsets, iterations, converged, config)


def _motion_weights(w: FloatArray, sys: _System) -> FloatArray:
    """Each motion row's weight: the mean weight of its track's equations."""
    n = int(max(sys.point.max(initial=-1), sys.j_point.max(initial=-1))) + 1
    total = np.bincount(sys.point, weights=w, minlength=n)
    count = np.bincount(sys.point, minlength=n)
    mean = np.where(count > 1, total / np.maximum(count, 1), 0.0)
    single = count == 1
    mean[single] = total[single]  # one equation: its own weight, exactly
    return mean[sys.j_point]


def _result(start: list[SensorModel], cur: list[SensorModel], fixed: int,
            groups: list[TrackGroup], tracks: Tracks, h: FloatArray, inlier: NDArray[np.bool_],
            source: NDArray[np.intp], sys: _System, final: _System, w: FloatArray,
            wj: FloatArray, share: FloatArray, vec: FloatArray, normal_inv: FloatArray,
            p0: FloatArray, p: FloatArray, offsets: dict[int, tuple[int, int]],
            iterations: int, converged: bool, config: RelativeConfig) -> JointOrientation:
    n_p = p.size
    before = _build(start, groups, tracks, h, offsets, n_p, config.height_step_m, False)
    use_eq = inlier[final.point]
    y = final.y
    dof = max(int(use_eq.sum()) - int((share >= config.min_observable).sum()), 1)
    s0 = float(np.sqrt(np.sum(w * y**2) / dof))
    mot = np.sqrt(np.einsum("n,nip->p", wj, sys.j**2) / max(float(wj.sum()), 1e-300))
    mot = np.where(mot > 0, mot, 1.0)
    names = tuple(f"{m}:{name}" for m in offsets for name in cur[m].param_names)
    units = tuple(u for m in offsets for u in cur[m].param_units)
    image = np.array([m for m in offsets for _ in cur[m].param_names], dtype=np.intp)
    unobs = tuple(
        Unobservable(dict(zip(names, map(float, vec[:, k]), strict=True)),
                     dict(zip(names, map(float, vec[:, k] / mot), strict=True)),
                     float(share[k]))
        for k in range(vec.shape[1]))
    angles = []
    for m in range(len(cur)):
        if m not in offsets:
            angles.append(None)
            continue
        cols = slice(*offsets[m])
        angles.append(_point_angle(sys.a[:, cols], y, use_eq, p[cols], cur[m].param_names,
                                   cur[m].param_units, sys.j[:, :, cols], w, wj))
    return JointOrientation(
        fixed=fixed, models=tuple(cur), param_names=names, param_units=units,
        param_image=image, params_before=p0, params_after=p.copy(),
        covariance=s0**2 * normal_inv, sigma_px=_robust_sigma(sys.y[inlier[sys.point]],
                                                              config.sigma_floor_px),
        rms_before_px=float(np.sqrt(np.mean(before.y[use_eq] ** 2))),
        rms_after_px=float(np.sqrt(np.mean(y[use_eq] ** 2))),
        parallax_px=_parallax_table(groups, final.fits, tracks.n, len(cur)), inlier=inlier,
        h_m=h, source=source, n_iterations=iterations, converged=converged, unobservable=unobs,
        point_angle=tuple(angles), pairs=_pair_fits(start, cur, tracks, h, inlier),
        n_equations=int(use_eq.sum()))


def _pair_fits(start: Sequence[SensorModel], cur: Sequence[SensorModel], tracks: Tracks,
               h: FloatArray, inlier: NDArray[np.bool_]) -> tuple[ViewPairFit, ...]:
    """Each pair of images' y-parallax over the inlier tracks both see."""
    seen = tracks.seen
    out = []
    for i, j in combinations(range(len(cur)), 2):
        both = np.flatnonzero(seen[:, i] & seen[:, j] & inlier)
        if both.size == 0:
            continue
        rms = []
        for models in (start, cur):
            try:
                fit = epipolar_fit(models[i], models[j], tracks.col[both, i],
                                   tracks.row[both, i], tracks.col[both, j],
                                   tracks.row[both, j], h[both])
            except InputError:  # no base (one pass's consecutive scenes): no y-parallax
                break
            rms.append(float(np.sqrt(np.mean(fit.parallax_px**2))))
        if len(rms) < 2:
            continue
        out.append(ViewPairFit((i, j), int(both.size), rms[0], rms[1]))
    return tuple(out)


@dataclass(frozen=True)
class JointAlong:
    """The common height of the images (the directions no tie point sees), set from a
    reference DEM or held at the metadata.

    ``observable`` says whether it was estimated; ``shift_px`` per image the shift along its
    epipolar lines with the fixed image, at its centre, that the estimate added (0 for the
    fixed image; empty when held), ``sigma_px`` its uncertainty there from ``sigma_m``: the
    reference's error common to the scene (``reference_sigma_m``) and the tie points' height
    scatter; ``height_offset_m`` the median tie-point height minus the reference before.
    """

    observable: bool
    shift_px: tuple[float, ...] = ()
    sigma_px: tuple[float, ...] = ()
    sigma_m: float | None = None
    height_offset_m: float | None = None
    reference_sigma_m: float | None = None
    n_points: int = 0


def track_heights(models: Sequence[SensorModel], tracks: Tracks, h0_m: ArrayLike,
                  fixed: int = 0) -> FloatArray:
    """Each track's height on its source ray, closest to its targets' pixels under ``models``
    (from ``h0_m``): the tracks' heights once the joint orientation's models have moved
    (:func:`fix_along_joint` moves them along the heights' common direction; the heights
    the adjustment ended with are then off by that move, hundreds of metres on a block of
    delivered models)."""
    h = np.array(h0_m, dtype=np.float64)
    for g in track_groups(tracks, fixed):
        h[g.idx] = fit_group(models, g, tracks.col, tracks.row, h[g.idx]).h_m
    return h


def fix_along_joint(models: Sequence[SensorModel], fixed: int, tracks: Tracks,
                    inlier: ArrayLike, steps: ArrayLike, h_reference_m: ArrayLike,
                    sizes: Sequence[tuple[int, int]], reference_sigma_m: float = 5.0
                    ) -> tuple[tuple[SensorModel, ...], JointAlong]:
    """Set the directions ``steps`` (P, K: 1 px of image motion each, over the adjusted
    images' parameters, :attr:`Unobservable.step`) so that the inlier tracks' heights agree
    with a reference DEM (``h_reference_m``: its ellipsoidal height under each track, NaN
    where it has none). Robust (Huber) least squares; a height change of a track is the
    mean of what its targets' along-curve motions say, weighted by their rates squared."""
    dirs = np.asarray(steps, dtype=np.float64)
    models = tuple(models)
    if dirs.size == 0:
        return models, JointAlong(observable=True)
    offsets, n_p = _offsets(models, fixed)
    href = np.asarray(h_reference_m, dtype=np.float64)
    use = np.asarray(inlier, dtype=bool) & np.isfinite(href)
    if use.sum() < 3:
        return models, JointAlong(observable=False)
    h0 = np.where(np.isfinite(href), href, 0.0)
    c_parts, d_parts, h_parts, speed_of = [], [], [], {m: [] for m in offsets}
    for g in track_groups(tracks, fixed):
        fit = fit_group(models, g, tracks.col, tracks.row, h0[g.idx])
        sel = use[g.idx]
        if not sel.any():
            continue
        sub = GroupFit(*(getattr(fit, k)[sel] for k in GroupFit.__dataclass_fields__))
        m = motion(models, g, sub, offsets, n_p)
        along = np.einsum("nki,nkip,pq->nkq", sub.tangent, m, dirs)
        s2 = sub.speed**2
        share = s2 / np.sum(s2, axis=1, keepdims=True)
        c_parts.append(-np.sum(along / sub.speed[:, :, None] * share[:, :, None], axis=1))
        d_parts.append(href[g.idx][sel] - sub.h_m)
        h_parts.append(sub.h_m)
        for k, j in enumerate(g.targets):
            if j in speed_of and g.source == fixed:
                speed_of[j].append(sub.speed[:, k])
    c, d, h = (np.concatenate(v) for v in (c_parts, d_parts, h_parts))
    w = np.ones(d.size)
    alpha = np.zeros(dirs.shape[1])
    s = 0.5
    for _ in range(10):  # redundant directions barely move the heights: rcond drops them
        alpha, *_ = np.linalg.lstsq(c * w[:, None] ** 0.5, d * w**0.5, rcond=1e-3)
        res = d - c @ alpha
        s = _robust_sigma(res, 0.5)
        w = 1.0 / np.maximum(np.abs(res) / (1.5 * s), 1.0)
    p = np.concatenate([models[m].params for m in offsets])
    new = tuple(_with_params(models, offsets, p + dirs @ alpha))
    h_mid = float(np.median(h))
    # a height error common to the reference moves the result along the epipolar line by that
    # error times the parallax rate; the tie points' scatter adds its standard error
    sigma_m = float(np.hypot(reference_sigma_m, s / np.sqrt(d.size)))
    shift, sigma = [], []
    for m in range(len(models)):
        if m not in offsets:
            shift.append(0.0)
            sigma.append(0.0)
            continue
        shift.append(image_correction(models[fixed], models[m], new[m], *sizes[m],
                                      h_mid).along_epipolar_px)
        rate = np.concatenate(speed_of[m]) if speed_of[m] else np.array([np.nan])
        sigma.append(sigma_m * float(np.median(rate)))
    return new, JointAlong(True, tuple(shift), tuple(sigma), sigma_m, float(np.median(-d)),
                           reference_sigma_m, int(d.size))
