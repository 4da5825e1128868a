"""The products' JSON documents on :mod:`tasks.io.documents`: each one's layout and its
:class:`~tasks.io.documents.Document` (gcps.json, eval.json, windows.json, checkpoints.json,
pair.json). Keys, their order and the readers' checks are those the hand-written writers and
readers had (``tests/tasks/test_documents.py`` reads the files today's code wrote, in
``tests/data/products_v0_1/``, and writes them back byte for byte), and the simulator's
checkpoints.json and truth/scene.json, which ``tasks.simulate`` writes itself. The orientation's
report.json is on the same pattern, beside its sections (:data:`tasks.absolute.report.REPORT`)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Annotated, Any

from pydantic import AfterValidator, PlainSerializer

from core.evaluation.evaluation import DzStats, StatsConfig
from core.evaluation.evaluation_report import (
    REPORT_FORMAT,
    EvaluationReport,
    GcpCheck,
    LandcoverInfo,
    PointCounts,
)
from core.geodesy import BBox
from core.matching.surface_file import WindowsFile, WindowTried
from core.points import CheckPoint, CheckPointSet, ControlPoint, GcpSet, GeoPoint
from core.simulation.scene import InjectedErrors, SceneDef, TruthGrid
from tasks.io.documents import Document, layout, shape

# ------------------------------------------------------------------------------ gcps.json

layout(ControlPoint, keys={"image_points": "images"})
GCPS: Document[GcpSet] = Document("gcps.json", GcpSet,
                                  hint="give the gcps.json written by gcpfree orient")

# ---------------------------------------------------------------------------- windows.json

layout(WindowTried, inline=("match",))
WINDOWS: Document[WindowsFile] = Document(
    "windows.json", WindowsFile, hint="give the windows.json written by gcpfree orient")

# ------------------------------------------------------------------------ checkpoints.json

layout(CheckPoint, spread="image_points")
layout(CheckPointSet, computed={"heights": lambda s: s.HEIGHTS,
                                "image_coordinates": lambda s: s.IMAGE_COORDINATES},
       order=("crs", "heights", "image_coordinates", "images", "points"))
#: the simulator's truth/checkpoints.json (written by ``tasks.simulate``; read here)
CHECKPOINTS: Document[CheckPointSet] = Document(
    "checkpoints.json", CheckPointSet, hint="give the checkpoints.json written by gcpfree simulate")

# ------------------------------------------------------------------------------ eval.json

layout(DzStats, keys={**{f"{k}_m": k for k in DzStats.KEYS}, "le68_ci_m": "le68_ci"},
       computed={"unit": lambda s: "m"})
layout(PointCounts, computed={"refused_pct": lambda p: p.refused_pct})
layout(StatsConfig, computed={
    "std": lambda s: "sample (n - 1)", "percentiles": lambda s: "numpy linear",
    "nmad": lambda s: "1.4826 median |dz - median|",
    "le68_ci": lambda s: "percentile bootstrap (order statistics), seeded"})
layout(GcpCheck, computed={"rms_m": lambda g: g.stats.rmse_m},
       order=("path", "points", "outside_dem", "rms_m", "stats"))
# the land-cover names as {"code": name}
_NAMES = Annotated[dict[str, str],
                   AfterValidator(lambda d: tuple((int(c), n) for c, n in d.items())),
                   PlainSerializer(lambda t: {str(c): n for c, n in t})]
layout(LandcoverInfo, types={"names": _NAMES})
# an empty class filter is written as null, as no filter
_FILTER = Annotated[shape(tuple[int, ...] | None),
                    PlainSerializer(lambda v: list(v) if v else None)]


def _inputs(r: EvaluationReport) -> dict[str, Any]:
    return {"dem": r.dem.path, "lidar": r.lidar.path,
            "landcover": r.landcover.path if r.landcover else None,
            "mask": r.mask.path if r.mask else None, "gcps": r.gcps.path if r.gcps else None}


layout(EvaluationReport, keys={"stats_config": "statistics"}, types={"class_filter": _FILTER},
       computed={"format": lambda r: REPORT_FORMAT, "version": lambda r: 1,
                 "dz": lambda r: ("DEM - lidar, metres; the DEM interpolated bilinearly at "
                                  "each lidar point"), "inputs": _inputs},
       order=("format", "version", "dz", "inputs", "heights_compared", "transformation", "dem",
              "lidar", "landcover", "classes_from", "class_filter", "points", "classes",
              "class_labels", "all", "statistics", "mask", "gcps"))
EVALUATION: Document[EvaluationReport] = Document(
    "eval.json", EvaluationReport, format=REPORT_FORMAT,
    hint="give the eval.json written by gcpfree evaluate")



@dataclass(frozen=True)
class EvaluationStats:
    """The statistics of an eval.json alone, per class and over ``all`` (what the archive's
    summary and artifacts read: they need no more of the file)."""

    classes: Mapping[str, DzStats]
    all: DzStats


EVALUATION_STATS: Document[EvaluationStats] = Document(
    "eval.json", EvaluationStats, format=REPORT_FORMAT,
    hint="give the eval.json written by gcpfree evaluate")

# ---------------------------------------------------------------------- truth/scene.json

layout(BBox, as_list=True)
layout(GeoPoint, as_list=True)
layout(TruthGrid, as_list=True)
layout(InjectedErrors, omit_default=("realistic",))
#: the simulator's truth/scene.json (written by ``tasks.simulate``; read here)
SCENE: Document[SceneDef] = Document(
    "scene.json", SceneDef, hint="give the truth/scene.json written by gcpfree simulate")

# ------------------------------------------------------------------------------ pair.json

PAIR_FORMAT = "gcpfree.pair"


@dataclass(frozen=True, kw_only=True)
class PairManifest:
    """``OUT/pair.json``, written last by ``gcpfree pair``: the run's parameters
    (:meth:`flows.pair.PairParams.to_dict`, flat keys; None in a manifest that records none),
    its products (manifest key -> path relative to OUT) and their sizes in bytes when the pair
    finished (path -> size)."""

    format: str = PAIR_FORMAT
    version: int = 1
    pair_id: str
    params: Mapping[str, Any] | None = None
    products: Mapping[str, str] = field(default_factory=dict)
    sizes: Mapping[str, int] = field(default_factory=dict)


PAIR: Document[PairManifest] = Document("pair.json", PairManifest, format=PAIR_FORMAT,
                                        hint="give the pair.json written by gcpfree pair")

__all__ = ["CHECKPOINTS", "EVALUATION", "EVALUATION_STATS", "GCPS", "PAIR", "PAIR_FORMAT", "SCENE",
           "WINDOWS",
           "EvaluationStats", "PairManifest"]
