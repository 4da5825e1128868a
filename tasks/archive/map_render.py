"""Drawing the archive's map (:class:`tasks.archive.map.ArchiveMap`): one SVG of two panels (the
pairs coloured by status, and by the accuracy their orientation states), the page
``map.html`` around it, and the markdown of the Prefect artifact. Self-contained: the
hillshade is a PNG inside the SVG, text in the viewer's own sans-serif font, no script, nothing
fetched. Plain strings, no I/O."""

from __future__ import annotations

import base64
import math
from html import escape
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from core.sensors.viewing import polygon_centroid, signed_area

if TYPE_CHECKING:
    from tasks.archive.map import ArchiveMap, PairState

STATUS_COLOURS = {"done": "#2e8b57", "refused": "#e69f00", "failed": "#d62728",
                  "running": "#0072b2", "queued": "#bdbdbd"}
STATUS_WORDS = {"done": "done", "refused": "refused (the reason: hover, or the table)",
                "failed": "failed", "running": "running on a worker",
                "queued": "queued (submitted, not started)"}
#: the stated check-point RMS (worst image and axis, px): upper bounds and colours
ACCURACY_BINS = ((0.25, "#1a9850"), (0.5, "#a6d96a"), (1.0, "#fee08b"), (2.0, "#fc8d59"),
                 (math.inf, "#d73027"))
NO_FIGURE = "#ffffff"
PANEL_W, PANEL_H_MAX, PAD, TITLE_H, LEGEND_H = 520.0, 620.0, 12.0, 26.0, 130.0


# ----------------------------------------------------------------------------- numbers


def seconds_text(s: float | None) -> str:
    """``42 s``, ``3 min 10 s``, ``2 h 05 min``; an en dash when unknown."""
    if s is None or not math.isfinite(s):
        return "–"
    if s < 60:
        return f"{s:.0f} s" if s >= 10 else f"{s:.1f} s"
    m, sec = divmod(round(s), 60)
    if m < 60:
        return f"{m} min {sec:02d} s"
    h, m = divmod(m, 60)
    return f"{h} h {m:02d} min"


def px_text(v: float | None) -> str:
    return "–" if v is None else f"{v:.2f} px"


def accuracy_bin(v: float | None) -> int | None:
    """Index in :data:`ACCURACY_BINS` of a stated RMS, None without one."""
    if v is None:
        return None
    return next(i for i, (hi, _) in enumerate(ACCURACY_BINS) if v <= hi)


def _bin_label(i: int) -> str:
    lo = 0.0 if i == 0 else ACCURACY_BINS[i - 1][0]
    hi = ACCURACY_BINS[i][0]
    return f"≤ {hi:g} px" if i == 0 else f"> {lo:g} px" if math.isinf(hi) else \
        f"{lo:g}–{hi:g} px"


# ----------------------------------------------------------------------------- the SVG


class _Frame:
    """lon/lat -> panel pixels: equirectangular at the box's mean latitude, fitted into the
    panel and centred."""

    def __init__(self, box: tuple[float, float, float, float]) -> None:
        self.lon0, self.lat0, lon1, self.lat1 = box
        self.k = math.cos(math.radians(0.5 * (self.lat0 + self.lat1)))
        w, h = (lon1 - self.lon0) * self.k, self.lat1 - self.lat0
        self.height = min(PANEL_H_MAX, max(240.0, PANEL_W * h / w))
        self.s = min(PANEL_W / w, self.height / h)
        self.dx, self.dy = 0.5 * (PANEL_W - w * self.s), 0.5 * (self.height - h * self.s)
        self.m_per_px = 111_195.0 / self.s  # metres of latitude per pixel

    def xy(self, lon: float, lat: float) -> tuple[float, float]:
        return (self.dx + (lon - self.lon0) * self.k * self.s,
                self.dy + (self.lat1 - lat) * self.s)

    def points(self, poly: tuple[tuple[float, float], ...]) -> str:
        return " ".join(f"{x:.1f},{y:.1f}" for x, y in (self.xy(*p) for p in poly))


def _label_at(frame: _Frame, poly: tuple[tuple[float, float], ...]) -> tuple[float, float]:
    p = np.array([frame.xy(*q) for q in poly])
    if abs(signed_area(p)) < 1.0:
        return float(p[:, 0].mean()), float(p[:, 1].mean())
    return polygon_centroid(p)


def _scale_bar(frame: _Frame) -> str:
    want = 0.25 * PANEL_W * frame.m_per_px / 1000.0  # km
    km = max((v for v in (0.5, 1, 2, 5, 10, 20, 50, 100, 200, 500) if v <= want), default=0.5)
    px = km * 1000.0 / frame.m_per_px
    y = frame.height - 10.0
    return (f'<g class="scale"><rect x="8" y="{y - 14:.1f}" width="{px + 8:.1f}" height="20" '
            f'fill="#fff" fill-opacity="0.75"/><line x1="12" y1="{y:.1f}" x2="{12 + px:.1f}" '
            f'y2="{y:.1f}" stroke="#000" stroke-width="2"/><text x="12" y="{y - 4:.1f}" '
            f'font-size="10">{km:g} km</text></g>')


def _pair_title(i: int, p: PairState) -> str:
    words = [f"{i}. {p.id}: {p.status}"]
    if p.reason:
        words.append(p.reason)
    if p.stated_px is not None:
        words.append(f"stated check-point RMS {p.stated_px:.2f} px")
    if p.measured_px is not None:
        words.append(f"measured {p.measured_px:.2f} px")
    if p.seconds is not None:
        words.append(f"{seconds_text(p.seconds)} on its worker")
    return escape(" — ".join(words))


def _panel(m: ArchiveMap, frame: _Frame, by: str, x0: float) -> str:
    """One panel: the hillshade, the scenes' outlines, the pairs coloured ``by`` status or
    stated accuracy, their numbers, a scale bar."""
    out = [f'<g transform="translate({x0:.1f},{TITLE_H:.1f})">',
           (f'<rect width="{PANEL_W:.0f}" height="{frame.height:.1f}" fill="#f4f4f4" '
           'stroke="#888"/>'), '<g clip-path="url(#panel)">']
    if m.shade is not None:
        out.append('<use xlink:href="#shade"/>')
    for poly in m.footprints.scenes.values():
        out.append(f'<polygon points="{frame.points(poly)}" fill="none" stroke="#333" '
                   'stroke-width="0.6" stroke-opacity="0.7"/>')
    labels = []
    for i, p in enumerate(m.pairs, start=1):
        poly = m.footprints.pairs.get(p.id)
        if poly is None:
            continue
        if by == "status":
            fill, dash = STATUS_COLOURS[p.shown], ""
        else:
            b = accuracy_bin(p.stated_px)
            fill = NO_FIGURE if b is None else ACCURACY_BINS[b][1]
            dash = ' stroke-dasharray="3 2"' if b is None else ""
        out.append(f'<polygon class="pair" data-id="{escape(p.id)}" data-status="{p.shown}" '
                   f'points="{frame.points(poly)}" fill="{fill}" fill-opacity="0.5" '
                   f'stroke="#111" stroke-width="1"{dash}><title>{_pair_title(i, p)}</title>'
                   '</polygon>')
        x, y = _label_at(frame, poly)
        labels.append(f'<text x="{x:.1f}" y="{y + 4:.1f}" text-anchor="middle" '
                      f'font-size="11" font-weight="bold" stroke="#fff" stroke-width="3" '
                      f'paint-order="stroke">{i}</text>')
    out += [*labels, "</g>", _scale_bar(frame) if m.footprints.box() else "", "</g>"]
    return "\n".join(out)


def _legend(items: list[tuple[str, str, str, int]], x0: float, y0: float) -> str:
    """Swatches (colour, dash, label, count) in a column."""
    out = []
    for k, (colour, dash, label, n) in enumerate(items):
        y = y0 + 17.0 * k
        out.append(f'<rect x="{x0:.1f}" y="{y:.1f}" width="14" height="12" fill="{colour}" '
                   f'fill-opacity="0.5" stroke="#111"{dash}/><text x="{x0 + 20:.1f}" '
                   f'y="{y + 10:.1f}" font-size="12">{escape(label)}: {n}</text>')
    return "\n".join(out)


def map_svg(m: ArchiveMap) -> str:
    """The two panels as one SVG document (empty panels with a note when no pair has a
    footprint)."""
    box = m.footprints.box()
    frame = _Frame((0.0, 0.0, 1.0, 1.0) if box is None else
                   (box.lon_min, box.lat_min, box.lon_max, box.lat_max))
    width = 2 * PANEL_W + 3 * PAD
    height = TITLE_H + frame.height + LEGEND_H
    defs = [(f'<clipPath id="panel"><rect width="{PANEL_W:.0f}" height="{frame.height:.1f}"/>'
            '</clipPath>')]
    if m.shade is not None:
        (x0, y1), (x1, y0) = (frame.xy(m.shade.bounds[0], m.shade.bounds[1]),
                              frame.xy(m.shade.bounds[2], m.shade.bounds[3]))
        data = base64.b64encode(m.shade.png).decode("ascii")
        defs.append(f'<image id="shade" x="{x0:.2f}" y="{y0:.2f}" width="{x1 - x0:.2f}" '
                    f'height="{y1 - y0:.2f}" preserveAspectRatio="none" '
                    f'xlink:href="data:image/png;base64,{data}"/>')
    status = [(STATUS_COLOURS[s], "", STATUS_WORDS[s].split(" (")[0], m.count(s))
              for s in STATUS_COLOURS]
    bins = [(c, "", _bin_label(i), sum(accuracy_bin(p.stated_px) == i for p in m.pairs))
            for i, (_, c) in enumerate(ACCURACY_BINS)]
    bins.append((NO_FIGURE, ' stroke-dasharray="3 2"', "no figure",
                 sum(p.stated_px is None for p in m.pairs)))
    right = 2 * PAD + PANEL_W
    y_leg = TITLE_H + frame.height + 14.0
    parts = [
        (f'<svg xmlns="http://www.w3.org/2000/svg" xmlns:xlink="http://www.w3.org/1999/xlink" '
        f'width="{width:.0f}" height="{height:.0f}" viewBox="0 0 {width:.0f} {height:.0f}" '
        'font-family="sans-serif" role="img" aria-label="archive map">'),
        f'<defs>{"".join(defs)}</defs>',
        f'<rect width="{width:.0f}" height="{height:.0f}" fill="#fff"/>',
        f'<text x="{PAD:.0f}" y="18" font-size="14" font-weight="bold">Pairs by status</text>',
        (f'<text x="{right:.0f}" y="18" font-size="14" font-weight="bold">By stated accuracy '
        '(predicted check-point RMS, worst image and axis)</text>'),
        _panel(m, frame, "status", PAD), _panel(m, frame, "accuracy", right),
        _legend(status, PAD, y_leg), _legend(bins, right, y_leg)]
    if box is None:
        parts.append(f'<text x="{PAD + 10:.0f}" y="{TITLE_H + 30:.0f}" font-size="13">No pair '
                     'has a footprint (see the table).</text>')
    return "\n".join([*parts, "</svg>"]) + "\n"


# ----------------------------------------------------------------------------- the page


def counts_text(m: ArchiveMap) -> str:
    kept = sum(p.status == "skipped" for p in m.pairs)
    kept_text = f" ({kept} kept from an earlier run)" if kept else ""
    return (f"{len(m.pairs)} pairs: {m.count('done')} done{kept_text}, "
            f"{m.count('refused')} refused, {m.count('failed')} failed, "
            f"{m.count('running')} running, {m.count('queued')} queued")


def throughput_text(m: ArchiveMap) -> str:
    t = m.throughput()
    if not t.ended and not t.left:
        return "No pair ran: every pair was complete from an earlier run."
    if not t.ended or t.per_hour is None:
        return f"No pair has ended yet in this run ({seconds_text(m.elapsed_s)} since it began)."
    text = (f"{t.ended} pairs ended in {seconds_text(m.elapsed_s)}: {t.per_hour:.0f} pairs per "
            f"hour; a pair took {seconds_text(t.median_s)} (median) on its worker, "
            f"{seconds_text(t.max_s)} at most.")
    if t.left:
        text += f" {t.left} to go: about {seconds_text(t.eta_s)} at this rate."
    return text


def _table(head: list[str], rows: list[list[str]]) -> str:
    h = "".join(f"<th>{escape(c)}</th>" for c in head)
    body = "".join("<tr>" + "".join(f"<td>{c}</td>" for c in r) + "</tr>" for r in rows)
    return f"<table><thead><tr>{h}</tr></thead><tbody>{body}</tbody></table>"


def _steps_rows(m: ArchiveMap) -> list[list[str]]:
    return [[escape(r.step), str(r.pairs), seconds_text(r.total_s), seconds_text(r.median_s),
             f"{seconds_text(r.max_s)} ({escape(r.slowest)})"] for r in m.slowest_steps()]


STYLE = """body{font-family:sans-serif;margin:1.2em;color:#111;max-width:1110px}
h1{font-size:1.4em}h2{font-size:1.1em;margin-top:1.4em}.map svg{width:100%;height:auto}
table{border-collapse:collapse;font-size:0.9em;display:block;overflow-x:auto}
td,th{border:1px solid #ccc;padding:3px 7px;text-align:left;vertical-align:top;
white-space:nowrap}td:last-child{white-space:normal;min-width:18em}
th{background:#eee}.counts{font-size:1.05em;font-weight:bold}.note{color:#444;font-size:0.9em}
.status{display:inline-block;width:0.8em;height:0.8em;margin-right:0.3em;border:1px solid #111}"""


def map_html(m: ArchiveMap, svg: str) -> str:
    """The page beside ``summary.csv``: counts, the map, where it comes from, the throughput,
    the slowest steps, the refusals and failures, every pair; it reloads itself every 30 s
    while pairs are running or queued."""
    going = m.count("running") + m.count("queued") > 0
    refresh = '<meta http-equiv="refresh" content="30">' if going else ""
    missing = ""
    if m.footprints.missing:
        missing = (f"<p class=\"note\">{len(m.footprints.missing)} pairs have no footprint "
                   "(their models could not be read): "
                   + "; ".join(f"{escape(k)}: {escape(v)}"
                               for k, v in m.footprints.missing.items()) + ".</p>")
    bad = [[escape(p.id), p.status, escape(p.reason)] for p in m.pairs
           if p.status in ("refused", "failed")]
    steps = _steps_rows(m)

    def dot(p: PairState) -> str:
        return f'<span class="status" style="background:{STATUS_COLOURS[p.shown]}"></span>'

    pairs = [[str(i), escape(p.id), dot(p) + p.status, px_text(p.stated_px),
              px_text(p.measured_px), "–" if p.gcps is None else str(p.gcps),
              seconds_text(p.seconds), escape(p.reason)] for i, p in enumerate(m.pairs, 1)]
    shade = m.shade.source if m.shade is not None else m.shade_note
    root = escape(str(m.root))
    return "\n".join([
        "<!doctype html>", '<html lang="en"><head><meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">', refresh,
        f"<title>gcpfree archive map: {escape(Path(m.root).name)}</title>",
        f"<style>{STYLE}</style></head><body>",
        f"<h1>Archive {escape(Path(m.root).name)}: the pairs on a map</h1>",
        f'<p class="counts">{escape(counts_text(m))}.</p>',
        (f'<p class="note">Updated {escape(m.updated_utc)}, as pairs end '
        f'{"(this page reloads itself every 30 s)" if going else "(the run is over)"}; '
        f"products and <code>summary.csv</code> in <code>{root}</code>.</p>"),
        f'<div class="map">{svg}</div>',
        (f'<p class="note">Footprints: {escape(m.footprints.source)}; each pair drawn where its '
        f"two images overlap, numbered as in the table. Relief: {escape(shade)}. Stated "
        "accuracy: the check-point RMS the orientation predicts for itself (report.json, "
        "worst image and axis).</p>"), missing,
        "<h2>Throughput</h2>", f"<p>{escape(throughput_text(m))}</p>",
        "<h2>Slowest steps</h2>",
        ("<p class=\"note\">From the products' write times: a step ends when its last product "
         "is in place; steps kept from an earlier run are not counted.</p>"
         + _table(["step", "pairs", "total", "median", "slowest (pair)"], steps))
        if steps else "<p>No step has ended yet in this run.</p>",
        "<h2>Refused and failed</h2>",
        _table(["pair", "status", "reason"], bad) if bad else "<p>None.</p>",
        "<h2>Pairs</h2>",
        _table(["#", "pair", "status", "stated", "measured", "GCPs", "time", "reason"], pairs),
        "</body></html>", ""])


def map_markdown(m: ArchiveMap, svg: str) -> str:
    """The artifact: the map as an image (the SVG as a data URI), the counts, the throughput,
    the slowest steps and the refusals and failures."""
    data = base64.b64encode(svg.encode("utf-8")).decode("ascii")
    lines = [f"# Archive map: {len(m.pairs)} pairs", "",
             f"**{counts_text(m)}** (updated {m.updated_utc}).", "",
             f"![the pairs by status and by stated accuracy](data:image/svg+xml;base64,{data})",
             "", throughput_text(m), "",
             f"The page with every pair: `{Path(m.root) / 'map.html'}`."]
    steps = _steps_rows(m)
    if steps:
        lines += ["", "## Slowest steps", "", "| step | pairs | total | median | slowest |",
                  "|---|---|---|---|---|"]
        lines += ["| " + " | ".join(r) + " |" for r in steps]
    bad = [p for p in m.pairs if p.status in ("refused", "failed")]
    if bad:
        lines += ["", "## Refused and failed", "", "| pair | status | reason |", "|---|---|---|"]
        lines += [f"| {p.id} | {p.status} | {p.reason.replace('|', '/')} |" for p in bad]
    return "\n".join(lines) + "\n"
