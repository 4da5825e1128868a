"""The block's ``report.html`` (``gcpfree block``): what ``report.json`` holds, for a person.

One self-contained page (figures as inline PNG, no file beside it): the block's map (each
image's footprint from the catalog, the tie-point graph between them, the GCPs used and
rejected), the check points and predicted RMS per image (when check points were given), the
GCPs' residuals per image, and the tables: images (how each is held, its GCPs and tie points,
its predicted accuracy, its RPC export), stereo pairs (B/H, relief verdict, GCPs, DSM), the
adjustment (sigma0, variance components, frames) and the fused DSM. Reads the products, draws,
computes nothing.
"""

from __future__ import annotations

import base64
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure as MplFigure
from prefect import task
from prefect.cache_policies import NO_CACHE

from core.jsonio import parse_json
from tasks.archive.scene_catalog import SceneEntry
from tasks.io.rasters import atomic_write_text
from tasks.report.doc import Block, Figure, Heading, Para, Table, fmt, to_html
from tasks.report.figures import png_bytes

DATE_COLOURS = ("#1f77b4", "#d55e00", "#2a9d2a", "#9467bd", "#e69f00", "#56b4e9")


def _triple(v: Sequence[float] | None) -> str:
    return "–" if not v else ", ".join(f"{x:.1f}" for x in v)


def _figure(fig: MplFigure, caption: str) -> Figure:
    """The figure inline (a data URI): the page needs no file beside it."""
    data = base64.b64encode(png_bytes(fig)).decode("ascii")
    return Figure(f"data:image/png;base64,{data}", caption)


def _date_of(name: str, names: Sequence[str]) -> int:
    """A colour index per acquisition: the simulator's ``...dK`` suffix, else the image's
    rank."""
    tail = name.rsplit("d", 1)
    return int(tail[1]) if len(tail) == 2 and tail[1].isdigit() else names.index(name)


def block_map(report: Mapping[str, Any], scenes: Mapping[str, SceneEntry],
              gcps: Sequence[Mapping[str, Any]]) -> MplFigure:
    """Footprints, tie-point graph (a line between two images' centres, as wide as their tie
    points are many), GCPs used and rejected, lon / lat."""
    fig = MplFigure(figsize=(7.5, 6.5))
    ax = fig.add_subplot()
    names = [im["name"] for im in report["images"]]
    centre = {}
    ties_only = set(report.get("connectivity", {}).get("ties_only", []))
    for name in names:
        ring = np.asarray(scenes[name].footprint if name in scenes else (), dtype=float)
        if ring.size == 0:
            continue
        colour = DATE_COLOURS[_date_of(name, names) % len(DATE_COLOURS)]
        closed = np.vstack([ring, ring[:1]])
        ax.plot(closed[:, 0], closed[:, 1], color=colour, ls="--" if name in ties_only else "-",
                lw=1.2)
        centre[name] = ring.mean(axis=0)
        ax.annotate(name, centre[name], fontsize=7, ha="center", va="center", color=colour)
    links = report.get("connectivity", {}).get("links", [])
    most = max([lk["tie_points"] for lk in links] + [1])
    for lk in links:
        a, b = lk["images"]
        if a in centre and b in centre:
            xy = np.array([centre[a], centre[b]])
            ax.plot(xy[:, 0], xy[:, 1], color="#555", alpha=0.5,
                    lw=0.5 + 3.0 * lk["tie_points"] / most)
    rejected = {r["id"] if isinstance(r, Mapping) else r
                for r in report.get("gcps", {}).get("rejected_ids", [])}
    for label, colour, keep in (("GCPs used", "#2a9d2a", False), ("rejected", "#cc0000", True)):
        pts = [(p["lon_deg"], p["lat_deg"]) for p in gcps if (p["id"] in rejected) == keep]
        if pts:
            xy = np.asarray(pts)
            ax.scatter(xy[:, 0], xy[:, 1], s=6 if not keep else 14, c=colour,
                       marker="o" if not keep else "x", label=f"{label} ({len(pts)})")
    ax.set_xlabel("longitude (deg)")
    ax.set_ylabel("latitude (deg)")
    ax.set_aspect(1.0 / np.cos(np.radians(np.mean([c[1] for c in centre.values()] or [0.0]))))
    ax.set_title("footprints (dashed: held by tie points only), tie-point graph, GCPs",
                 fontsize=9)
    if gcps:
        ax.legend(fontsize=7, loc="best")
    return fig


def per_image_bars(rows: Sequence[tuple[str, float, float, float, float]], title: str,
                   predicted: bool) -> MplFigure:
    """Columns and rows per image (px), with the predicted RMS as ticks when ``predicted``."""
    fig = MplFigure(figsize=(7.5, 3.2))
    ax = fig.add_subplot()
    x = np.arange(len(rows))
    col = [r[1] for r in rows]
    row = [r[2] for r in rows]
    ax.bar(x - 0.2, col, 0.4, label="columns", color="#1f77b4")
    ax.bar(x + 0.2, row, 0.4, label="rows", color="#e69f00")
    if predicted:
        ax.scatter(x - 0.2, [r[3] for r in rows], marker="_", s=250, c="k", label="predicted")
        ax.scatter(x + 0.2, [r[4] for r in rows], marker="_", s=250, c="k")
    ax.set_xticks(x, [r[0] for r in rows], rotation=45, ha="right", fontsize=7)
    ax.set_ylabel("RMS (px)")
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=7)
    return fig


def block_html(report: Mapping[str, Any], scenes: Mapping[str, SceneEntry],
               gcps: Sequence[Mapping[str, Any]]) -> str:
    """The page's HTML (:func:`tasks.report.doc.to_html`, as the pair's report)."""
    images, pairs = report["images"], report["pairs"]
    checks = report.get("check_points") or {}
    adj = report.get("adjustment", {})
    g, t = report.get("gcps", {}), report.get("tie_points", {})
    blocks: list[Block] = [
        Para(f"GCPs {fmt(g.get('used'))} used of {fmt(g.get('given'))}; tie points "
             f"{fmt(t.get('n'))} (parallax {fmt(t.get('rms_px'))} px RMS); sigma0 "
             f"{fmt(adj.get('sigma0'))}; fused DSM "
             f"{fmt(report.get('dsm', {}).get('completeness_pct'))} % complete."),
        Heading("Map"), _figure(block_map(report, scenes, gcps),
                                "footprints, tie-point graph, GCPs used and rejected")]
    if checks:
        rows = [(n, c["rms_col_px"], c["rms_row_px"], c.get("predicted_rms_col_px", np.nan),
                 c.get("predicted_rms_row_px", np.nan)) for n, c in checks.items()]
        blocks += [Heading("Check points"),
                   _figure(per_image_bars(rows, "check points: measured RMS and predicted", True),
                           "check points per image: measured RMS, predicted as ticks"),
                   Table.of(["image", "n", "RMS col px", "RMS row px", "predicted col",
                             "predicted row"],
                            [(n, c["n"], c["rms_col_px"], c["rms_row_px"],
                              c.get("predicted_rms_col_px"), c.get("predicted_rms_row_px"))
                             for n, c in checks.items()])]
    res = [(im["name"], *(im.get("residual_rms_px") or (np.nan, np.nan)), np.nan, np.nan)
           for im in images]
    blocks += [Heading("Images"),
               _figure(per_image_bars(res, "GCP residuals per image (RMS)", False),
                       "GCP residuals per image"),
               Table.of(["image", "held by", "GCPs", "tie points", "GCP RMS col px",
                         "GCP RMS row px", "predicted col px", "predicted row px",
                         "RPC fit px"],
                        [(im["name"], im.get("held_by"), im.get("gcps"), im.get("tie_points"),
                          *(im.get("residual_rms_px") or (None, None)),
                          (im.get("predicted") or {}).get("predicted_rms_col_px"),
                          (im.get("predicted") or {}).get("predicted_rms_row_px"),
                          (im.get("rpc_export") or {}).get("fit_rms_px")) for im in images]),
               Heading("Stereo pairs"),
               Table.of(["pair", "images", "B/H", "windows OK", "GCPs", "relief m", "DSM"],
                        [(p["id"], " / ".join(p["images"]), p.get("b_over_h"),
                          (p.get("windows") or {}).get("OK"), p.get("gcps"),
                          (p.get("verdict") or {}).get("relief_found_m"), p.get("dsm"))
                         for p in pairs])]
    vc = adj.get("variance_components") or {}
    if vc.get("groups"):
        blocks += [Heading("Variance components"),
                   Table.of(["group", "n", "factor", "sigma scale", "redundancy"],
                            [(k, c["n"], c["factor"], c["sigma_scale"], c["redundancy"])
                             for k, c in vc["groups"].items()]),
                   Para(str(vc.get("split", "")))]
    frames = report.get("frames") or []
    if frames:
        blocks += [Heading("Frames"),
                   Table.of(["frame", "prior sigma m (E, N, U)", "shift m (E, N, U)",
                             "sigma m (E, N, U)", "observed", "source"],
                            [(f.get("name"), _triple(f.get("prior_sigma_m")),
                              _triple(f.get("shift_m")), _triple(f.get("sigma_m")),
                              f.get("observed"), f.get("source")) for f in frames])]
    blocks.append(Para("All figures from report.json, gcps.json and the catalog's footprints "
                       "(gcpfree block)."))
    return to_html(f"Block: {len(images)} images, {len(pairs)} stereo pairs", blocks)


@task(name="write-block-html", cache_policy=NO_CACHE)
def write_block_html(out: Path, scenes: Sequence[SceneEntry]) -> Path:
    """``out/report.html`` from ``out/report.json`` and ``out/gcps.json`` (written
    atomically)."""
    out = Path(out)
    report = parse_json((out / "report.json").read_text(encoding="utf-8"), "report.json")
    gcp_path = out / "gcps.json"
    gcps = (parse_json(gcp_path.read_text(encoding="utf-8"), "gcps.json").get("points", [])
            if gcp_path.is_file() else [])
    return atomic_write_text(out / "report.html",
                             block_html(report, {s.id: s for s in scenes}, gcps))
