"""Lens self-calibration inside the absolute orientation (Toutin 2006).

The rigorous models' radial symmetric (``k1 r + k3 r^3``) and decentering (``p1, p2``) terms
(:mod:`core.sensors.linear_array`) are added to the adjusted parameters of every pushbroom
image; a term is kept only when its estimate is significant against its own sigma
(``|estimate| > t sigma``), and the adjustment is redone with the significant terms alone.
RPC models have no lens: an affine image correction cannot absorb a distortion, and their
images are left as they are (the report says so).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from core.orientation.absolute import (
    AbsoluteConfig,
    AbsoluteOrientation,
    Observations,
    absolute_orientation,
)
from core.sensors.base import SensorModel
from core.sensors.pushbroom import PushbroomModel

LENS_TERMS = ("k1", "k3", "p1", "p2")


@dataclass(frozen=True, eq=False)
class SelfCalibration:
    """The adjustment without and with lens terms, and what was kept.

    ``significant`` maps each image name to its kept terms with (estimate, sigma);
    ``applied`` says whether any term was kept (then ``with_lens`` is the result to use).
    ``improvement`` gives, per image, the relative drop of the GCP residual RMS in col and row.
    """

    without: AbsoluteOrientation
    with_lens: AbsoluteOrientation | None
    significant: dict[str, dict[str, tuple[float, float]]] = field(default_factory=dict)
    t_threshold: float = 3.0

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
                "significant": {n: {k: {"estimate": e, "sigma": s} for k, (e, s) in terms.items()}
                                for n, terms in self.significant.items()},
                "improvement": self.improvement()}


def _with_terms(model: SensorModel, terms: Sequence[str]) -> SensorModel:
    if not isinstance(model, PushbroomModel) or not terms:
        return model
    return model.with_adjust(tuple(model.param_names) + tuple(t for t in terms
                                                               if t not in model.param_names))


def _t_values(result: AbsoluteOrientation, chosen: dict[str, list[str]]
              ) -> dict[tuple[str, str], tuple[float, float, float]]:
    """(estimate, sigma, |t|) of every chosen lens term in ``result``."""
    out = {}
    for name, pn, pa, sd in zip(result.names, result.param_names, result.params_after,
                                result.sigmas(), strict=True):
        for t in chosen.get(name, []):
            e, s = float(pa[pn.index(t)]), float(sd[pn.index(t)])
            out[(name, t)] = (e, s, abs(e) / s if s > 0 else 0.0)
    return out


def self_calibrate(models: Sequence[SensorModel], obs: Observations, names: Sequence[str],
                   config: AbsoluteConfig = AbsoluteConfig(), terms: Sequence[str] = LENS_TERMS,
                   t_threshold: float = 3.0) -> SelfCalibration:
    """Orient without lens terms, then add them to the pushbroom images one at a time.

    Forward selection: each round tries every (image, term) not yet chosen and adds the one
    with the largest ``|estimate| / sigma`` above ``t_threshold``; after each addition, the
    chosen terms that are no longer significant are dropped. Testing the four terms together
    would drown them: ``k1 r`` and ``k3 r^3`` are nearly collinear over a CCD line, so on
    simulated ``tiny`` a real ``k3`` of -35 had t = -1.8 next to ``k1`` and t = -8.3 alone.
    GCPs rejected without lens terms stay rejected (blunders, not distortion).
    """
    names = tuple(names)
    without = absolute_orientation(models, obs, names, config)
    base = list(without.models)
    candidates = [(n, t) for n, m in zip(names, base, strict=True)
                  if isinstance(m, PushbroomModel) for t in terms]
    if not candidates:
        return SelfCalibration(without, None, {}, t_threshold)
    keep = without.inlier
    trial_obs = Observations(obs.lon_deg[keep], obs.lat_deg[keep], obs.h_m[keep],
                             np.asarray(obs.col)[keep], np.asarray(obs.row)[keep],
                             obs.sigma_xy_m[keep], obs.sigma_h_m[keep])

    def fit(chosen: dict[str, list[str]]) -> AbsoluteOrientation:
        trial = [_with_terms(m, chosen.get(n, [])) for m, n in zip(base, names, strict=True)]
        return absolute_orientation(trial, trial_obs, names, config)

    chosen: dict[str, list[str]] = {}
    dropped: set[tuple[str, str]] = set()  # never tried again: the selection cannot cycle
    best_fit: AbsoluteOrientation | None = None
    while True:
        best: tuple[float, str, str, AbsoluteOrientation] | None = None
        for name, term in candidates:
            if term in chosen.get(name, []) or (name, term) in dropped:
                continue
            trial_terms = {**chosen, name: [*chosen.get(name, []), term]}
            trial = fit(trial_terms)
            t = _t_values(trial, trial_terms)[(name, term)][2]
            if t > t_threshold and (best is None or t > best[0]):
                best = (t, name, term, trial)
        if best is None:
            break
        _, name, term, best_fit = best
        chosen = {**chosen, name: [*chosen.get(name, []), term]}
        while True:  # drop what the new term made redundant
            weak = [k for k, (_, _, t) in _t_values(best_fit, chosen).items() if t <= t_threshold]
            if not weak:
                break
            n_, t_ = min(weak, key=lambda k: _t_values(best_fit, chosen)[k][2])
            dropped.add((n_, t_))
            chosen = {k: [x for x in v if not (k == n_ and x == t_)] for k, v in chosen.items()}
            chosen = {k: v for k, v in chosen.items() if v}
            best_fit = fit(chosen)
        if not chosen:
            break
    if not chosen or best_fit is None:
        return SelfCalibration(without, None, {}, t_threshold)
    significant: dict[str, dict[str, tuple[float, float]]] = {}
    for (name, term), (e, sd, _) in _t_values(best_fit, chosen).items():
        significant.setdefault(name, {})[term] = (e, sd)
    return SelfCalibration(without, best_fit, significant, t_threshold)
