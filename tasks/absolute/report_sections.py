"""The sections of ``report.json`` (:class:`tasks.absolute.report.OrientReport`), one typed
value each, and the key access they share: :func:`_get` (a key of a kind, or InputError naming
its path) and :func:`_json`. Each section writes its keys (``to_dict``) and reads them
(``from_dict``) here; the report itself, its format and version, are
:mod:`tasks.absolute.report`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from core.errors import InputError
from core.jsonio import json_ready
from core.orientation.frames import REFERENCE
from tasks.dense.dem import DemSummary

if TYPE_CHECKING:
    from core.heights import DatumDecision
    from core.matching.relief import ReliefVerdict
    from core.matching.surface import SurfaceMatchConfig
    from core.orientation.adjust import Solution
    from tasks.absolute.orientation import AbsoluteProducts
    from tasks.absolute.surface_match import SurfaceMatchResult
    from tasks.io.pair import PairInputs

Doc = Mapping[str, Any]
NUMBER = (int, float, type(None))  # a number; NaN is written as null


def _get(d: Any, key: str, where: str, kind: type | tuple[type, ...] = object) -> Any:
    """``d[key]``, or InputError naming the key path (``where.key``) when it is missing or
    not of ``kind`` (a boolean is no number here)."""
    path = f"{where}.{key}" if where else key
    if not isinstance(d, Mapping):
        raise InputError(f"'{where}' is not an object")
    if key not in d:
        raise InputError(f"'{path}' is missing")
    v = d[key]
    if not isinstance(v, kind) or (isinstance(v, bool) and kind is not bool):
        raise InputError(f"'{path}' is a {type(v).__name__}, not what gcpfree writes there")
    return v


# ---------------------------------------------------------------------------- sections


@dataclass(frozen=True)
class Relief:
    """The relief verdict (:meth:`core.matching.relief.ReliefVerdict.to_dict`): windows placed,
    qualified and needed, the relief found and needed (m, None when undefined), and the
    reason of a refusal (None when ``enough``)."""

    n_windows: int
    n_qualified: int
    n_needed: int
    relief_found_m: float | None
    relief_needed_m: float | None
    max_precision_m: float
    n_small: int
    n_voids: int
    best_dem_cells: int
    min_cells: int
    cell_m: float | None
    radius_m: float | None
    enough: bool
    reason: str | None

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: Doc, where: str = "surface_matching.relief") -> Relief:
        ints = ("n_windows", "n_qualified", "n_needed", "n_small", "n_voids",
                "best_dem_cells", "min_cells")
        return cls(**{k: _get(d, k, where, int) for k in ints},
                   **{k: _get(d, k, where, NUMBER) for k in
                      ("relief_found_m", "relief_needed_m", "max_precision_m", "cell_m",
                       "radius_m")},
                   enough=_get(d, "enough", where, bool),
                   reason=_get(d, "reason", where, (str, type(None))))


@dataclass(frozen=True)
class SurfaceMatching:
    """Step 3 in figures: the settings used, the windows placed, their ``counts`` by status,
    how many ``qualified`` by their relief, the verdict, and the file of every window."""

    settings: Mapping[str, Any]
    windows: int
    counts: Mapping[str, int]
    qualified: int
    relief: Relief
    windows_file: str = "windows.json"

    @classmethod
    def of(cls, cfg: SurfaceMatchConfig, spacing_m: float | None, min_windows: int,
           result: SurfaceMatchResult, verdict: ReliefVerdict) -> SurfaceMatching:
        """The figures of a run of :func:`tasks.absolute.surface_match.match_surfaces`."""
        return cls.from_dict(_json({
            "settings": {**asdict(cfg), "spacing_m": spacing_m, "min_windows": min_windows},
            "windows": len(result.matches), "counts": result.counts(),
            "qualified": verdict.n_qualified, "relief": verdict.to_dict(),
            "windows_file": "windows.json"}))

    def to_dict(self) -> dict[str, Any]:
        return {"settings": dict(self.settings), "windows": self.windows,
                "counts": dict(self.counts), "qualified": self.qualified,
                "relief": self.relief.to_dict(), "windows_file": self.windows_file}

    @classmethod
    def from_dict(cls, d: Doc, where: str = "surface_matching") -> SurfaceMatching:
        return cls(settings=dict(_get(d, "settings", where, Mapping)),
                   windows=_get(d, "windows", where, int),
                   counts=dict(_get(d, "counts", where, Mapping)),
                   qualified=_get(d, "qualified", where, int),
                   relief=Relief.from_dict(_get(d, "relief", where, Mapping)),
                   windows_file=_get(d, "windows_file", where, str))


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
        return cls.from_dict(_json({**absolute.gcp_summary(), "file": "gcps.json"}))

    def to_dict(self) -> dict[str, Any]:
        return {"given": self.given, "used": self.used, "rejected": self.rejected,
                "rejected_ids": [asdict(r) for r in self.rejected_ids], "file": self.file}

    @classmethod
    def from_dict(cls, d: Doc, where: str = "gcps") -> GcpSummary:
        ids = tuple(RejectedGcp(_get(r, "id", f"{where}.rejected_ids", int),
                                _get(r, "reason", f"{where}.rejected_ids", str))
                    for r in _get(d, "rejected_ids", where, list))
        return cls(_get(d, "given", where, int), _get(d, "used", where, int),
                   _get(d, "rejected", where, int), ids, _get(d, "file", where, str))


@dataclass(frozen=True)
class ImageFit:
    """One image after the absolute orientation: its parameters before and after, with their
    sigmas, and the residuals (px) at the ``n`` GCPs used; ``rms_col_px`` is the paper's P,
    ``rms_row_px`` its L."""

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

    def to_dict(self) -> dict[str, Any]:
        return {"param_names": list(self.param_names),
                "params_before": list(self.params_before),
                "params_after": list(self.params_after), "sigmas": list(self.sigmas),
                "name": self.name, "n": self.n, "rms_col_px": self.rms_col_px,
                "rms_row_px": self.rms_row_px, "mean_col_px": self.mean_col_px,
                "mean_row_px": self.mean_row_px}

    @classmethod
    def from_dict(cls, d: Doc, where: str) -> ImageFit:
        return cls(_get(d, "name", where, str), _get(d, "n", where, int),
                   *(_get(d, k, where, NUMBER) for k in ("rms_col_px", "rms_row_px",
                                                         "mean_col_px", "mean_row_px")),
                   *(tuple(_get(d, k, where, list)) for k in ("param_names", "params_before",
                                                              "params_after", "sigmas")))


@dataclass(frozen=True)
class LensCalibration:
    """The lens self-calibration (:meth:`core.orientation.selfcal.SelfCalibration.to_dict`):
    whether terms were ``applied``, the terms kept per image (``significant``: term ->
    estimate, sigma, the term's name in the menu), the GCP residual RMS without and with them
    per image, each image's Wald statistic against its limit (``wald``: on ``N^-1``;
    ``wald_correlated``: on the sandwich covariance, the GCPs' correlated ground error in it,
    against ``wald_correlated_limit``; absent from older reports), and the tie points'
    evidence (their parallax RMS without and with the terms, the F test; null without tie
    points); ``decision``: why, in one line (absent from older reports, read as None)."""

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

    def to_dict(self) -> dict[str, Any]:
        return {"applied": self.applied, "t_threshold": self.t_threshold,
                "significant": {k: dict(v) for k, v in self.significant.items()},
                "improvement": {k: dict(v) for k, v in self.improvement.items()},
                "wald": dict(self.wald) if self.wald is not None else None,
                "wald_limit": self.wald_limit,
                "tie_points": dict(self.tie_points) if self.tie_points is not None else None,
                **({"decision": self.decision} if self.decision is not None else {}),
                **({"wald_correlated": dict(self.wald_correlated),
                    "wald_correlated_limit": self.wald_correlated_limit}
                   if self.wald_correlated is not None else {})}

    @classmethod
    def from_dict(cls, d: Doc, where: str = "absolute.self_calibration") -> LensCalibration:
        limit, limit_correlated = d.get("wald_limit"), d.get("wald_correlated_limit")
        decision = (None if d.get("decision") is None
                    else str(_get(d, "decision", where, str)))
        return cls(_get(d, "applied", where, bool), _get(d, "t_threshold", where, NUMBER),
                   dict(_get(d, "significant", where, Mapping)),
                   dict(_get(d, "improvement", where, Mapping)),
                   _optional(d, "wald", where),
                   float(limit) if isinstance(limit, (int, float)) else None,
                   _optional(d, "tie_points", where), decision,
                   _optional(d, "wald_correlated", where),
                   float(limit_correlated) if isinstance(limit_correlated, (int, float))
                   else None)


@dataclass(frozen=True)
class Absolute:
    """Step 4: both images adjusted together on the GCPs (``corrections``: ``linear`` or
    ``offset`` terms), optionally with lens terms."""

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
    frames: tuple[Mapping[str, Any], ...] | None = None

    @classmethod
    def of(cls, absolute: AbsoluteProducts, corrections: str) -> Absolute:
        """The figures of :func:`tasks.absolute.orientation.orient_absolute`."""
        lens = absolute.self_calibration
        return cls.from_dict(_json({**absolute.adjustment.to_dict(), "corrections": corrections,
                                    "self_calibration": lens.to_dict() if lens else None,
                                    "predicted": absolute.predicted or None,
                                    "along_track": (absolute.along_track.to_dict()
                                                    if absolute.along_track else None)}))

    def to_dict(self) -> dict[str, Any]:
        return {"images": {n: f.to_dict() for n, f in self.images.items()},
                "sigma0": self.sigma0, "n_gcps": self.n_gcps,
                "rejected": [dict(r) for r in self.rejected],
                "n_iterations": self.n_iterations, "converged": self.converged,
                "corrections": self.corrections,
                "self_calibration": (self.self_calibration.to_dict()
                                     if self.self_calibration is not None else None),
                **{k: dict(v) for k, v in (("variance_components", self.variance_components),
                                           ("predicted", self.predicted),
                                           ("tie_points", self.tie_points),
                                           ("along_track", self.along_track)) if v is not None},
                **({"frames": [dict(f) for f in self.frames]} if self.frames is not None
                   else {})}

    @classmethod
    def from_dict(cls, d: Doc, where: str = "absolute") -> Absolute:
        lens = _get(d, "self_calibration", where, (Mapping, type(None)))
        return cls(
            images={n: ImageFit.from_dict(v, f"{where}.images.{n}")
                    for n, v in _get(d, "images", where, Mapping).items()},
            sigma0=_get(d, "sigma0", where, NUMBER), n_gcps=_get(d, "n_gcps", where, int),
            rejected=tuple(dict(r) for r in _get(d, "rejected", where, list)),
            n_iterations=_get(d, "n_iterations", where, int),
            converged=_get(d, "converged", where, bool),
            corrections=_get(d, "corrections", where, str),
            self_calibration=LensCalibration.from_dict(lens) if lens is not None else None,
            variance_components=_optional(d, "variance_components", where),
            predicted=_predicted(d, where), tie_points=_optional(d, "tie_points", where),
            along_track=_optional(d, "along_track", where),
            frames=(tuple(dict(f) for f in _get(d, "frames", where, list)) if "frames" in d
                    else None))


@dataclass(frozen=True)
class Models:
    """The oriented model files, relative to the output folder."""

    left: str = "left.json"
    right: str = "right.json"

    @classmethod
    def from_dict(cls, d: Doc, where: str = "models") -> Models:
        return cls(_get(d, "left", where, str), _get(d, "right", where, str))


@dataclass(frozen=True)
class ReferenceUsed:
    """The reference DEM the pair was oriented to (``path``: given, or prepared from
    ``srtm_dir``), its vertical datum and what decided it; ``registration_estimate``: where
    other control (a SAR scene) made the reference's own misregistration observable, the
    reference's shift as estimated (``shift_m``: east, north, up, m, where the reference
    shows the world against the truth; ``sigma_m``; its prior ``prior_sigma_m``), removed from
    the orientation; None where it was not observable."""

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
                   None if pair.srtm_dir is None else str(pair.srtm_dir), est)

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        if self.registration_estimate is None:
            d.pop("registration_estimate")
        return d

    @classmethod
    def from_dict(cls, d: Doc, where: str = "reference") -> ReferenceUsed:
        opt = (str, type(None))
        return cls(_get(d, "path", where, str), _get(d, "vertical", where, str),
                   _get(d, "vertical_source", where, str), _get(d, "given", where, opt),
                   _get(d, "srtm_dir", where, opt),
                   _optional(d, "registration_estimate", where))


@dataclass(frozen=True)
class FinalDsm:
    """The final DSM: its ellipsoidal and EGM96 files and the ellipsoidal one's summary."""

    ellipsoidal: str
    egm96: str
    summary: DemSummary

    def to_dict(self) -> dict[str, Any]:
        return {"ellipsoidal": self.ellipsoidal, "egm96": self.egm96,
                "summary": self.summary.to_dict()}

    @classmethod
    def from_dict(cls, d: Doc, where: str = "dsm") -> FinalDsm:
        return cls(_get(d, "ellipsoidal", where, str), _get(d, "egm96", where, str),
                   _dem_summary(_get(d, "summary", where, Mapping), f"{where}.summary"))


def _optional(d: Doc, key: str, where: str) -> dict[str, Any] | None:
    """``d[key]`` as a dict when present and not null (a key later versions added)."""
    v = d.get(key)
    return None if v is None else dict(_get(d, key, where, Mapping))


def _predicted(d: Doc, where: str) -> dict[str, Any] | None:
    """``absolute.predicted``, its per-image RMS checked to be numbers."""
    p = _optional(d, "predicted", where)
    if p is not None:
        for n, img in _get(p, "images", f"{where}.predicted", Mapping).items():
            for k in ("predicted_rms_col_px", "predicted_rms_row_px"):
                _get(img, k, f"{where}.predicted.images.{n}", NUMBER)
    return p


def _json(doc: Any) -> Any:
    """``doc`` as its JSON values (NumPy numbers as Python's, NaN as None)."""
    return json_ready(doc)


def _dem_summary(d: Doc, where: str) -> DemSummary:
    try:
        return DemSummary.from_dict(d)
    except InputError as exc:
        raise InputError(f"'{where}': {exc}") from None
