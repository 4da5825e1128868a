"""The attitude's along-track profile: harmonics in time chosen by the data.

Delivered attitude departs from the straight line the adjustment's biases and rates correct by a
few microradians of smooth, non-polynomial motion (SPOT 1-4 DIMAP angular speeds integrated over
a scene: 4-12 microradians peak in pitch, 0.3-1 px in rows). It is estimated here as a cosine
series ``sum_k a_k cos(pi k u)`` on pitch (``u`` = 0..1 over the image's time span,
:data:`core.sensors.pushbroom.ATTITUDE_HARMONICS`) added to each pushbroom image, from the GCPs
and, when given, the tie points (whose parallax carries the two images' profiles against each
other at thousands of places, whatever the reference). Every harmonic is held by the prior of
the additional parameters (their joint effect beyond the biases and rates, ``prior_px`` RMS);
the number of harmonics is the data's choice: the Bayesian information criterion over the
observation groups (GCPs, tie points), each with its own variance, among ``orders``
(0 keeps the straight line). This is the along-track part of MMASTER's jitter correction of
ASTER and of ASP's jitter_solve, on a low-order basis because the observations are hundreds of
GCPs, not a dense DEM difference.

Pitch only by default: it moves the rows, which the tie points' parallax sees across a
cross-track pair; a roll wave moves the columns, which only the GCPs see (the tie points'
column parallax is height), and on the jitter demo scene (28 GCPs) roll harmonics traded with
the columns: right check points 0.33 -> 0.72 px in columns with roll and pitch, 0.32 -> 0.35
with pitch alone, rows 0.41 -> 0.23.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from core.errors import ConvergenceError, GeometryError
from core.orientation.absolute import AbsoluteConfig, absolute_orientation
from core.orientation.frames import FramePrior
from core.orientation.observations import Observations
from core.orientation.result import AbsoluteOrientation
from core.orientation.ties import TieObservations
from core.sensors.base import SensorModel
from core.sensors.pushbroom import ATTITUDE_HARMONICS, PushbroomModel

ORDERS = (0, 3, 6)
AXES = ("pitch",)
N_BINS = 10


def harmonic_names(order: int, axes: Sequence[str] = AXES) -> tuple[str, ...]:
    """The correction names of harmonics 1..``order`` on ``axes``."""
    return tuple(f"{a}_h{k}" for a in axes for k in range(1, order + 1))


def _with_order(model: SensorModel, order: int, axes: Sequence[str]) -> SensorModel:
    if not isinstance(model, PushbroomModel):
        return model
    base = tuple(n for n in model.param_names if n not in ATTITUDE_HARMONICS)
    return model.with_adjust(base + harmonic_names(order, axes))


def _bic(result: AbsoluteOrientation, ties: TieObservations | None, n_added: int) -> float:
    """BIC with one unknown variance per group: ``sum n_g log(RSS_g / n_g) + p log n``."""
    v = np.concatenate([np.concatenate([r.col_px, r.row_px]) for r in result.residuals])
    groups = [(v.size, float(np.sum(v**2)))]
    if ties is not None and result.tie_rms_px is not None and result.n_ties:
        groups.append((ties.n_equations, ties.n_equations * result.tie_rms_px**2))
    n = sum(g[0] for g in groups)
    return float(sum(k * np.log(max(rss / k, 1e-30)) for k, rss in groups)
                 + n_added * np.log(n))


def row_profile(result: AbsoluteOrientation, obs: Observations, inlier: np.ndarray,
                n_rows: Sequence[int], n_bins: int = N_BINS) -> dict[str, Any]:
    """Per image, the GCPs' row residuals (px) averaged in ``n_bins`` bands of image rows:
    bin centres and mean residuals (None in an empty bin), the along-track profile an
    adjustment leaves."""
    out = {}
    for m, res in enumerate(result.residuals):
        use = inlier & np.isfinite(np.asarray(obs.row)[:, m])
        rows = np.asarray(obs.row)[use, m]
        edges = np.linspace(0.0, float(n_rows[m]), n_bins + 1)
        idx = np.clip(np.searchsorted(edges, rows, side="right") - 1, 0, n_bins - 1)
        means = [float(np.mean(res.row_px[idx == b])) if np.any(idx == b) else None
                 for b in range(n_bins)]
        out[res.name] = {"row_centres": (0.5 * (edges[1:] + edges[:-1])).tolist(),
                         "mean_row_residual_px": means}
    return out


@dataclass(frozen=True, eq=False)
class AlongTrack:
    """The orientations tried (by number of harmonics), their BIC, the one chosen and the
    GCPs' row residuals against row without harmonics and with the choice."""

    results: dict[int, AbsoluteOrientation]
    bic: dict[int, float]
    chosen: int
    profile_before: dict[str, Any] = field(default_factory=dict)
    profile_after: dict[str, Any] = field(default_factory=dict)
    axes: tuple[str, ...] = AXES

    @property
    def result(self) -> AbsoluteOrientation:
        return self.results[self.chosen]

    def to_dict(self) -> dict[str, Any]:
        base, best = self.results[0], self.result
        return {
            "axes": list(self.axes), "orders_tried": sorted(self.bic),
            "bic": {str(k): v for k, v in sorted(self.bic.items())},
            "harmonics": self.chosen,
            "rms_row_px_without": {r.name: r.rms_row_px for r in base.residuals},
            "rms_row_px_with": {r.name: r.rms_row_px for r in best.residuals},
            "tie_rms_px_without": base.tie_rms_px, "tie_rms_px_with": best.tie_rms_px,
            "row_profile_without": self.profile_before, "row_profile_with": self.profile_after,
        }


def estimate_along_track(models: Sequence[SensorModel], obs: Observations,
                         names: Sequence[str], config: AbsoluteConfig = AbsoluteConfig(),
                         ties: TieObservations | None = None,
                         orders: Sequence[int] = ORDERS,
                         axes: Sequence[str] = AXES,
                         base: AbsoluteOrientation | None = None,
                         frames: Sequence[FramePrior] | None = None) -> AlongTrack:
    """Orient with 0 and each of ``orders`` harmonics on ``axes`` of every pushbroom image
    (the models' other adjusted parameters kept) and keep the order of least BIC. The GCPs are
    those ``models`` were oriented on (an order that fails to converge is left out); ``base``:
    the orientation without harmonics already made on them (then not made again)."""
    names = tuple(names)
    cfg = replace(config, prior_terms=tuple(config.prior_terms)
                  + tuple(ATTITUDE_HARMONICS))
    results: dict[int, AbsoluteOrientation] = {}
    bic: dict[int, float] = {}
    for order in sorted({0, *orders}):
        trial = [_with_order(m, order, axes) for m in models]
        added = sum(len(t.params) - len(_with_order(m, 0, axes).params)
                    for t, m in zip(trial, models, strict=True))
        if order == 0 and base is not None:
            results[0], bic[0] = base, _bic(base, ties, 0)
            continue
        try:
            res = absolute_orientation(trial, obs, names, cfg if order else config, ties,
                                       frames)
        except (ConvergenceError, GeometryError):
            if order == 0:
                raise
            continue
        results[order] = res
        bic[order] = _bic(res, ties, added)
    chosen = min(bic, key=lambda k: bic[k])
    sizes = [int(getattr(m, "n_rows", 0)) for m in models]
    before = row_profile(results[0], obs, results[0].inlier, sizes)
    after = row_profile(results[chosen], obs, results[chosen].inlier, sizes)
    return AlongTrack(results, bic, chosen, before, after, tuple(axes))
