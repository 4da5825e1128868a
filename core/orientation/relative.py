"""Relative orientation of a stereo pair: the right model adjusted to the fixed left one from
tie points (the pair's case of :mod:`core.orientation.multiview`, which orients N images; the
epipolar geometry is :mod:`core.orientation.epipolar`).

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
from numpy.typing import ArrayLike, NDArray

from core.errors import InputError
from core.orientation.epipolar import (  # noqa: F401 (the pair's API, as it always was)
    NEIGHBOURS,
    EpipolarFit,
    ImageCorrection,
    epipolar_fit,
    image_correction,
    local_value,
)
from core.orientation.multiview import (
    DEFAULT_CONFIG,
    PointAngleStats,
    RelativeConfig,
    Tracks,
    Unobservable,
    fix_along_joint,
    joint_relative_orientation,
)
from core.sensors.base import SensorModel

FloatArray = NDArray[np.float64]


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


def relative_orientation(
    left: SensorModel, right: SensorModel, left_col: ArrayLike, left_row: ArrayLike,
    right_col: ArrayLike, right_row: ArrayLike, h0_m: ArrayLike,
    config: RelativeConfig = DEFAULT_CONFIG,
) -> RelativeOrientation:
    """Adjust ``right`` (its corrections of ``config.corrections``) to ``left`` from tie points:
    the stereo pair's case of :func:`core.orientation.multiview.joint_relative_orientation`.

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
    h = np.broadcast_to(np.asarray(h0_m, dtype=np.float64), (n,))
    joint = joint_relative_orientation(
        (left, right), Tracks(np.stack([lc, rc], axis=1), np.stack([lr, rr], axis=1), h),
        config)
    model = joint.models[1]
    names = model.param_names
    return RelativeOrientation(
        param_names=names, param_units=model.param_units, params_before=joint.params_before,
        params_after=joint.params_after, covariance=joint.covariance, sigma_px=joint.sigma_px,
        parallax_rms_before_px=joint.rms_before_px, parallax_rms_after_px=joint.rms_after_px,
        parallax_px=joint.parallax_px[:, 1], inlier=joint.inlier,
        n_iterations=joint.n_iterations, converged=joint.converged,
        unobservable=tuple(Unobservable(*(dict(zip(names, d.values(), strict=True))
                                          for d in (u.direction, u.step)), u.observable_share)
                           for u in joint.unobservable),
        point_angle=joint.point_angle[1], right_model=model,
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
    NaN where it has none): the stereo pair's case of
    :func:`core.orientation.multiview.fix_along_joint`."""
    model = relative.right_model
    if not relative.unobservable:
        return model, AlongEpipolar(observable=True)
    lc, lr, rc, rr = (np.atleast_1d(np.asarray(v, dtype=np.float64))
                      for v in (left_col, left_row, right_col, right_row))
    dirs = np.array([[u.step[n] for n in relative.param_names]
                     for u in relative.unobservable]).T  # (p, k): 1 px of motion each
    tracks = Tracks(np.stack([lc, rc], axis=1), np.stack([lr, rr], axis=1), 0.0)
    models, joint = fix_along_joint((left, model), 0, tracks, relative.inlier, dirs,
                                    h_reference_m, [(n_cols, n_rows)] * 2, reference_sigma_m)
    if not joint.observable:
        return model, AlongEpipolar(observable=False)
    return models[1], AlongEpipolar(
        observable=True, shift_px=joint.shift_px[1], sigma_px=joint.sigma_px[1],
        height_offset_m=joint.height_offset_m, reference_sigma_m=reference_sigma_m,
        n_points=joint.n_points)
