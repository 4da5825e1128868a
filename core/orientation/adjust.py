"""The one estimator of the absolute orientation: any number of images, typed sets of ground
control each in its own frame, tie points, and the steps a configuration chooses.

``adjust(images, control, ties, config) -> Solution``. Each image is one model with its
correction family (``config.corrections``); each control set (SRTM surface-matching windows,
SAR-optical points, a GCP file) brings its GCPs and the prior of its frame
(:mod:`core.orientation.frames`: the set's common registration error, an unknown of the
adjustment); the tie points carry the images' relative geometry. The steps:

1. the adjustment (:func:`~core.orientation.absolute.absolute_orientation`: robust, blunders
   rejected, variance components), with lens self-calibration when ``config.lens``
   (:mod:`core.orientation.selfcal`) and the attitude's along-track profile when
   ``config.along_track`` (:mod:`core.orientation.along_track`);
2. the GCPs' correlated ground error found on its residuals and propagated into the
   parameters' covariance (:func:`~core.orientation.absolute.with_gcp_errors_as_they_are`);
3. where that error is not nil, or where two frames meet, the adjustment once more: each GCP
   weighted with its share of the correlated error
   (:func:`~core.orientation.ground_field.with_correlated_error`), and each frame's prior
   holding what its GCPs may share beyond their producer's statement (:func:`frames_widened`),
   so that the better-known frame wins;
4. the predictions from that one solution: per image and axis, the check-point RMS relative
   to the control's frames and what the frames' registration carries, with their total
   (:meth:`Solution.predict`, :meth:`Solution.predicted_over_images`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.choices import CORRECTIONS, Corrections
from core.errors import InputError
from core.orientation.absolute import AbsoluteConfig, absolute_orientation
from core.orientation.along_track import AlongTrack, estimate_along_track
from core.orientation.checkpoints import CheckPointStats, check_point_stats
from core.orientation.frames import FrameEstimate, FramePrior
from core.orientation.gcp_errors import with_gcp_errors_as_they_are
from core.orientation.ground_field import (
    NO_CORRELATION,
    CorrelatedGroundError,
    with_correlated_error,
)
from core.orientation.observations import Observations
from core.orientation.result import AbsoluteOrientation
from core.orientation.selfcal import SelfCalibration, self_calibrate
from core.orientation.ties import TieObservations
from core.orientation.uncertainty import PredictedAccuracy
from core.points import CheckPointSet, ControlPoint
from core.sensors.base import SensorModel
from core.sensors.pushbroom import PushbroomModel

FloatArray = NDArray[np.float64]
ControlKind = Literal["surface", "sar", "gcp"]
#: the predicted RMS over an image: a regular grid of this many points per side
GRID_SIDE = 9
#: a surface frame's widening takes the fitted correlated field's mean over the windows only
#: when the field rests on this many distance classes (16 windows and more); fewer windows
#: (a flat scene's handful) fit no field to trust: simulated tiny at relief x0.05, 8 windows
#: off by 32 m east in common, fitted 0-8 m over 0.4 km in a synthetic case like it
MIN_FIELD_BINS = 4
#: ... and on this many windows
MIN_FIELD_WINDOWS = 16


@dataclass(frozen=True, eq=False)
class ImageToAdjust:
    """One image of the adjustment: its name, its model as delivered (the corrections of
    ``AdjustConfig.corrections`` are added to it) and its size (cols, rows)."""

    name: str
    model: SensorModel
    size: tuple[int, int]


@dataclass(frozen=True, eq=False)
class ControlSet:
    """One source of ground control: its ``kind``, its GCPs (each measured in one or more of
    the images, by name) and the prior of its frame."""

    kind: ControlKind
    points: tuple[ControlPoint, ...]
    frame: FramePrior

    def __post_init__(self) -> None:
        if self.kind not in ("surface", "sar", "gcp"):
            raise InputError(f"control kind {self.kind!r} unknown; use surface, sar or gcp")


@dataclass(frozen=True)
class AdjustConfig:
    """What :func:`adjust` does: the adjustment's settings (``absolute``), the corrections of
    every image (``linear``: pushbroom attitude biases and rates, RPC affine; ``offset``:
    biases, RPC shift), lens self-calibration (``lens``), the along-track attitude profile
    (``along_track``), the GCPs' correlated ground error (``correlated_ground_error``) and,
    where two frames meet, their priors widened by what their GCPs may share
    (``frames_from_scatter``, :func:`frames_widened`)."""

    absolute: AbsoluteConfig = field(default_factory=AbsoluteConfig)
    corrections: Corrections = "linear"
    lens: bool = False
    along_track: bool = False
    correlated_ground_error: bool = True
    frames_from_scatter: bool = True

    def __post_init__(self) -> None:
        if self.corrections not in CORRECTIONS:
            raise InputError(f"corrections {self.corrections!r} unknown; use "
                             f"{' or '.join(CORRECTIONS)}")


@dataclass(frozen=True, eq=False)
class Solution:
    """The adjusted images and everything the estimator found: the final adjustment (its
    models, covariance over the images' and frames' parameters, residuals), the lens and
    along-track steps, the GCPs kept (over ``gcps``, every set's in order) and why others were
    rejected, the GCPs' correlated ground error, the frames as their priors finally were."""

    names: tuple[str, ...]
    sizes: tuple[tuple[int, int], ...]
    adjustment: AbsoluteOrientation
    self_calibration: SelfCalibration | None
    along_track: AlongTrack | None
    gcps: tuple[ControlPoint, ...]
    kinds: tuple[ControlKind, ...]
    kept: NDArray[np.bool_]
    reasons: dict[int, str]
    ground_error: CorrelatedGroundError
    frames_used: tuple[FramePrior, ...]
    connectivity: Connectivity | None = None

    @property
    def models(self) -> tuple[SensorModel, ...]:
        return self.adjustment.models

    def frames(self) -> tuple[FrameEstimate, ...]:
        return self.adjustment.frames()

    def frame(self, name: str) -> FrameEstimate | None:
        return next((f for f in self.frames() if f.name == name), None)

    def predict(self, k: int, lon_deg: ArrayLike, lat_deg: ArrayLike, h_m: ArrayLike,
                noise_px: float = 0.0) -> PredictedAccuracy:
        """The check-point RMS predicted at ground points in image ``k``: relative to the
        control's frames, the frames' registration, and their total."""
        return self.adjustment.predict(k, lon_deg, lat_deg, h_m, noise_px)

    def predicted_over_images(self) -> dict[str, Any]:
        """report.json's ``absolute.predicted``: per image, the check-point RMS predicted over
        a regular grid of ``GRID_SIDE`` x ``GRID_SIDE`` pixels spanning the image at the
        scene's heights (the 5th, 50th and 95th percentiles of the heights of the GCPs kept),
        with the reference's registration sigma assumed, the GCPs' correlated ground error
        propagated and every frame."""
        h = np.array([p.h_m for p, k in zip(self.gcps, self.kept, strict=True) if k])
        heights = [float(v) for v in np.percentile(h, [5.0, 50.0, 95.0])]
        images = {name: self.adjustment.predict_over_image(k, self.sizes[k], heights,
                                                           GRID_SIDE).to_dict()
                  for k, name in enumerate(self.names)}
        ref = self.frames_used[0].sigma_m if self.frames_used else (0.0, 0.0, 0.0)
        return {"grid_points_per_side": GRID_SIDE, "heights_m": heights,
                "reference_sigma_m": list(ref),
                "correlated_ground_error": self.ground_error.to_dict(),
                "frames": [f.to_dict() for f in self.frames()], "images": images}

    def check_points(self, points: CheckPointSet) -> dict[str, CheckPointStats]:
        """The paper's Table 2 per image at independent check points, with the RMS predicted
        there (in total and its two parts; the check points carry no measurement noise of
        their own, none is added)."""
        out = {}
        for k, (name, model) in enumerate(zip(self.names, self.models, strict=True)):
            stats = check_points_in(model, points, name)
            if stats is None:
                continue
            lon, lat, h = _points_in(points, name)[:3]
            out[name] = stats.with_prediction(self.predict(k, lon, lat, h))
        return out

    def gcp_summary(self) -> dict[str, Any]:
        """GCPs used and rejected (ids and reasons), over the GCPs given."""
        return {"given": len(self.gcps), "used": int(self.kept.sum()),
                "rejected": int((~self.kept).sum()),
                "rejected_ids": [{"id": self.gcps[int(i)].id, "reason": self.reasons[int(i)]}
                                 for i in np.flatnonzero(~self.kept)]}


def _points_in(points: CheckPointSet, name: str) -> tuple[FloatArray, ...]:
    pts = [p for p in points.points if name in p.image_points]
    return tuple(np.array(v, dtype=np.float64) for v in zip(
        *[(p.lon_deg, p.lat_deg, p.h_m, p.image_points[name].col, p.image_points[name].row)
          for p in pts], strict=True)) if pts else ()


def check_points_in(model: SensorModel, points: CheckPointSet, name: str
                    ) -> CheckPointStats | None:
    """The check points' residuals in image ``name`` under ``model`` (None: none there)."""
    arrays = _points_in(points, name)
    return check_point_stats(model, *arrays, name) if arrays else None


@dataclass(frozen=True)
class Connectivity:
    """How a block holds together: the images measuring GCPs, those held only through tie
    points to them, the components of the tie-point graph (images linked by tie points seen
    in both), and each linked couple's number of tie points."""

    with_gcps: tuple[str, ...]
    ties_only: tuple[str, ...]
    components: tuple[tuple[str, ...], ...]
    links: tuple[tuple[str, str, int], ...]

    def to_dict(self) -> dict[str, Any]:
        return {"with_gcps": list(self.with_gcps), "ties_only": list(self.ties_only),
                "components": [list(c) for c in self.components],
                "links": [{"images": [a, b], "tie_points": n} for a, b, n in self.links]}


def connectivity(names: tuple[str, ...], gcps: Sequence[ControlPoint],
                 ties: TieObservations | None) -> Connectivity:
    """The block's :class:`Connectivity`; InputError naming the images neither a GCP nor a
    chain of tie points to an image with GCPs holds (they cannot be oriented)."""
    with_gcps = {n for p in gcps for n in p.image_points}
    links: list[tuple[str, str, int]] = []
    if ties is not None and ties.n:
        seen = ties.seen
        for i in range(len(names)):
            for j in range(i + 1, len(names)):
                k = int(np.sum(seen[:, i] & seen[:, j]))
                if k:
                    links.append((names[i], names[j], k))
    parent = {n: n for n in names}

    def root(n: str) -> str:
        while parent[n] != n:
            n = parent[n]
        return n

    for a, b, _ in links:
        parent[root(a)] = root(b)
    groups: dict[str, list[str]] = {}
    for n in names:
        groups.setdefault(root(n), []).append(n)
    components = tuple(tuple(g) for g in groups.values())
    held = {n for c in components if with_gcps & set(c) for n in c}
    loose = [n for n in names if n not in held]
    if loose:
        raise InputError(f"images {', '.join(loose)} have no GCP and no tie points to an image "
                         "that has one: they cannot be oriented; give tie points between "
                         "overlapping images (gcpfree block finds them) or GCPs in them")
    return Connectivity(tuple(n for n in names if n in with_gcps),
                        tuple(n for n in names if n not in with_gcps), components, tuple(links))


@dataclass(frozen=True, eq=False)
class _Run:
    adj: AbsoluteOrientation
    calib: SelfCalibration | None
    at: AlongTrack | None
    kept: np.ndarray
    reasons: dict[int, str]
    ground_error: CorrelatedGroundError


def _run(models: Sequence[SensorModel], names: tuple[str, ...], obs: Observations,
         frames: Sequence[FramePrior], config: AdjustConfig,
         ties: TieObservations | None) -> _Run:
    """Step 1 and 2 with the GCPs weighted as ``obs`` says and the frames' priors
    ``frames``."""
    cfg = config.absolute
    calib = None
    if config.lens:
        calib = self_calibrate(models, obs, names, cfg, ties=ties, frames=frames)
        adj = calib.result
    else:
        adj = absolute_orientation(models, obs, names, cfg, ties, frames)
    kept = (calib or adj).inlier  # over the GCPs given
    reasons = dict((calib or adj).reasons)
    at = None
    if config.along_track and any(isinstance(m, PushbroomModel) for m in adj.models):
        idx = np.flatnonzero(kept)
        base = adj if adj.inlier.size == idx.size else None
        at = estimate_along_track(adj.models, obs.subset(idx), names, cfg, ties, base=base,
                                  frames=frames)
        adj = at.result
        kept = np.zeros_like(kept)
        kept[idx[adj.inlier]] = True
        reasons.update({int(idx[i]): r for i, r in adj.reasons.items()})
    ground_error = NO_CORRELATION
    if config.correlated_ground_error:
        adj, ground_error = with_gcp_errors_as_they_are(adj, obs, kept, cfg, ties)
    return _Run(adj, calib, at, kept, reasons, ground_error)


def frames_widened(sets: Sequence[ControlSet], frames: Sequence[FramePrior],
                   errors: Mapping[str, CorrelatedGroundError] | None = None
                   ) -> tuple[FramePrior, ...]:
    """Each frame's prior with what its GCPs may share beyond its producer's statement added.
    Surface-matching windows overlap and inherit the relative DEM's deformation and the
    reference's local errors: their errors are correlated across the scene, and their mean is
    off, whatever SRTM's registration, by at least their median stated precision
    (``sigma_xy_m``, ``sigma_h_m``: the bound of an error correlated over the whole scene),
    or by the mean of the correlated error over them where that is larger (``errors``: frame
    name -> the field the first solution's residuals of that set's GCPs alone show;
    ``c_k mean_ij exp(-d_ij / L)`` per axis; taken from :data:`MIN_FIELD_WINDOWS` windows
    over :data:`MIN_FIELD_BINS` distance classes). A residuals' field never sees the part
    common to all windows (the solution absorbs it): over a flat world 23 windows fitted
    0.1 m horizontally while they sat 20 m off in common (the stated 15 m bounds it). SAR points and GCP files state their
    own independent precision and their common error is the frame's (nothing added)."""
    out = list(frames)
    names = [f.name for f in frames]
    for c in sets:
        if c.kind != "surface":
            continue
        k = names.index(c.frame.name)
        sxy = float(np.median([p.sigma_xy_m for p in c.points]))
        sh = float(np.median([p.sigma_h_m for p in c.points]))
        extra = np.array([sxy, sxy, sh])
        why = (f"its {len(c.points)} windows' median precision {sxy:.1f} m horizontal, "
               f"{sh:.1f} m vertical (overlapping windows share their errors)")
        error = (errors or {}).get(c.frame.name, NO_CORRELATION)
        if (any(error.variance_m2) and error.n_bins >= MIN_FIELD_BINS
                and len(c.points) >= MIN_FIELD_WINDOWS):
            field_mean = _field_mean_m(c.points, error)
            if np.any(field_mean > extra):
                why += (f", or more where their correlated error (sigma "
                        f"{'/'.join(f'{np.sqrt(v):.1f}' for v in error.variance_m2)} m over "
                        f"{error.length_m / 1000.0:.1f} km) averages to "
                        f"{'/'.join(f'{v:.1f}' for v in field_mean)} m over them")
            extra = np.maximum(extra, field_mean)
        if out[k].up_of:
            extra[2] = 0.0
        out[k] = out[k].inflated(extra, why)
    return tuple(out)


def _field_mean_m(points: Sequence[ControlPoint], error: CorrelatedGroundError) -> FloatArray:
    """The RMS over ``points`` of the mean of the correlated ``error`` (per axis, m):
    ``sqrt(c_k mean_ij rho(d_ij))``."""
    from core.geodesy import metres_per_degree

    lon = np.array([p.lon_deg for p in points])
    lat = np.array([p.lat_deg for p in points])
    m_lon, m_lat = metres_per_degree(float(np.mean(lat)))
    xy = np.stack([(lon - lon.mean()) * m_lon, (lat - lat.mean()) * m_lat], axis=1)
    d = np.sqrt(np.sum((xy[:, None] - xy[None]) ** 2, axis=2))
    return np.sqrt(np.asarray(error.variance_m2) * float(np.mean(error.correlation(d))))


def adjust(images: Sequence[ImageToAdjust], control: Sequence[ControlSet],
           ties: TieObservations | None = None,
           config: AdjustConfig = AdjustConfig()) -> Solution:
    """Every image adjusted to every control set and the tie points (module docstring)."""
    images = tuple(images)
    names = tuple(i.name for i in images)
    if len(set(names)) != len(names):
        raise InputError(f"image names must be unique, got {names}")
    sets = [c for c in control if c.points]
    if not sets:
        raise InputError("no ground control: give at least one control set with GCPs")
    frames: list[FramePrior] = []
    frame_of: list[int] = []
    gcps: list[ControlPoint] = []
    kinds: list[ControlKind] = []
    for c in sets:
        if c.frame.name not in [f.name for f in frames]:
            frames.append(c.frame)
        f = [p.name for p in frames].index(c.frame.name)
        unknown = {n for p in c.points for n in p.image_points} - set(names)
        if unknown:
            raise InputError(f"{c.kind} GCPs measured in images {sorted(unknown)} that are not "
                             f"adjusted ({', '.join(names)})")
        gcps.extend(c.points)
        frame_of.extend([f] * len(c.points))
        kinds.extend([c.kind] * len(c.points))
    for p in frames:  # a frame sharing another's vertical needs that one present
        if p.up_of is not None and p.up_of not in [q.name for q in frames]:
            frames[frames.index(p)] = replace(p, up_of=None)
    if len(frames) == 1:  # alone, a frame trades with the biases: considered, not estimated
        frames[0] = replace(frames[0], estimated=False)
    links = connectivity(names, gcps, ties)
    models = [i.model.with_corrections(config.corrections)  # type: ignore[attr-defined]
              for i in images]
    obs = Observations.from_control_points(gcps, names, frame_of)
    run = _run(models, names, obs, frames, config, ties)
    used = tuple(frames)
    again = any(run.ground_error.variance_m2)
    if len(frames) > 1 and config.frames_from_scatter:
        fields_ = {f.name: with_gcp_errors_as_they_are(
            run.adj, obs, run.kept & (np.asarray(obs.frame) == k), config.absolute)[1]
            for k, f in enumerate(frames)}
        used = frames_widened(sets, frames, fields_)
        again = True
    if again:  # each GCP weighted with its own share of the correlated error
        xy, h = with_correlated_error(obs.sigma_xy_m, obs.sigma_h_m, run.ground_error)
        run = _run(models, names, obs.with_sigmas(xy, h), used, config, ties)
    return Solution(names, tuple(i.size for i in images), run.adj, run.calib, run.at,
                    tuple(gcps), tuple(kinds), run.kept, run.reasons, run.ground_error, used,
                    links)
