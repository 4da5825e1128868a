"""The run report as a list of blocks (headings, paragraphs, tables, figures) rendered twice:
HTML (``report.html``) and Markdown (``report.md``), with one way of writing numbers.

No Prefect and no I/O here: :mod:`tasks.report.build` builds the blocks and writes the files.
"""

from __future__ import annotations

import html
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

# lists of numbers longer than this are summarised (count, min, max) instead of printed
MAX_INLINE = 12


def fmt(v: Any) -> str:
    """A value as the report prints it: integers whole, floats to 4 significant digits (one
    decimal from 1000 up, scientific below 0.001), None/NaN as an en dash, booleans yes/no."""
    if v is None:
        return "–"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not math.isfinite(v):
            return "–"
        a = abs(v)
        if a >= 1000:
            return f"{v:.1f}"
        if a >= 1e-3 or a == 0:
            return f"{v:.4g}"
        return f"{v:.3e}"
    return str(v)


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _is_scalar(v: Any) -> bool:
    return v is None or isinstance(v, (str, int, float, bool))


def flatten(obj: Any, prefix: str = "", skip: Iterable[str] = ()) -> list[tuple[str, str]]:
    """``(key path, value)`` rows of a JSON value: nested keys joined by dots, short lists of
    scalars on one row, rows ``a[i]`` for lists of objects and short matrices; long lists of
    numbers are summarised as their count and range. ``skip``: top-level keys left out."""
    rows: list[tuple[str, str]] = []
    skipped = set(skip)
    if isinstance(obj, Mapping):
        for k, v in obj.items():
            if str(k) in skipped:
                continue
            rows += flatten(v, f"{prefix}.{k}" if prefix else str(k))
    elif isinstance(obj, (list, tuple)):
        if all(_is_scalar(v) for v in obj):
            rows.append((prefix, _list_text(obj)))
        elif len(obj) <= MAX_INLINE or all(isinstance(v, Mapping) for v in obj):
            for i, v in enumerate(obj):
                rows += flatten(v, f"{prefix}[{i}]")
        else:
            rows.append((prefix, f"{len(obj)} entries (in the JSON file)"))
    else:
        rows.append((prefix, fmt(obj)))
    return rows


def _list_text(values: Sequence[Any]) -> str:
    if not values:
        return "(none)"
    if len(values) <= MAX_INLINE:
        return ", ".join(fmt(v) for v in values)
    nums = [float(v) for v in values if _is_number(v) and math.isfinite(float(v))]
    if len(nums) == len(values):
        return f"{len(values)} values, {fmt(min(nums))} .. {fmt(max(nums))} (in the JSON file)"
    return f"{len(values)} values (in the JSON file)"


# ---------------------------------------------------------------------------- blocks


@dataclass(frozen=True)
class Heading:
    text: str
    level: int = 2


@dataclass(frozen=True)
class Para:
    """A paragraph of plain text; ``kind`` ``note`` (default), ``good`` or ``bad`` colours it
    in HTML and prefixes it in Markdown."""

    text: str
    kind: str = "note"


@dataclass(frozen=True)
class Table:
    header: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]
    caption: str = ""

    @classmethod
    def of(cls, header: Sequence[str], rows: Iterable[Sequence[Any]],
           caption: str = "") -> Table:
        """A table from raw values (formatted with :func:`fmt`)."""
        return cls(tuple(header), tuple(tuple(v if isinstance(v, str) else fmt(v) for v in r)
                                        for r in rows), caption)

    @classmethod
    def flat(cls, obj: Any, caption: str = "", skip: Iterable[str] = ()) -> Table:
        """A two-column table of :func:`flatten`."""
        return cls(("quantity", "value"), tuple(flatten(obj, skip=skip)), caption)


@dataclass(frozen=True)
class Figure:
    """An image beside the report: ``src`` relative to the report's folder."""

    src: str
    caption: str


Block = Heading | Para | Table | Figure

MARK = {"note": "", "good": "**OK** ", "bad": "**WARNING** "}

CSS = """
body { font-family: system-ui, sans-serif; max-width: 1100px; margin: 2em auto; padding: 0 1em;
       color: #222; line-height: 1.45; }
h1 { border-bottom: 2px solid #446; } h2 { border-bottom: 1px solid #ccd; margin-top: 2em; }
div.table { overflow-x: auto; }  /* a wide table scrolls, not the page */
table { border-collapse: collapse; margin: 0.8em 0; font-size: 0.9em; }
th, td { border: 1px solid #ccd; padding: 0.2em 0.6em; text-align: left; vertical-align: top; }
th { background: #eef; } td { font-variant-numeric: tabular-nums; }
caption { caption-side: top; text-align: left; font-weight: 600; padding: 0.3em 0;
          white-space: nowrap; }
figure { margin: 1em 0; } figure img { max-width: 100%; border: 1px solid #ddd; }
figcaption { font-size: 0.9em; color: #444; }
p.good { background: #e7f6e7; border-left: 4px solid #3a3; padding: 0.4em 0.8em; }
p.bad { background: #fdeaea; border-left: 4px solid #c33; padding: 0.4em 0.8em; }
"""


def to_html(title: str, blocks: Sequence[Block]) -> str:
    e = html.escape
    out = ["<!DOCTYPE html>", '<html lang="en"><head><meta charset="utf-8">',
           f"<title>{e(title)}</title><style>{CSS}</style></head><body>", f"<h1>{e(title)}</h1>"]
    for b in blocks:
        if isinstance(b, Heading):
            out.append(f"<h{b.level}>{e(b.text)}</h{b.level}>")
        elif isinstance(b, Para):
            out.append(f'<p class="{e(b.kind)}">{e(b.text)}</p>')
        elif isinstance(b, Figure):
            out.append(f'<figure><img src="{e(b.src)}" alt="{e(b.caption)}">'
                       f"<figcaption>{e(b.caption)}</figcaption></figure>")
        else:
            cap = f"<caption>{e(b.caption)}</caption>" if b.caption else ""
            head = "".join(f"<th>{e(h)}</th>" for h in b.header)
            body = "".join("<tr>" + "".join(f"<td>{e(c)}</td>" for c in r) + "</tr>"
                           for r in b.rows)
            out.append(f'<div class="table"><table>{cap}<thead><tr>{head}</tr></thead>'
                       f"<tbody>{body}</tbody></table></div>")
    out.append("</body></html>")
    return "\n".join(out) + "\n"


def _md_cell(text: str) -> str:
    return text.replace("\\", "\\\\").replace("|", "\\|").replace("\n", " ")


def to_markdown(title: str, blocks: Sequence[Block]) -> str:
    out = [f"# {title}", ""]
    for b in blocks:
        if isinstance(b, Heading):
            out += [f"{'#' * b.level} {b.text}", ""]
        elif isinstance(b, Para):
            out += [MARK.get(b.kind, "") + b.text, ""]
        elif isinstance(b, Figure):
            out += [f"![{_md_cell(b.caption)}]({b.src})", "", f"*{b.caption}*", ""]
        else:
            if b.caption:
                out += [f"**{b.caption}**", ""]
            out.append("| " + " | ".join(_md_cell(h) for h in b.header) + " |")
            out.append("|" + "---|" * len(b.header))
            out += ["| " + " | ".join(_md_cell(c) for c in r) + " |" for r in b.rows]
            out.append("")
    return "\n".join(out)
