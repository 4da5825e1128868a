"""The sections of ``report.json`` (:class:`tasks.absolute.report.OrientReport`), one typed
value each: their fields are the file's keys, read and written by :mod:`tasks.io.documents`
(the report's document is :data:`tasks.absolute.report.REPORT`). A layout is registered here
only where a section's keys differ from its fields.

Where the section is a result of core, core's class is the schema, declared once:
:class:`core.matching.relief.ReliefVerdict` (``surface_matching.relief``; ``enough`` and
``reason`` written from it), :class:`core.orientation.checkpoints.CheckPointStats`
(``check_points.<image>``; the predicted RMS left out when there is none) and
:class:`core.orientation.frames.FrameEstimate` (``absolute.frames``). Where core's result
cannot be read back from the file, the section is the schema of what core writes of it, and
its ``of`` reads core's output through that schema: :class:`ImageFit` of
:meth:`core.orientation.result.AbsoluteOrientation.to_dict`'s ``images.<image>`` (the
parameters, and :meth:`~core.orientation.result.ImageResiduals.to_dict`'s figures: the
residual arrays are not in the file), :class:`LensCalibration` of
:meth:`core.orientation.selfcal.SelfCalibration.to_dict` (the two adjustments are not in the
file); ``tests/tasks/test_report.py`` checks that nothing core writes is dropped on the way.

Kept as the mappings their writers make (a class would only re-declare their dict output;
the writers own their keys): ``relative`` (rel.json, whole), ``sar``
(:meth:`tasks.absolute.sar_control.SarControl.summary`), ``settings``
(:meth:`flows.orient.OrientParams.settings`: the flat keys the resume checks compare),
``report`` (the run report's record), and in ``absolute``: ``predicted``
(:meth:`core.orientation.adjust.Solution.predicted_over_images`; its per-image keys grew
over versions and are written back as each file has them; its predicted RMS checked to be
numbers), ``variance_components``, ``tie_points``, ``along_track`` (their results hold
arrays the file summarises), ``rejected`` and ``reference.registration_estimate``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, TypeVar

from pydantic import AfterValidator

from core.errors import InputError
from core.jsonio import json_ready
from core.matching.relief import ReliefVerdict
from core.orientation.checkpoints import CheckPointStats
from core.orientation.frames import REFERENCE, FrameEstimate
from tasks.dense.dem import DemSummary
from tasks.io.documents import Number, adapter, layout, shape

if TYPE_CHECKING:
    from core.heights import DatumDecision
    from core.matching.surface import SurfaceMatchConfig
    from core.orientation.adjust import Solution
    from tasks.absolute.orientation import AbsoluteProducts
    from tasks.absolute.surface_match import SurfaceMatchResult
    from tasks.io.pair import PairInputs

T = TypeVar("T")

layout(ReliefVerdict, computed={"enough": lambda v: v.enough, "reason": lambda v: v.reason})
layout(CheckPointStats, omit_default=tuple(f.name for f in fields(CheckPointStats)
                                           if f.name.startswith("predicted_")))


def of_core(value_type: Any, doc: Any) -> Any:
    """What core wrote (``doc``: its ``to_dict`` output) read through the section's schema
    ``value_type``, as the file will hold it (JSON values first: NaN as null, NumPy numbers
    as Python's)."""
    return adapter(value_type).validate_python(json_ready(doc))


# ---------------------------------------------------------------------------- sections


@dataclass(frozen=True)
class SurfaceMatching:
    """Step 3 in figures: the settings used, the windows placed, their ``counts`` by status,
    how many ``qualified`` by their relief, the verdict, and the file of every window."""

    settings: Mapping[str, Any]
    windows: int
    counts: Mapping[str, int]
    qualified: int
    relief: ReliefVerdict
    windows_file: str = "windows.json"

    @classmethod
    def of(cls, cfg: SurfaceMatchConfig, spacing_m: float | None, min_windows: int,
           result: SurfaceMatchResult, verdict: ReliefVerdict) -> SurfaceMatching:
        """The figures of a run of :func:`tasks.absolute.surface_match.match_surfaces`."""
        return of_core(cls, {
            "settings": {**asdict(cfg), "spacing_m": spacing_m, "min_windows": min_windows},
            "windows": len(result.matches), "counts": result.counts(),
            "qualified": verdict.n_qualified, "relief": verdict.to_dict()})


@dataclass(frozen=True)
class RejectedGcp:
    """A GCP the absolute orientation rejected (its id in gcps.json) and why."""

    id: int
    reason: str


@dataclass(frozen=True)
class GcpSummary:
    """The simulated GCPs: ``given`` to the adjustment, ``used``, ``rejected`` (with their
    ids and reasons), and their file."""

    given: int
    used: int
    rejected: int
    rejected_ids: tuple[RejectedGcp, ...] = ()
    file: str = "gcps.json"

    @classmethod
    def of(cls, absolute: AbsoluteProducts) -> GcpSummary:
        """The GCPs ``absolute`` used and rejected, over the GCPs given to it."""
        return of_core(cls, absolute.gcp_summary())


@dataclass(frozen=True)
class ImageFit:
    """One image after the absolute orientation (the record
    :meth:`core.orientation.result.AbsoluteOrientation.to_dict` writes per image): its
    parameters before and after, with their sigmas, and the residuals (px) at the ``n`` GCPs
    used as :meth:`core.orientation.result.ImageResiduals.to_dict` writes them; ``rms_col_px``
    is the paper's P, ``rms_row_px`` its L."""

    name: str
    n: int
    rms_col_px: float
    rms_row_px: float
    mean_col_px: float
    mean_row_px: float
    param_names: tuple[str, ...]
    params_before: tuple[float, ...]
    params_after: tuple[float, ...]
    sigmas: tuple[float | None, ...]


layout(ImageFit, order=("param_names", "params_before", "params_after", "sigmas"))


@dataclass(frozen=True)
class LensCalibration:
    """The lens self-calibration (what
    :meth:`core.orientation.selfcal.SelfCalibration.to_dict` writes): whether terms were
    ``applied``, the terms kept per image (``significant``: term -> estimate, sigma, the
    term's name in the menu), the GCP residual RMS without and with them per image, each
    image's Wald statistic against its limit (``wald``: on ``N^-1``; ``wald_correlated``: on
    the sandwich covariance, the GCPs' correlated ground error in it, against
    ``wald_correlated_limit``; both absent from older reports), and the tie points' evidence
    (their parallax RMS without and with the terms, the F test; null without tie points);
    ``decision``: why, in one line (absent from older reports, read as None)."""

    applied: bool
    t_threshold: float
    significant: Mapping[str, Mapping[str, Mapping[str, Any]]]
    improvement: Mapping[str, Mapping[str, float]]
    wald: Mapping[str, float] | None = None
    wald_limit: float | None = None
    tie_points: Mapping[str, float] | None = None
    decision: str | None = None
    wald_correlated: Mapping[str, float] | None = None
    wald_correlated_limit: float | None = None


# the limit is written beside its statistics (null when undefined), absent with them
layout(LensCalibration, omit_default=("decision", "wald_correlated", "wald_correlated_limit"),
       types={"wald_correlated_limit": Number})


def _predicted(p: Mapping[str, Any] | None) -> Mapping[str, Any] | None:
    """``absolute.predicted`` as written, its per-image predicted RMS checked to be numbers."""
    if p is None:
        return None
    images = p.get("images")
    if not isinstance(images, Mapping):
        raise InputError("key 'absolute.predicted.images' must be an object, got "
                         f"{images!r:.40}")
    for name, img in images.items():
        for k in ("predicted_rms_col_px", "predicted_rms_row_px"):
            v = img.get(k, "") if isinstance(img, Mapping) else ""
            if isinstance(v, bool) or not isinstance(v, (int, float, type(None))):
                raise InputError(f"key 'absolute.predicted.images.{name}.{k}' must be a "
                                 f"number, got {v!r:.40}")
    return p


@dataclass(frozen=True)
class Absolute:
    """Step 4: both images adjusted together on the GCPs (``corrections``: ``linear`` or
    ``offset`` terms), optionally with lens terms; since the true uncertainties, the variance
    components, the predicted accuracy, the tie points, the along-track attitude and the
    frames (each absent from older reports, read as None)."""

    images: Mapping[str, ImageFit]
    sigma0: float | None
    n_gcps: int
    rejected: tuple[Mapping[str, Any], ...]
    n_iterations: int
    converged: bool
    corrections: str
    self_calibration: LensCalibration | None = None
    variance_components: Mapping[str, Any] | None = None
    predicted: Mapping[str, Any] | None = None
    tie_points: Mapping[str, Any] | None = None
    along_track: Mapping[str, Any] | None = None
    frames: tuple[FrameEstimate, ...] | None = None

    @classmethod
    def of(cls, absolute: AbsoluteProducts, corrections: str) -> Absolute:
        """The figures of :func:`tasks.absolute.orientation.orient_absolute`."""
        lens, at = absolute.self_calibration, absolute.along_track
        return of_core(cls, {**absolute.adjustment.to_dict(), "corrections": corrections,
                             "self_calibration": lens.to_dict() if lens else None,
                             "predicted": absolute.predicted or None,
                             "along_track": at.to_dict() if at else None})


layout(Absolute, omit_default=("variance_components", "predicted", "tie_points", "along_track",
                               "frames"),
       types={"predicted": Annotated[shape(Mapping[str, Any] | None),
                                     AfterValidator(_predicted)]})


@dataclass(frozen=True)
class Models:
    """The oriented model files, relative to the output folder."""

    left: str = "left.json"
    right: str = "right.json"


@dataclass(frozen=True)
class ReferenceUsed:
    """The reference DEM the pair was oriented to (``path``: given, or prepared from
    ``srtm_dir``), its vertical datum and what decided it; ``registration_estimate``: where
    other control (a SAR scene) made the reference's own misregistration observable, the
    reference's shift as estimated (``shift_m``: east, north, up, m, where the reference
    shows the world against the truth; ``sigma_m``; its prior ``prior_sigma_m``), removed from
    the orientation; None (and absent) where it was not observable."""

    path: str
    vertical: str
    vertical_source: str
    given: str | None = None
    srtm_dir: str | None = None
    registration_estimate: Mapping[str, Any] | None = None

    @classmethod
    def of(cls, path: Path, datum: DatumDecision, pair: PairInputs,
           solution: Solution | None = None) -> ReferenceUsed:
        """The reference at ``path`` with its datum decision, as ``pair`` gave it; with the
        ``solution``, its registration where it was estimated."""
        est = None
        frame = solution.frame(REFERENCE) if solution is not None else None
        if frame is not None and frame.observed:
            # X_true = X_gcp + s: the reference shows the world moved by -s
            est = {"shift_m": [-v for v in frame.shift_m], "sigma_m": list(frame.sigma_m),
                   "prior_sigma_m": list(frame.prior_sigma_m), "source": frame.source}
        return cls(str(path), datum.datum, datum.source,
                   None if pair.reference is None else str(pair.reference),
                   None if pair.srtm_dir is None else str(pair.srtm_dir), json_ready(est))


layout(ReferenceUsed, omit_default=("registration_estimate",))


@dataclass(frozen=True)
class FinalDsm:
    """The final DSM: its ellipsoidal and EGM96 files and the ellipsoidal one's summary."""

    ellipsoidal: str
    egm96: str
    summary: DemSummary
