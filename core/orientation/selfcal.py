"""Self-calibration of the cameras inside the absolute orientation (Toutin 2006).

The rigorous models' distortion terms (:mod:`core.sensors.linear_array`) are added to the
adjusted parameters of every pushbroom image. Over a detector line (along the focal plane's
``y``) they are the calibration errors real products carry (:data:`TERMS`, the menu): the
look-angle scale (``k1``: across-track angles scaled about the principal point), the bow of the
line (``p1``: an along-track displacement growing with the square of the distance to the
centre), the cubic radial term (``k3``) and an across-track quadratic (``p2``). Each term is held
by a prior worth a couple of pixels (:class:`~core.orientation.absolute.AbsoluteConfig`), so
one the data cannot determine stays put.

An image's terms are kept when they are significant together (a Wald test) and worth it: they
lower its GCP column RMS, or the tie points' parallax RMS, by ``min_col_drop``. With tie points
(``ties``) the adjustment carries the images' relative geometry, which the reference DEM's
errors never reach: their parallax RMS falling significantly with the terms (an F test) keeps
the terms of every pushbroom image, whatever the GCPs' noise. RPC models have no lens: an
affine image correction cannot absorb a distortion, and their images are left as they are (the
report says so).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from core.errors import ConvergenceError, GeometryError
from core.orientation.absolute import AbsoluteConfig, absolute_orientation
from core.orientation.frames import FramePrior
from core.orientation.gcp_errors import with_gcp_errors_as_they_are
from core.orientation.observations import Observations
from core.orientation.result import AbsoluteOrientation
from core.orientation.ties import TieObservations
from core.sensors.base import SensorModel
from core.sensors.pushbroom import PushbroomModel

LENS_TERMS = ("k1", "k3", "p1", "p2")
#: the GCPs alone decide an image's terms only when there are this many per term at least.
#: Windows of surface matching overlap and share the relative DEM's deformation and the
#: reference's errors, so their GCPs' ground errors are correlated over kilometres, a smooth
#: pattern across the swath that a camera term fits: simulated ``tiny`` at relief x 0.1, 8
#: GCPs (their errors matching their stated 18-20 m, +40 m east at both ends of the swath, 0 in
#: the middle): Wald 51 and 44 against a limit of 16, four terms kept per image, the check
#: points 0.56-0.66 px without them and 0.91-1.41 px with them. The tie points' evidence
#: does not depend on the GCPs and still applies
MIN_GCPS_PER_TERM = 4
TERMS = {"look_scale": "k1", "bow": "p1", "radial_cubic": "k3", "across_quadratic": "p2"}
#: an image's terms are worth keeping when their Wald statistic on the sandwich covariance
#: (the GCPs' correlated ground error in it) exceeds this many per term: the break-even of
#: mean squared error (Mallows' Cp, Akaike), where the error the terms remove (their squared
#: estimate less its variance) exceeds the variance their estimation adds
WORTH_PER_TERM = 2.0


@dataclass(frozen=True, eq=False)
class SelfCalibration:
    """The adjustment without and with lens terms, and what was kept.

    ``significant`` maps each image name to its kept terms with (estimate, sigma);
    ``applied`` says whether any term was kept (then ``with_lens`` is the result to use).
    ``improvement`` gives, per image, the relative drop of the GCP residual RMS in col and row.
    ``decision``: why, in one line (the evidence that kept the terms, or why none was kept).
    """

    without: AbsoluteOrientation
    with_lens: AbsoluteOrientation | None
    significant: dict[str, dict[str, tuple[float, float]]] = field(default_factory=dict)
    t_threshold: float = 3.0
    wald: dict[str, float] = field(default_factory=dict)
    wald_limit: float = float("nan")
    ties: dict[str, float] = field(default_factory=dict)
    decision: str = ""
    wald_correlated: dict[str, float] = field(default_factory=dict)
    wald_correlated_limit: float = float("nan")

    @property
    def applied(self) -> bool:
        return self.with_lens is not None

    @property
    def result(self) -> AbsoluteOrientation:
        return self.with_lens if self.with_lens is not None else self.without

    @property
    def inlier(self) -> np.ndarray:
        """The GCPs kept, over the GCPs given (the lens adjustment ran on those kept without
        lens terms)."""
        if self.with_lens is None:
            return self.without.inlier
        keep = np.flatnonzero(self.without.inlier)
        out = np.zeros_like(self.without.inlier)
        out[keep[self.with_lens.inlier]] = True
        return out

    @property
    def reasons(self) -> dict[int, str]:
        """Why each GCP was rejected, indexed over the GCPs given."""
        out = dict(self.without.reasons)
        if self.with_lens is not None:
            keep = np.flatnonzero(self.without.inlier)
            out.update({int(keep[i]): r for i, r in self.with_lens.reasons.items()})
        return out

    def improvement(self) -> dict[str, dict[str, float]]:
        if self.with_lens is None:
            return {}
        out = {}
        for a, b in zip(self.without.residuals, self.with_lens.residuals, strict=True):
            out[a.name] = {
                "rms_col_px_without": a.rms_col_px, "rms_col_px_with": b.rms_col_px,
                "rms_row_px_without": a.rms_row_px, "rms_row_px_with": b.rms_row_px,
                "col_drop": 1.0 - b.rms_col_px / a.rms_col_px if a.rms_col_px else 0.0,
                "row_drop": 1.0 - b.rms_row_px / a.rms_row_px if a.rms_row_px else 0.0,
            }
        return out

    def to_dict(self) -> dict[str, Any]:
        return {"applied": self.applied, "t_threshold": self.t_threshold,
                "significant": {n: {k: {"estimate": e, "sigma": s,
                                        "term": next((t for t, v in TERMS.items() if v == k), k)}
                                    for k, (e, s) in terms.items()}
                                for n, terms in self.significant.items()},
                "wald": self.wald, "wald_limit": self.wald_limit,
                "wald_correlated": self.wald_correlated,
                "wald_correlated_limit": self.wald_correlated_limit,
                "tie_points": self.ties or None,
                "improvement": self.improvement(), "decision": self.decision}


def _with_terms(model: SensorModel, terms: Sequence[str]) -> SensorModel:
    if not isinstance(model, PushbroomModel) or not terms:
        return model
    return model.with_adjust(tuple(model.param_names) + tuple(t for t in terms
                                                               if t not in model.param_names))


def _wald(result: AbsoluteOrientation, name: str, terms: Sequence[str]) -> float:
    """Wald statistic ``theta' C^-1 theta`` of image ``name``'s lens terms in ``result``
    (chi-square with ``len(terms)`` degrees of freedom when the terms are zero)."""
    k = result.names.index(name)
    start = sum(len(p) for p in result.param_names[:k])
    pn = result.param_names[k]
    idx = np.array([start + pn.index(t) for t in terms])
    theta = result.params_after[k][[pn.index(t) for t in terms]]
    cov = result.covariance[np.ix_(idx, idx)]
    try:
        return float(theta @ np.linalg.solve(cov, theta))
    except np.linalg.LinAlgError:
        return float(theta @ np.linalg.pinv(cov) @ theta)


def self_calibrate(models: Sequence[SensorModel], obs: Observations, names: Sequence[str],
                   config: AbsoluteConfig = AbsoluteConfig(), terms: Sequence[str] = LENS_TERMS,
                   t_threshold: float = 3.0, min_col_drop: float = 0.15,
                   ties: TieObservations | None = None,
                   frames: Sequence[FramePrior] | None = None) -> SelfCalibration:
    """Orient without lens terms, then with ``terms`` on every pushbroom image; keep an
    image's terms when they are significant together and worth it, and orient again with
    those.

    The test is on the block of an image's terms against their covariance (Wald: chi-square
    with one degree of freedom per term, at the two-sided probability of ``t_threshold``
    sigmas, 0.27 % for 3): one term at a time would drown them, ``k1 r`` and ``k3 r^3`` being
    nearly collinear over a CCD line (simulated ``tiny``: a real ``k3`` of -35 had t = -1.8
    next to ``k1``, t = -8.3 alone). Worth it: the terms lower the image's column RMS at the
    GCPs by ``min_col_drop`` at least. With some 200 GCPs a statistical test alone finds
    "significant" lens terms in any small systematic error: on a simulated ``spot`` pair without
    distortion they passed the test and lowered the column RMS by 6-7 %; real distortion
    (``--lens``, 1.5 px at the CCD ends) lowered it by 39-58 % (``spot``, ``tiny``). GCPs
    rejected without lens terms stay rejected (blunders, not distortion); with fewer than
    :data:`MIN_GCPS_PER_TERM` per term they decide nothing (the Wald statistics are still
    reported).

    Worth it also means beyond the GCPs' correlated ground error: surface-matching GCPs share
    the relative DEM's and the reference's errors, a smooth pattern across the swath that
    ``N^-1`` takes for independent noise averaging out, so its Wald test reads a lens into
    it. The terms' Wald statistic on their covariance with that error in it (the sandwich,
    :func:`~core.orientation.absolute.with_gcp_errors_as_they_are`) must exceed
    :data:`WORTH_PER_TERM` per term, where the error they remove exceeds the error their
    estimation adds. Not a 3-sigma test there: a lens left out costs far more than a term
    kept in vain, and the fitted field is itself uncertain. Simulated ``tiny`` with realistic
    errors and no lens, four places: ``N^-1`` gave Wald 25.2 for one image (limit 16.3), whose
    terms were kept and left its check points 0.18 px off in columns beyond the reference's
    shift, against 0.16 without them; its sandwich Wald is 5.8, and none is kept now. ``make
    demo``'s pair (30 GCPs, a lens of 1.5 px at the CCD's ends) has sandwich Walds of 16.0
    and 12.5: refused at 16.3 its check points' columns were 0.47 / 0.50 px, kept 0.08 / 0.13.
    """
    from scipy.stats import chi2, f, norm

    names = tuple(names)
    without = absolute_orientation(models, obs, names, config, ties, frames)
    trial_models = [_with_terms(m, terms) for m in without.models]
    if all(tm is m for tm, m in zip(trial_models, without.models, strict=True)):
        return SelfCalibration(without, None, {}, t_threshold,
                               decision="no pushbroom image: RPC images take no lens terms")
    keep = without.inlier
    trial_obs = obs.subset(keep)
    try:
        trial = absolute_orientation(trial_models, trial_obs, names, config, ties, frames)
    except (ConvergenceError, GeometryError) as exc:  # terms the GCPs cannot carry: none kept
        return SelfCalibration(without, None, {}, t_threshold, decision=(
            f"none kept: the adjustment with lens terms failed ({exc})"))
    p_two = 2.0 * norm.sf(t_threshold)
    limit = float(chi2.ppf(1.0 - p_two, len(terms)))
    calibrated = [n for n, m in zip(names, trial_models, strict=True)
                  if isinstance(m, PushbroomModel)]
    wald = {n: _wald(trial, n, terms) for n in calibrated}
    # worth it: the terms' covariance with the GCPs' correlated ground error in it (the
    # sandwich), against the error the terms would add
    judged, _ = with_gcp_errors_as_they_are(trial, trial_obs, trial.inlier, config)
    worth = {n: _wald(judged, n, terms) for n in calibrated}
    worth_limit = WORTH_PER_TERM * len(terms)
    enough = keep.sum() >= MIN_GCPS_PER_TERM * len(terms)
    chosen = ([n for n in calibrated if wald[n] > limit and worth[n] > worth_limit]
              if enough else [])
    walds = ", ".join(f"{n} {w:.1f}" for n, w in wald.items())
    worths = ", ".join(f"{n} {w:.1f}" for n, w in worth.items())
    why = (f"GCPs: Wald {walds} against {limit:.1f}, with their correlated error {worths} "
           f"against {worth_limit:.0f}" if enough else
           f"GCPs decide nothing: {int(keep.sum())} kept, {MIN_GCPS_PER_TERM * len(terms)} "
           f"needed ({MIN_GCPS_PER_TERM} per term; Wald {walds} against {limit:.1f})")
    tie_info: dict[str, float] = {}
    tie_evidence = False
    if ties is not None and without.tie_rms_px and trial.tie_rms_px is not None:
        k = len(terms) * len(calibrated)
        dof = max(without.n_ties - k, 1)
        r0, r1 = without.tie_rms_px**2, max(trial.tie_rms_px**2, 1e-30)
        stat = ((r0 - r1) / k) / (r1 / dof)
        tie_info = {"n": float(without.n_ties), "rms_px_without": without.tie_rms_px,
                    "rms_px_trial": trial.tie_rms_px, "f_statistic": float(stat),
                    "f_limit": float(f.ppf(1.0 - p_two, k, dof)),
                    "drop": 1.0 - trial.tie_rms_px / without.tie_rms_px}
        # the tie points' parallax says the cameras need the terms: every pushbroom image's
        tie_evidence = stat > tie_info["f_limit"] and tie_info["drop"] >= min_col_drop
        tie_info["evidence"] = float(tie_evidence)
        why += (f"; tie points' parallax F {stat:.1f} against {tie_info['f_limit']:.1f}, "
                f"{100.0 * tie_info['drop']:.0f} % lower with the terms")
        if tie_evidence:
            chosen = list(calibrated)
    with_lens = None
    while chosen:
        final_models = [_with_terms(m, terms if n in chosen else ())
                        for m, n in zip(without.models, names, strict=True)]
        with_lens = absolute_orientation(final_models, trial_obs, names, config, ties, frames)
        drops = {a.name: 1.0 - b.rms_col_px / a.rms_col_px if a.rms_col_px else 0.0
                 for a, b in zip(without.residuals, with_lens.residuals, strict=True)}
        tie_drop = (1.0 - with_lens.tie_rms_px / without.tie_rms_px
                    if tie_evidence and with_lens.tie_rms_px is not None else 0.0)
        weak = [n for n in chosen if drops[n] < min_col_drop and tie_drop < min_col_drop]
        if not weak:
            break
        chosen.remove(min(weak, key=lambda n: drops[n]))
    if not chosen or with_lens is None:
        if with_lens is not None:
            verdict = ("none kept: they lowered no image's column RMS by "
                       f"{100.0 * min_col_drop:.0f} %")
        elif enough and any(wald[n] > limit for n in calibrated):
            verdict = "none worth it beyond the GCPs' correlated error"
        else:
            verdict = "none significant"
        return SelfCalibration(without, None, {}, t_threshold, wald, limit, tie_info,
                               f"{verdict} ({why})", worth, worth_limit)
    if with_lens.tie_rms_px is not None:
        tie_info["rms_px_with"] = with_lens.tie_rms_px
    significant: dict[str, dict[str, tuple[float, float]]] = {}
    for name, pn, pa, sd in zip(names, with_lens.param_names, with_lens.params_after,
                                with_lens.sigmas(), strict=True):
        if name in chosen:
            significant[name] = {t: (float(pa[pn.index(t)]), float(sd[pn.index(t)]))
                                 for t in terms}
    return SelfCalibration(without, with_lens, significant, t_threshold, wald, limit, tie_info,
                           f"kept in {', '.join(chosen)} ({why})", worth, worth_limit)
