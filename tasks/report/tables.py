"""The tables of the run report: the numbers of ``report.json`` (its typed sections,
:mod:`tasks.absolute.report`), of ``windows.json`` and ``eval.json`` as blocks of
:mod:`tasks.report.doc`, every one of them but the relative orientation's, which is curated (its
full record is rel.json). Plain functions: no I/O, no figures (those are
:mod:`tasks.report.build`)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

from tasks.absolute.report import OrientReport
from tasks.io.documents import plain
from tasks.report.doc import Block, Para, Table, flatten, fmt

if TYPE_CHECKING:
    from core.matching.relief import ReliefVerdict
    from core.orientation.checkpoints import CheckPointStats
    from tasks.absolute.report import Absolute, GcpSummary, SurfaceMatching
    from tasks.dense.dem import DemSummary

STATS = ("n", "min_col_px", "max_col_px", "mean_col_px", "std_col_px", "rms_col_px",
         "min_row_px", "max_row_px", "mean_row_px", "std_row_px", "rms_row_px")
WINDOW_KEYS = ("tie_point", "status", "shift_lon_arcsec", "shift_lat_arcsec", "shift_h_m",
               "shift_east_m", "shift_north_m", "correlation", "precision_m", "precision_h_m",
               "predicted_precision_m", "relief_m", "rms_slope", "n_cells", "masked_share")
EVAL_KEYS = ("count", "mean", "std", "rmse", "nmad", "le68", "le90")
PARAMS = ("param_names", "param_units", "params_before", "params_after", "sigmas")
# the top-level keys of report.json given their own section
SECTIONS = OrientReport.SECTIONS

Doc = Mapping[str, Any]


def _cell(v: Any) -> str:
    """A value in a table cell: a number, or a short list, a nested value flattened."""
    rows = flatten({"v": v})
    return "; ".join(f"{k[2:]}: {x}" if len(rows) > 1 else x for k, x in rows) or "–"


def relative_tables(rel: Doc) -> list[Block]:
    """rel.json as a photogrammetrist reads it: the tie points (how many, how spread, how well
    matched), the y-parallax before and after, how far the right image moved across and along
    the epipolar lines and what fixed each part, the rays' miss distance, the main angle solved
    point by point (Goncalves's Table 1); then the right image's parameters with their sigmas.
    The rest of rel.json (every count of the search, the covariance, the unobservable
    directions, the adjusted right model) stays in the file, as the report says."""
    adj, search = rel.get("adjustment", {}), rel.get("tie_point_search", {})
    corr, miss = rel.get("right_correction", {}), rel.get("miss_distance_m", {})
    rejected = search.get("rejected")
    rows = [
        ["sensor models left / right",
         _slash(rel.get("left", {}).get("family"), rel.get("right", {}).get("family"))],
        ["tie points used / rejected",
         _slash(rel.get("tie_points"), rel.get("tie_points_rejected"))],
        ["tie-point grid: one point per ground cell of (m)", fmt(search.get("cell_m"))],
        ["ground cells with a tie point / with texture / in all",
         _slash(search.get("n_cells_with_point"), search.get("n_cells_textured"),
                search.get("n_cells"))],
        ["interest points searched / matched",
         _slash(search.get("n_candidates"), search.get("n_matched"))],
        ["interest points rejected, by reason",
         ", ".join(f"{k.lower().replace('_', ' ')} {fmt(v)}" for k, v in rejected.items())
         if isinstance(rejected, Mapping) and rejected else "(none)"],
        ["tie-point correlation: median (5 % .. 95 %)",
         (f"{fmt(search.get('correlation_p50'))} ({fmt(search.get('correlation_p05'))} .. "
          f"{fmt(search.get('correlation_p95'))})")],
        ["y-parallax RMS before / after (px)",
         _slash(rel.get("parallax_rms_before_px"), rel.get("parallax_rms_after_px"))],
        ["robust sigma of the y-parallaxes after (px)", fmt(adj.get("sigma_px"))],
        ["iterations / converged", _slash(adj.get("n_iterations"), adj.get("converged"))],
        ["right image moved at its centre: across / along the epipolar line (px)",
         _slash(corr.get("across_epipolar_px"), corr.get("along_epipolar_px"))],
        *_along_epipolar_rows(rel),
        ["rays' miss distance at the tie points: median / 95 % (m)",
         _slash(miss.get("median"), miss.get("p95"))],
    ]
    ref = rel.get("reference")
    if isinstance(ref, Mapping):  # the reference DEM the orientation read, and its datum
        rows.append(["reference DEM: vertical datum (decided by)",
                     f"{ref.get('path')}: {ref.get('vertical')} ({ref.get('vertical_source')})"])
    pa = adj.get("point_angle")
    if isinstance(pa, Mapping):
        rows.append(["main parameter solved point by point (Goncalves's Table 1)",
                     (f"{pa.get('name')}: {fmt(pa.get('mean'))} ± {fmt(pa.get('std'))} "
                      f"{pa.get('unit')}, {fmt(pa.get('min'))} .. {fmt(pa.get('max'))} "
                      f"({fmt(pa.get('count'))} points)")])
    out: list[Block] = [Table(("", "value"), tuple(tuple(r) for r in rows),
                              "Tie points and the right image adjusted to the left")]
    if "param_names" in adj:
        names = adj["param_names"]
        units = adj.get("param_units") or [""] * len(names)
        out.append(Table.of(("parameter", "unit", "before", "after", "sigma"),
                            zip(names, units, adj["params_before"], adj["params_after"],
                                _sigmas(adj.get("covariance"), len(names)), strict=True),
                            "Right-image parameters from the tie points (sigma: the "
                            "adjustment's, within the directions the tie points see)"))
    out.append(Para("Every count of the tie-point search, the covariance, the unobservable "
                    "directions and the adjusted right model are in relative/rel.json."))
    return out


def _slash(*values: Any) -> str:
    return " / ".join(fmt(v) for v in values)


def _sigmas(covariance: Any, n: int) -> list[float | None]:
    """The square roots of a covariance matrix's diagonal (None when there is none)."""
    if not isinstance(covariance, Sequence) or len(covariance) != n or not all(
            isinstance(row, Sequence) and len(row) == n for row in covariance):
        return [None] * n
    return [math.sqrt(v) if isinstance(v := row[i], (int, float)) and v >= 0 else None
            for i, row in enumerate(covariance)]


def _along_epipolar_rows(rel: Doc) -> list[list[str]]:
    """What fixed the right image along the epipolar lines: the tie points when they see it;
    otherwise the reference DEM (the shift it set with its sigma, from the tie points' heights
    against it), or nothing (held at the metadata)."""
    unobservable = rel.get("adjustment", {}).get("unobservable") or []
    along = rel.get("along_epipolar") or {}
    if not unobservable:
        return [["along the epipolar line", "seen by the tie points"]]
    mostly = ", ".join(dict.fromkeys(
        max(u["direction"], key=lambda k: abs(u["direction"][k])) for u in unobservable
        if u.get("direction")))
    n = len(unobservable)
    rows = [["along the epipolar line: seen by the tie points",
             f"no: {n} direction{'s' if n != 1 else ''} held (mostly {mostly})"]]
    if along.get("sigma_px") is None:
        return [*rows, ["along the epipolar line: set from the reference DEM",
                        ("no: held at the metadata (no reference DEM heights at 3 tie points "
                         "or more)")]]
    return [*rows,
            ["along the epipolar line: set from the reference DEM (px)",
             f"{fmt(along.get('shift_px'))} ± {fmt(along.get('sigma_px'))}"],
            ["tie-point heights - reference before, median (m) / reference sigma (m) / points",
             _slash(along.get("height_offset_m"), along.get("reference_sigma_m"),
                    along.get("n_points"))]]


def dem_tables(dem: DemSummary) -> list[Block]:
    """The relative DEM's summary and one row per tile."""
    out: list[Block] = [Table.flat(dem.to_dict(), "Relative DEM", skip=("tiles",))]
    if dem.tiles:
        keys = list(dict.fromkeys(k for t in dem.tiles for k in t))
        out.append(Table.of(keys, ([_cell(t.get(k)) for k in keys] for t in dem.tiles),
                            "Relative DEM tiles"))
    return out


def relief_verdict(v: ReliefVerdict) -> Para:
    """The relief-sufficiency verdict in a sentence (green when enough)."""
    text = (f"{fmt(v.n_qualified)} of {fmt(v.n_windows)} windows have the relief to fix the "
            f"position to {fmt(v.max_precision_m)} m ({fmt(v.n_needed)} needed); relief found "
            f"{fmt(v.relief_found_m)} m (median std of heights per window), needed about "
            f"{fmt(v.relief_needed_m)} m.")
    return Para(("Relief sufficient: " if v.enough else "Relief insufficient: ") + text,
                "good" if v.enough else "bad")


def surface_tables(sm: SurfaceMatching, windows: Sequence[Doc] | None) -> list[Block]:
    out: list[Block] = [relief_verdict(sm.relief),
                        Table.flat(plain(sm), "Surface matching and relief verdict")]
    if windows is not None:
        out.append(Table.of(WINDOW_KEYS, ([w.get(k) for k in WINDOW_KEYS] for w in windows),
                            "Windows (windows.json; shifts move the relative DEM onto the "
                            "reference)"))
    return out


def gcp_tables(g: GcpSummary) -> list[Block]:
    out: list[Block] = [Table.flat(plain(g), "Simulated GCPs", skip=("rejected_ids",))]
    if g.rejected_ids:
        out.append(Table.of(("GCP id", "reason"), ((r.id, r.reason) for r in g.rejected_ids),
                            "GCPs rejected by the absolute orientation"))
    return out


def absolute_tables(a: Absolute) -> list[Block]:
    """Per image its parameters before and after with their sigmas and its GCP residuals; the
    adjustment's figures; the lens self-calibration."""
    out: list[Block] = []
    for name, img in a.images.items():
        out.append(Table.of(("parameter", "before", "after", "sigma"),
                            zip(img.param_names, img.params_before, img.params_after,
                                img.sigmas, strict=True),
                            f"Image {name}: parameters adjusted"))
        out.append(Table.flat(plain(img), f"Image {name}: residuals at the GCPs used (px)",
                              skip=PARAMS))
    out.append(Table.flat(plain(a), "Absolute adjustment",
                          skip=("images", "self_calibration")))
    if a.self_calibration is not None:
        out.append(Table.flat(plain(a.self_calibration), "Lens self-calibration"))
    else:
        out.append(Para("Lens self-calibration was not asked for."))
    return out


def check_point_table(after: Mapping[str, CheckPointStats],
                      before: Mapping[str, CheckPointStats] | None) -> Table:
    """The paper's Table 2: check-point residual statistics per image, before (relative
    orientation only) and after the absolute orientation."""
    rows = []
    for name in after:
        for stage, s in (("before", (before or {}).get(name)), ("after", after[name])):
            if s is not None:
                rows.append([name, stage, *(getattr(s, k) for k in STATS)])
    return Table.of(("image", "orientation", *STATS), rows,
                    "Check-point residuals (measured - projected, px; col = P, row = L); "
                    "before: relative orientation only")


def prediction_table(after: Mapping[str, CheckPointStats],
                     absolute: Absolute | None = None,
                     registration: Mapping[str, Any] | None = None) -> Table:
    """The check points measured against what the orientation predicted there, in total and
    in its two parts: relative to the control's frames (what the method achieves) and the
    frames' own registration carried through the models (the reference's, from its producer's
    statement or ``--reference-sigma``; another frame's where one was used); with the frames
    the adjustment estimated and, where it was observable, the reference's own shift."""
    rows = []
    for name, s in after.items():
        if s.predicted_relative_rms_col_px is None:  # a report of an earlier version
            continue
        for ax, key in (("col", "P"), ("row", "L")):
            rows.append([name, key, getattr(s, f"rms_{ax}_px"),
                         getattr(s, f"predicted_rms_{ax}_px"),
                         getattr(s, f"predicted_relative_rms_{ax}_px"),
                         getattr(s, f"predicted_reference_rms_{ax}_px")])
    frames = "; ".join(
        f"{f.name}: prior {'/'.join(fmt(v) for v in f.prior_sigma_m)} m"
        + (f", shift {'/'.join(fmt(v) for v in f.shift_m)} +- "
           f"{'/'.join(fmt(v) for v in f.sigma_m)} m" if f.observed else
           " (not observable: its prior stands)")
        for f in ((absolute.frames or ()) if absolute is not None else ()))
    shift = ""
    if registration:
        shift = (f"; the reference's own shift (east / north / up, m): "
                 f"{'/'.join(fmt(v) for v in registration.get('shift_m', []))} +- "
                 f"{'/'.join(fmt(v) for v in registration.get('sigma_m', []))}, removed")
    return Table.of(("image", "axis", "measured RMS", "predicted", "of which relative",
                     "of which reference"), rows,
                    "Check points: measured against predicted (px; predicted^2 = relative^2 "
                    "+ reference^2)" + (f". Frames: {frames}" if frames else "") + shift)


def evaluation_tables(ev: Doc) -> list[Block]:
    """eval.json: per class and overall, then where the points went and the inputs."""
    labels = ev.get("class_labels") or {}
    stats = {**ev["classes"], **({"all": ev["all"]} if ev.get("all") else {})}
    out: list[Block] = [Table.of(
        ("class", "label", *EVAL_KEYS, "le68 interval"),
        ([k, labels.get(k, ""), *(s.get(k) for k in EVAL_KEYS),
          " .. ".join(fmt(v) for v in s.get("le68_ci") or [])] for k, s in stats.items()),
        "DEM - lidar per class (m)" + (f": {ev['dz']}" if ev.get("dz") else ""))]
    for key in ("points", "inputs", "heights_compared", "transformation", "mask", "gcps"):
        if ev.get(key):
            out.append(Table.flat({key: ev[key]}, f"Evaluation: {key.replace('_', ' ')}"))
    return out


def summary_table(r: OrientReport | None) -> Table:
    """The run at a glance (dashes where the orientation's report is not available)."""
    rel = r.relative if r is not None else {}
    rows = [["tie points used / rejected",
             f"{fmt(rel.get('tie_points'))} / {fmt(rel.get('tie_points_rejected'))}"],
            ["y-parallax RMS before / after (px)",
             (f"{fmt(rel.get('parallax_rms_before_px'))} / "
              f"{fmt(rel.get('parallax_rms_after_px'))}")]]
    if r is None:
        rows += [["windows / matched / qualified by relief", _slash(None, None, None)],
                 ["GCPs given / used / rejected", _slash(None, None, None)]]
        return Table(("", "value"), tuple(tuple(x) for x in rows))
    sm, g = r.surface_matching, r.gcps
    rows += [["windows / matched / qualified by relief",
              f"{fmt(sm.windows)} / {fmt(sm.counts.get('OK'))} / {fmt(sm.qualified)}"],
             ["GCPs given / used / rejected",
              f"{fmt(g.given)} / {fmt(g.used)} / {fmt(g.rejected)}"]]
    for name, a in r.absolute.images.items():
        rows.append([f"GCP residual RMS {name}: col / row (px)",
                     f"{fmt(a.rms_col_px)} / {fmt(a.rms_row_px)}"])
    for stage, stats in (("before", r.check_points_before), ("after", r.check_points)):
        for name, c in (stats or {}).items():
            rows.append([f"check-point RMS {name} {stage}: col / row (px)",
                         f"{fmt(c.rms_col_px)} / {fmt(c.rms_row_px)} ({fmt(c.n)} points)"])
    return Table(("", "value"), tuple(tuple(x) for x in rows))
