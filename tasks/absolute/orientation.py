"""Tasks of step 4: the absolute orientation of both images on the simulated GCPs, check points
and the products of ``gcpfree orient`` (oriented models, GCPs, report.json).

The maths is :mod:`core.orientation.absolute` and :mod:`core.orientation.selfcal`; here the
check points are read (the simulator's ``checkpoints.json`` or a CSV), the adjustment run and
its products written atomically.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from prefect import task
from prefect.cache_policies import NO_CACHE

from core.errors import InputError
from core.jsonio import parse_json
from core.orientation.absolute import (
    AbsoluteConfig,
    AbsoluteOrientation,
    Observations,
    absolute_orientation,
    check_point_stats,
    with_gcp_errors_as_they_are,
)
from core.orientation.along_track import AlongTrack, estimate_along_track
from core.orientation.ground_field import (
    NO_CORRELATION,
    CorrelatedGroundError,
    with_correlated_error,
)
from core.orientation.selfcal import SelfCalibration, self_calibrate
from core.orientation.ties import TieObservations
from core.points import (
    CheckPoint,
    CheckPointSet,
    ControlPoint,
    ImagePoint,
    control_points_to_dict,
)
from core.sensors.base import SensorModel
from core.sensors.pushbroom import PushbroomModel
from tasks.absolute.surface_match import TieGround
from tasks.io.rasters import atomic_write_json
from tasks.io.sensors import LoadedModel, sun_to_dict

NAMES = ("left", "right")
CSV_COLUMNS = ("id", "lon_deg", "lat_deg", "h_m", "left_col", "left_row", "right_col",
               "right_row")


def _checkpoints_csv(path: Path) -> CheckPointSet:
    try:
        with path.open(newline="", encoding="utf-8", errors="replace") as f:
            rows = list(csv.DictReader(f))
    except csv.Error as exc:
        raise InputError(f"check point CSV {path} is not a readable CSV ({exc}); give "
                         f"the columns {','.join(CSV_COLUMNS)}") from None
    if not rows or any(c not in rows[0] for c in CSV_COLUMNS):
        raise InputError(f"check point CSV {path} must have the columns {','.join(CSV_COLUMNS)}")
    points = []
    for k, r in enumerate(rows, start=2):
        try:
            points.append(CheckPoint(
                id=int(r["id"]), lon_deg=float(r["lon_deg"]), lat_deg=float(r["lat_deg"]),
                h_m=float(r["h_m"]), H_egm96_m=float("nan"), x_m=float("nan"),
                y_m=float("nan"), land_cover=r.get("land_cover", "") or "",
                image_points={n: ImagePoint(float(r[f"{n}_col"]), float(r[f"{n}_row"]))
                              for n in NAMES}))
        except (TypeError, ValueError, OverflowError) as exc:
            raise InputError(f"check point CSV {path} line {k}: {exc}; every column must be a "
                             "number (h_m WGS84 ellipsoidal, 0-based pixel centres)") from None
    return CheckPointSet("EPSG:4326", NAMES, tuple(points))


def read_checkpoints(path: str | Path) -> CheckPointSet:
    """Check points from the simulator's ``truth/checkpoints.json`` or a CSV
    ``id,lon_deg,lat_deg,h_m,left_col,left_row,right_col,right_row`` (heights WGS84
    ellipsoidal, image coordinates 0-based with pixel centres at integers)."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"check point file {path} does not exist")
    if path.suffix.lower() == ".csv":
        points = _checkpoints_csv(path)
    else:
        text = path.read_text(encoding="utf-8", errors="replace")
        doc = parse_json(text, f"check point file {path}")
        try:
            if not isinstance(doc, dict):
                raise InputError("it is not a JSON object")
            points = CheckPointSet.from_dict(doc)
        except InputError as exc:
            raise InputError(f"check point file {path}: {exc}") from None
        except (KeyError, TypeError, ValueError, AttributeError, OverflowError) as exc:
            raise InputError(f"check point file {path} is malformed ({type(exc).__name__}: "
                             f"{exc}); give the simulator's checkpoints.json or a CSV") from None
    bad = [p.id for p in points.points if not np.isfinite(
        [p.lon_deg, p.lat_deg, p.h_m, *(v for ip in p.image_points.values()
                                          for v in (ip.col, ip.row))]).all()]
    if bad:
        raise InputError(f"check point file {path}: point {bad[0]} has a coordinate that is not a "
                         "finite number")
    missing = [n for n in NAMES if n not in points.images]
    if missing or not points.points:
        raise InputError(f"check point file {path} has no points measured in images "
                         f"{', '.join(missing) or 'left, right'}")
    return points


def check_point_report(models: tuple[SensorModel, ...], points: CheckPointSet,
                       adjustment: AbsoluteOrientation | None = None,
                       reference_sigma_m: tuple[float, float, float] = (5.0, 5.0, 5.0)
                       ) -> dict[str, dict[str, Any]]:
    """The paper's Table 2 per image: the check points' residuals under ``models``; with the
    ``adjustment`` that made them, the RMS it predicts at the same points beside the measured
    (``predicted_rms_col_px``, ``predicted_rms_row_px``: its covariance and the reference's
    registration ``reference_sigma_m``; the check points carry no measurement noise of their
    own, none is added)."""
    out = {}
    for k, (name, model) in enumerate(zip(NAMES, models, strict=True)):
        pts = [p for p in points.points if name in p.image_points]
        if not pts:
            continue
        lon, lat, h, col, row = (np.array(v, dtype=float) for v in zip(
            *[(p.lon_deg, p.lat_deg, p.h_m, p.image_points[name].col, p.image_points[name].row)
              for p in pts], strict=True))
        stats = check_point_stats(model, lon, lat, h, col, row, name)
        if adjustment is not None:
            pred = adjustment.predict(k, lon, lat, h, reference_sigma_m)
            stats = replace(stats, predicted_rms_col_px=pred.predicted_rms_col_px,
                            predicted_rms_row_px=pred.predicted_rms_row_px)
        out[name] = stats.to_dict()
    return out


@dataclass(frozen=True, eq=False)
class AbsoluteProducts:
    """The oriented models, the adjustment and where they were written."""

    models: tuple[SensorModel, ...]
    adjustment: AbsoluteOrientation
    self_calibration: SelfCalibration | None
    model_paths: tuple[Path, ...]
    predicted: dict[str, Any] = field(default_factory=dict)
    along_track: AlongTrack | None = None
    inlier: np.ndarray | None = None
    reasons: dict[int, str] | None = None

    def gcp_summary(self, gcps: tuple[ControlPoint, ...]) -> dict[str, Any]:
        """GCPs used and rejected (ids and reasons), over the GCPs given."""
        src = self.self_calibration or self.adjustment
        inlier = src.inlier if self.inlier is None else self.inlier
        reasons = src.reasons if self.reasons is None else self.reasons
        return {"given": len(gcps), "used": int(inlier.sum()), "rejected": int((~inlier).sum()),
                "rejected_ids": [{"id": gcps[int(i)].id, "reason": reasons[int(i)]}
                                 for i in np.flatnonzero(~inlier)]}


@task(name="absolute-orientation", cache_policy=NO_CACHE)
def orient_absolute(left: LoadedModel, right: LoadedModel, gcps: tuple[ControlPoint, ...],
                    out_dir: Path, corrections: str = "linear", lens: bool = False,
                    config: AbsoluteConfig | None = None,
                    ties: TieGround | None = None, along_track: bool = False
                    ) -> AbsoluteProducts:
    """Both models adjusted to the GCPs (``corrections``: ``offset`` or ``linear`` terms of
    each model; ``lens``: self-calibration of the cameras, kept only where significant) and,
    with ``ties`` (the relative orientation's tie points), to the images' relative geometry
    too; ``along_track``: then the attitude's along-track profile, harmonics in time as many
    as the data choose (:mod:`core.orientation.along_track`); written as
    ``out_dir/left.json`` and ``out_dir/right.json`` (gcpfree model files, with the sun the
    metadata stated: what later chooses the tie points' measure)."""
    config = config or AbsoluteConfig()
    models = (left.model.with_corrections(corrections),
              right.model.with_corrections(corrections))
    obs = Observations.from_control_points(gcps, NAMES)
    tie_obs = None
    if ties is not None and ties.lon_deg.size:
        tie_obs = TieObservations(np.stack([ties.left_col, ties.right_col], axis=1),
                                  np.stack([ties.left_row, ties.right_row], axis=1),
                                  ties.lon_deg, ties.lat_deg, ties.h_m, config.matching_sigma_px)
    run = _adjusted(models, obs, config, tie_obs, lens, along_track)
    if any(run.ground_error.variance_m2):  # again, each GCP weighted with its own share of it
        xy, h = with_correlated_error(obs.sigma_xy_m, obs.sigma_h_m, run.ground_error)
        run = _adjusted(models, replace(obs, sigma_xy_m=xy, sigma_h_m=h), config, tie_obs,
                        lens, along_track)
    adj, calib, at, kept, reasons, ground_error = (run.adj, run.calib, run.at, run.kept,
                                                   run.reasons, run.ground_error)
    paths = []
    for name, model, given in zip(NAMES, adj.models, (left, right), strict=True):
        paths.append(atomic_write_json(Path(out_dir) / f"{name}.json", {
            **model.to_dict(), **sun_to_dict(given.sun)}))  # type: ignore[attr-defined]
    return AbsoluteProducts(tuple(adj.models), adj, calib, tuple(paths),
                            predicted_over_images(adj, (left.size, right.size),
                                                  np.asarray(obs.h_m)[kept], config,
                                                  ground_error),
                            at, kept, reasons)


@dataclass(frozen=True, eq=False)
class _Run:
    adj: AbsoluteOrientation
    calib: SelfCalibration | None
    at: AlongTrack | None
    kept: np.ndarray
    reasons: dict[int, str]
    ground_error: CorrelatedGroundError


def _adjusted(models: tuple[SensorModel, ...], obs: Observations, config: AbsoluteConfig,
              tie_obs: TieObservations | None, lens: bool, along_track: bool) -> _Run:
    """One run of :func:`orient_absolute`'s adjustment with the GCPs weighted as ``obs``
    says: self-calibration or not, the along-track profile, the uncertainties."""
    calib = None
    if lens:
        calib = self_calibrate(models, obs, NAMES, config, ties=tie_obs)
        adj = calib.result
    else:
        adj = absolute_orientation(models, obs, NAMES, config, tie_obs)
    kept = (calib or adj).inlier  # over the GCPs given
    reasons = dict((calib or adj).reasons)
    at = None
    if along_track and any(isinstance(m, PushbroomModel) for m in adj.models):
        idx = np.flatnonzero(kept)
        sub = Observations(obs.lon_deg[idx], obs.lat_deg[idx], obs.h_m[idx],
                           np.asarray(obs.col)[idx], np.asarray(obs.row)[idx],
                           obs.sigma_xy_m[idx], obs.sigma_h_m[idx])
        base = adj if adj.inlier.size == idx.size else None
        at = estimate_along_track(adj.models, sub, NAMES, config, tie_obs, base=base)
        adj = at.result
        kept = np.zeros_like(kept)
        kept[idx[adj.inlier]] = True
        reasons.update({int(idx[i]): r for i, r in adj.reasons.items()})
    adj, ground_error = with_gcp_errors_as_they_are(adj, obs, kept, config, tie_obs)
    return _Run(adj, calib, at, kept, reasons, ground_error)


GRID_SIDE = 9


def predicted_over_images(adj: AbsoluteOrientation, sizes: tuple[tuple[int, int], ...],
                          h: np.ndarray, config: AbsoluteConfig,
                          ground_error: CorrelatedGroundError = NO_CORRELATION
                          ) -> dict[str, Any]:
    """report.json's ``absolute.predicted``: per image, the check-point RMS the adjustment
    predicts over a regular grid of ``GRID_SIDE`` x ``GRID_SIDE`` pixels spanning the image at
    the scene's heights (the 5th, 50th and 95th percentiles of the heights ``h`` of the GCPs
    kept), with the reference's registration sigma it assumed and the GCPs' correlated ground
    error it propagated (``ground_error``)."""
    heights = [float(v) for v in np.percentile(h, [5.0, 50.0, 95.0])]
    images = {name: adj.predict_over_image(k, sizes[k], heights, config.reference_sigma_m,
                                           GRID_SIDE).to_dict()
              for k, name in enumerate(NAMES)}
    return {"grid_points_per_side": GRID_SIDE, "heights_m": heights,
            "reference_sigma_m": list(config.reference_sigma_m),
            "correlated_ground_error": ground_error.to_dict(), "images": images}


def write_gcps(path: Path, gcps: tuple[ControlPoint, ...]) -> Path:
    return atomic_write_json(path, control_points_to_dict(gcps))
