"""The tables of the run report: every number of ``report.json`` (and of ``windows.json`` and
``eval.json``) as blocks of :mod:`tasks.report_doc`. Plain functions of the JSON documents: no
I/O, no figures (those are :mod:`tasks.report`)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from tasks.report_doc import Block, Para, Table, flatten, fmt

STATS = ("n", "min_col_px", "max_col_px", "mean_col_px", "std_col_px", "rms_col_px",
         "min_row_px", "max_row_px", "mean_row_px", "std_row_px", "rms_row_px")
WINDOW_KEYS = ("tie_point", "status", "shift_lon_arcsec", "shift_lat_arcsec", "shift_h_m",
               "shift_east_m", "shift_north_m", "correlation", "precision_m", "precision_h_m",
               "predicted_precision_m", "relief_m", "rms_slope", "n_cells", "masked_share")
EVAL_KEYS = ("count", "mean", "std", "rmse", "nmad", "le68", "le90")
PARAMS = ("param_names", "param_units", "params_before", "params_after", "sigmas")
# the top-level keys of report.json given their own section
SECTIONS = ("format", "version", "relative", "relative_dem", "surface_matching", "gcps",
            "absolute", "check_points", "check_points_before")

Doc = Mapping[str, Any]


def _cell(v: Any) -> str:
    """A value in a table cell: a number, or a short list, a nested value flattened."""
    rows = flatten({"v": v})
    return "; ".join(f"{k[2:]}: {x}" if len(rows) > 1 else x for k, x in rows) or "–"


def relative_tables(rel: Doc) -> list[Block]:
    """rel.json: its figures, the right model's adjustment and the right model after it."""
    adj = rel.get("adjustment", {})
    out: list[Block] = [Table.flat(rel, "Relative orientation (rel.json)",
                                   skip=("adjustment", "right_model"))]
    if "param_names" in adj:
        units = adj.get("param_units") or [""] * len(adj["param_names"])
        out.append(Table.of(("parameter", "unit", "before", "after"),
                            zip(adj["param_names"], units, adj["params_before"],
                                adj["params_after"], strict=True),
                            "Right image adjusted to the left (relative orientation)"))
    out.append(Table.flat(adj, "Relative adjustment", skip=PARAMS))
    if "right_model" in rel:
        out.append(Table.flat(rel["right_model"], "Right model after the relative orientation"))
    return out


def dem_tables(dem: Doc) -> list[Block]:
    """The relative DEM's summary and one row per tile."""
    out: list[Block] = [Table.flat(dem, "Relative DEM", skip=("tiles",))]
    tiles = dem.get("tiles") or []
    if tiles:
        keys = list(dict.fromkeys(k for t in tiles for k in t))
        out.append(Table.of(keys, ([_cell(t.get(k)) for k in keys] for t in tiles),
                            "Relative DEM tiles"))
    return out


def relief_verdict(v: Doc) -> Para:
    """The relief-sufficiency verdict in a sentence (green when enough)."""
    text = (f"{fmt(v.get('n_qualified'))} of {fmt(v.get('n_windows'))} windows have the relief "
            f"to fix the position to {fmt(v.get('max_precision_m'))} m "
            f"({fmt(v.get('n_needed'))} needed); relief found {fmt(v.get('relief_found_m'))} m "
            f"(median std of heights per window), needed about "
            f"{fmt(v.get('relief_needed_m'))} m.")
    enough = bool(v.get("enough"))
    return Para(("Relief sufficient: " if enough else "Relief insufficient: ") + text,
                "good" if enough else "bad")


def surface_tables(sm: Doc, windows: Sequence[Doc] | None) -> list[Block]:
    out: list[Block] = [relief_verdict(sm.get("relief", {})),
                        Table.flat(sm, "Surface matching and relief verdict")]
    if windows is not None:
        out.append(Table.of(WINDOW_KEYS, ([w.get(k) for k in WINDOW_KEYS] for w in windows),
                            "Windows (windows.json; shifts move the relative DEM onto the "
                            "reference)"))
    return out


def gcp_tables(g: Doc) -> list[Block]:
    out: list[Block] = [Table.flat(g, "Simulated GCPs", skip=("rejected_ids",))]
    if g.get("rejected_ids"):
        out.append(Table.of(("GCP id", "reason"),
                            ((r.get("id"), r.get("reason")) for r in g["rejected_ids"]),
                            "GCPs rejected by the absolute orientation"))
    return out


def absolute_tables(a: Doc) -> list[Block]:
    """Per image its parameters before and after with their sigmas and its GCP residuals; the
    adjustment's figures; the lens self-calibration."""
    out: list[Block] = []
    for name, img in a.get("images", {}).items():
        out.append(Table.of(("parameter", "before", "after", "sigma"),
                            zip(img["param_names"], img["params_before"], img["params_after"],
                                img["sigmas"], strict=True),
                            f"Image {name}: parameters adjusted"))
        out.append(Table.flat(img, f"Image {name}: residuals at the GCPs used (px)",
                              skip=PARAMS))
    out.append(Table.flat(a, "Absolute adjustment", skip=("images", "self_calibration")))
    if a.get("self_calibration") is not None:
        out.append(Table.flat(a["self_calibration"], "Lens self-calibration"))
    else:
        out.append(Para("Lens self-calibration was not asked for."))
    return out


def check_point_table(after: Doc, before: Doc | None) -> Table:
    """The paper's Table 2: check-point residual statistics per image, before (relative
    orientation only) and after the absolute orientation."""
    rows = []
    for name in after:
        for stage, d in (("before", (before or {}).get(name)), ("after", after[name])):
            if d is not None:
                rows.append([name, stage, *(d.get(k) for k in STATS)])
    return Table.of(("image", "orientation", *STATS), rows,
                    "Check-point residuals (measured - projected, px; col = P, row = L); "
                    "before: relative orientation only")


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


def summary_table(d: Doc) -> Table:
    """The run at a glance."""
    rel, sm, g = d.get("relative", {}), d.get("surface_matching", {}), d.get("gcps", {})
    rows = [["tie points used / rejected",
             f"{fmt(rel.get('tie_points'))} / {fmt(rel.get('tie_points_rejected'))}"],
            ["y-parallax RMS before / after (px)",
             (f"{fmt(rel.get('parallax_rms_before_px'))} / "
              f"{fmt(rel.get('parallax_rms_after_px'))}")],
            ["windows / matched / qualified by relief",
             (f"{fmt(sm.get('windows'))} / {fmt(sm.get('counts', {}).get('OK'))} / "
              f"{fmt(sm.get('qualified'))}")],
            ["GCPs given / used / rejected",
             f"{fmt(g.get('given'))} / {fmt(g.get('used'))} / {fmt(g.get('rejected'))}"]]
    for name, a in d.get("absolute", {}).get("images", {}).items():
        rows.append([f"GCP residual RMS {name}: col / row (px)",
                     f"{fmt(a.get('rms_col_px'))} / {fmt(a.get('rms_row_px'))}"])
    for stage, key in (("before", "check_points_before"), ("after", "check_points")):
        for name, c in (d.get(key) or {}).items():
            rows.append([f"check-point RMS {name} {stage}: col / row (px)",
                         (f"{fmt(c.get('rms_col_px'))} / {fmt(c.get('rms_row_px'))} "
                          f"({fmt(c.get('n'))} points)")])
    return Table(("", "value"), tuple(tuple(r) for r in rows))
