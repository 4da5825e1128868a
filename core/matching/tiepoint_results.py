"""Tie points as values: their status codes, every searched point (:class:`Matches`), the tie
points kept (JSON round trip) and the report of the search (:mod:`core.matching.tiepoints`
finds them)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from enum import IntEnum
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.errors import InputError
from core.matching.peaks import MEASURE_NAMES

FloatArray = NDArray[np.float64]


class TiePointStatus(IntEnum):
    """Why a point is (not) a tie point. 0-15 matching, 16 and above orientation."""

    OK = 0
    NO_PRIOR = 1  # no height or no prediction in the right image (off the DEM, off the model)
    OUTSIDE = 2  # the template or the search area lies outside the images or on nodata
    NO_TEXTURE = 3  # flat template (zero variance): correlation undefined
    EDGE_PEAK = 4  # best correlation on the border of the search area: the match may be beyond
    LOW_CORRELATION = 5  # best correlation below the minimum
    BACK_MATCH = 6  # the right -> left search did not return to the left point
    INCONSISTENT = 7  # its offset from the prediction disagrees with its neighbours'
    # codes from 16 on are set by the orientation steps
    ORIENTATION_OUTLIER = 16  # rejected by the relative orientation (residual over k sigma)



@dataclass(frozen=True, eq=False)
class Matches:
    """Every searched point: positions in full-image pixels, the correlation at the sub-pixel
    match, the back-match distance (left pixels), a :class:`TiePointStatus` code, the height
    the search was centred on (metres, ellipsoidal), the right position predicted there and
    the epipolar rate d(right col, row)/dh (pixels per metre)."""

    left_col: FloatArray
    left_row: FloatArray
    right_col: FloatArray
    right_row: FloatArray
    correlation: FloatArray
    back_error_px: FloatArray
    status: NDArray[np.uint8]
    h_m: FloatArray
    pred_col: FloatArray
    pred_row: FloatArray
    epipolar_col: FloatArray
    epipolar_row: FloatArray

    def with_status(self, index: ArrayLike, code: int) -> Matches:
        status = self.status.copy()
        status[np.asarray(index)] = np.uint8(code)
        return replace(self, status=status)

    @property
    def ok(self) -> NDArray[np.bool_]:
        return self.status == TiePointStatus.OK

    @classmethod
    def concat(cls, parts: list[Matches]) -> Matches:
        """The matches of several tiles as one set."""
        names = [f.name for f in cls.__dataclass_fields__.values()]
        if not parts:
            return cls(*(np.empty(0, np.uint8 if k == "status" else np.float64) for k in names))
        return cls(*(np.concatenate([getattr(p, k) for p in parts]) for k in names))


@dataclass(frozen=True, eq=False)
class TiePoints:
    """Tie points between a left and a right image (full-image pixels, (col, row) 0-based).

    ``correlation`` is the normalised cross-correlation at the match, ``status`` a
    :class:`TiePointStatus` code (0 = usable), ``cell_id`` the ground cell the point was kept
    for (-1 if none), ``h_m`` the height the search was centred on (reference DEM, ellipsoidal;
    NaN if unknown).
    """

    left_col: FloatArray
    left_row: FloatArray
    right_col: FloatArray
    right_row: FloatArray
    correlation: FloatArray
    status: NDArray[np.uint8] = field(default_factory=lambda: np.empty(0, np.uint8))
    cell_id: NDArray[np.int64] = field(default_factory=lambda: np.empty(0, np.int64))
    h_m: FloatArray = field(default_factory=lambda: np.empty(0))

    def __post_init__(self) -> None:
        n = np.size(self.left_col)
        optional = {"status": (np.uint8, 0), "cell_id": (np.int64, -1), "h_m": (np.float64, np.nan)}
        for name in (f.name for f in fields(self)):
            dtype, fill = optional.get(name, (np.float64, None))
            v = getattr(self, name)
            empty = fill is not None and np.size(v) == 0
            v = np.array(np.full(n, fill) if empty else v, dtype=dtype).ravel()
            if v.size != n:
                raise InputError(f"tie points: '{name}' has {v.size} values, expected {n}")
            v.setflags(write=False)
            object.__setattr__(self, name, v)

    def __len__(self) -> int:
        return int(self.left_col.size)

    @property
    def ok(self) -> NDArray[np.bool_]:
        """The usable points (status OK)."""
        return self.status == TiePointStatus.OK

    def with_status(self, index: ArrayLike, code: int | TiePointStatus) -> TiePoints:
        """A copy with the points ``index`` (boolean mask or indices) given ``code``."""
        status = self.status.copy()
        status[np.asarray(index)] = np.uint8(code)
        return replace(self, status=status)

    def subset(self, index: ArrayLike) -> TiePoints:
        """The points ``index`` (boolean mask or indices)."""
        return TiePoints(*(getattr(self, f.name)[np.asarray(index)] for f in fields(self)))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready, one list per column (floats written exactly, NaN as null)."""
        def floats(a: FloatArray) -> list[float | None]:
            return [float(v) if np.isfinite(v) else None for v in a]

        return {
            "type": "tie_points",
            "image_coordinates": "0-based, pixel centres at integers, (col, row)",
            "status_codes": {s.name: int(s) for s in TiePointStatus},
            "count": len(self),
            **{k: floats(getattr(self, k)) for k in _TP_FLOATS},
            "status": [int(v) for v in self.status],
            "cell_id": [int(v) for v in self.cell_id],
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> TiePoints:
        if not isinstance(d, Mapping) or d.get("type") != "tie_points":
            raise InputError("not a tie-point record (type 'tie_points' missing); give the "
                             "JSON written by TiePoints.to_dict")
        try:
            cols = {k: [np.nan if v is None else v for v in d[k]] for k in _TP_FLOATS}
            return cls(**cols, status=d["status"], cell_id=d["cell_id"])
        except KeyError as exc:
            raise InputError(f"tie-point record lacks the column {exc}; give the JSON "
                             "written by TiePoints.to_dict") from exc
        except (TypeError, ValueError) as exc:
            raise InputError(f"tie-point record has a malformed column: {exc}") from exc


_TP_FLOATS = ("left_col", "left_row", "right_col", "right_row", "correlation", "h_m")
_PERCENTILES = (5, 25, 50, 75, 95)


@dataclass(frozen=True)
class TiePointReport:
    """What the search found. ``n_candidates`` interest points were searched, ``n_matched``
    passed correlation and back-match, ``n_points`` were kept (one per cell). Of the
    ``n_cells`` ground cells of the overlap, ``n_cells_textured`` held an interest point and
    ``n_cells_with_point`` a tie point: ``coverage`` and ``coverage_textured`` are the shares.
    Correlation percentiles (5, 25, 50, 75, 95) are of the kept points, in the ``measure``
    they were matched with (``ncc`` or ``orientation``; a report written before the measure
    was recorded was NCC's); ``rejected`` counts the candidates per rejection status name."""

    n_points: int
    n_candidates: int
    n_matched: int
    n_cells: int
    n_cells_textured: int
    n_cells_with_point: int
    cell_m: float
    coverage: float
    coverage_textured: float
    correlation_p05: float
    correlation_p25: float
    correlation_p50: float
    correlation_p75: float
    correlation_p95: float
    rejected: dict[str, int] = field(default_factory=dict)
    measure: str = "ncc"

    def to_dict(self) -> dict[str, Any]:
        return {k: (dict(v) if isinstance(v, dict) else v) for k, v in self.__dict__.items()}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> TiePointReport:
        try:
            return cls(**{k: d[k] for k in cls.__dataclass_fields__ if k != "measure"},
                       measure=d.get("measure", "ncc"))
        except (KeyError, TypeError) as exc:
            raise InputError(f"tie-point report lacks {exc}; give the JSON written by "
                             "TiePointReport.to_dict") from exc

    def lines(self) -> list[str]:
        rejected = ", ".join(f"{k.lower()} {v}" for k, v in self.rejected.items()) or "none"
        return [
            (f"tie points     {self.n_points} kept (one per {self.cell_m:g} m cell) of "
             f"{self.n_matched} matched, {self.n_candidates} searched"),
            (f"coverage       {100 * self.coverage:.1f} % of {self.n_cells} overlap cells, "
             f"{100 * self.coverage_textured:.1f} % of the {self.n_cells_textured} textured"),
            (f"correlation    p5 {self.correlation_p05:.3f}  median {self.correlation_p50:.3f}"
             f"  p95 {self.correlation_p95:.3f} "
             f"({MEASURE_NAMES.get(self.measure, self.measure)})"),
            f"rejected       {rejected}",
        ]


def tiepoint_report(tie_points: TiePoints, candidate_status: ArrayLike,
                    candidate_cells: ArrayLike, overlap: ArrayLike, cell_m: float,
                    measure: str = "ncc") -> TiePointReport:
    """The report of a search: kept points, the status and cell id of every candidate searched
    (-1 for none), the ids of the overlap cells, the correlation measure."""
    st = np.asarray(candidate_status, dtype=np.uint8)
    overlap_ids = np.unique(np.asarray(overlap, dtype=np.int64))
    cand = np.asarray(candidate_cells, dtype=np.int64)
    textured = np.intersect1d(cand[cand >= 0], overlap_ids)
    kept = tie_points.cell_id[tie_points.ok]
    with_point = np.intersect1d(kept[kept >= 0], overlap_ids)
    corr = tie_points.correlation[tie_points.ok]
    q = (np.percentile(corr, _PERCENTILES) if corr.size else np.full(len(_PERCENTILES), np.nan))
    rejected = {s.name: int(np.sum(st == s)) for s in TiePointStatus
                if s != TiePointStatus.OK and np.any(st == s)}
    return TiePointReport(
        n_points=int(np.sum(tie_points.ok)), n_candidates=int(st.size),
        n_matched=int(np.sum(st == TiePointStatus.OK)), n_cells=int(overlap_ids.size),
        n_cells_textured=int(textured.size), n_cells_with_point=int(with_point.size),
        cell_m=float(cell_m), coverage=float(with_point.size / max(overlap_ids.size, 1)),
        coverage_textured=float(with_point.size / max(textured.size, 1)),
        correlation_p05=float(q[0]), correlation_p25=float(q[1]), correlation_p50=float(q[2]),
        correlation_p75=float(q[3]), correlation_p95=float(q[4]), rejected=rejected,
        measure=measure,
    )


@dataclass(frozen=True, eq=False)
class TiePointResult:
    """Tie points and their report, as a task returns them."""

    tie_points: TiePoints
    report: TiePointReport

    def to_dict(self) -> dict[str, Any]:
        return {"report": self.report.to_dict(), "tie_points": self.tie_points.to_dict()}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> TiePointResult:
        try:
            return cls(TiePoints.from_dict(d["tie_points"]),
                       TiePointReport.from_dict(d["report"]))
        except (KeyError, TypeError) as exc:
            raise InputError(f"tie-point result lacks {exc}; give the JSON written by "
                             "TiePointResult.to_dict") from exc
