"""Tasks of step 4: the absolute orientation of the images on the simulated GCPs, check points
and the products of ``gcpfree orient`` (oriented models, GCPs, report.json).

The maths is :mod:`core.orientation.adjust` (the one estimator); here the check points are
read (the simulator's ``checkpoints.json`` or a CSV), the estimator called once and its
products written atomically.
"""

from __future__ import annotations

import csv
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from prefect import task
from prefect.cache_policies import NO_CACHE

from core.errors import InputError
from core.jsonio import parse_json
from core.orientation.absolute import AbsoluteConfig
from core.orientation.adjust import (
    AdjustConfig,
    ControlSet,
    ImageToAdjust,
    Solution,
    adjust,
    check_points_in,
)
from core.orientation.along_track import AlongTrack
from core.orientation.result import AbsoluteOrientation
from core.orientation.selfcal import SelfCalibration
from core.orientation.ties import TieObservations
from core.points import (
    CheckPoint,
    CheckPointSet,
    ControlPoint,
    GcpSet,
    ImagePoint,
)
from core.sensors.base import SensorModel
from tasks.absolute.surface_match import TieGround
from tasks.io.model_files import model_document
from tasks.io.products import CHECKPOINTS, GCPS
from tasks.io.rasters import atomic_write_json
from tasks.io.sensors import LoadedModel

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


def read_checkpoints(path: str | Path, images: tuple[str, ...] = NAMES) -> CheckPointSet:
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
        if not isinstance(doc, dict):
            raise InputError(f"check point file {path}: it is not a JSON object; give the "
                             "simulator's checkpoints.json or a CSV")
        points = CHECKPOINTS.load(doc, f"check point file {path}")
    bad = [p.id for p in points.points if not np.isfinite(
        [p.lon_deg, p.lat_deg, p.h_m, *(v for ip in p.image_points.values()
                                          for v in (ip.col, ip.row))]).all()]
    if bad:
        raise InputError(f"check point file {path}: point {bad[0]} has a coordinate that is not a "
                         "finite number")
    missing = [n for n in images if n not in points.images]
    if (missing if images == NAMES else len(missing) == len(images)) or not points.points:
        raise InputError(f"check point file {path} has no points measured in images "
                         f"{', '.join(missing) or ', '.join(images)}")
    return points


def check_point_report(models: tuple[SensorModel, ...], points: CheckPointSet,
                       solution: Solution | None = None, names: tuple[str, ...] = NAMES
                       ) -> dict[str, dict[str, Any]]:
    """The paper's Table 2 per image: the check points' residuals under ``models``; with the
    ``solution`` that made them, the RMS it predicts at the same points beside the measured
    (:meth:`core.orientation.adjust.Solution.check_points`)."""
    if solution is not None:
        return {n: s.to_dict() for n, s in solution.check_points(points).items()}
    out = {}
    for name, model in zip(names, models, strict=True):
        stats = check_points_in(model, points, name)
        if stats is not None:
            out[name] = stats.to_dict()
    return out


@dataclass(frozen=True, eq=False)
class AbsoluteProducts:
    """The solution of :func:`core.orientation.adjust.adjust` and where its models were
    written."""

    solution: Solution
    model_paths: tuple[Path, ...]

    @property
    def models(self) -> tuple[SensorModel, ...]:
        return self.solution.models

    @property
    def adjustment(self) -> AbsoluteOrientation:
        return self.solution.adjustment

    @property
    def self_calibration(self) -> SelfCalibration | None:
        return self.solution.self_calibration

    @property
    def along_track(self) -> AlongTrack | None:
        return self.solution.along_track

    @property
    def predicted(self) -> dict[str, Any]:
        return self.solution.predicted_over_images()

    def gcp_summary(self, gcps: tuple[ControlPoint, ...] | None = None) -> dict[str, Any]:
        """GCPs used and rejected (ids and reasons), over the GCPs given."""
        return self.solution.gcp_summary()


def tie_observations(ties: TieGround | None, config: AbsoluteConfig
                     ) -> TieObservations | None:
    """The relative orientation's tie points as the adjustment takes them (None: none)."""
    if ties is None or not ties.lon_deg.size:
        return None
    return TieObservations(np.stack([ties.left_col, ties.right_col], axis=1),
                           np.stack([ties.left_row, ties.right_row], axis=1),
                           ties.lon_deg, ties.lat_deg, ties.h_m, config.matching_sigma_px)


@task(name="absolute-orientation", cache_policy=NO_CACHE)
def orient_absolute(images: Sequence[tuple[str, LoadedModel]], control: Sequence[ControlSet],
                    out_dir: Path, config: AdjustConfig | None = None,
                    ties: TieGround | TieObservations | None = None) -> AbsoluteProducts:
    """Every image (name, model) adjusted to the control sets and the tie points (a pair's, or
    a block's tracks) in one solution (:func:`core.orientation.adjust.adjust`), written as
    ``out_dir/NAME.json`` (gcpfree model files, with the sun the metadata stated: what later
    chooses the tie points' measure)."""
    config = config or AdjustConfig()
    tie_obs = ties if isinstance(ties, TieObservations) else \
        tie_observations(ties, config.absolute)
    solution = adjust([ImageToAdjust(n, m.model, m.size) for n, m in images], control,
                      tie_obs, config)
    paths = []
    Path(out_dir).mkdir(parents=True, exist_ok=True)
    for (name, given), model in zip(images, solution.models, strict=True):
        paths.append(atomic_write_json(Path(out_dir) / f"{name}.json",
                                       model_document(model, given.sun)))
    return AbsoluteProducts(solution, tuple(paths))


def write_gcps(path: Path, gcps: tuple[ControlPoint, ...]) -> Path:
    return GCPS.write(path, GcpSet(points=gcps))
