"""The run report of ``gcpfree orient`` (report.html, report.md, PNG figures beside them, the
key ``report`` added to report.json) on the orientation of the tiny simulated pair and the
lidar evaluation of its final DSM: every figure there and a valid PNG; every number of the
tables read back from the Markdown and the HTML equal to the JSON products it came from;
report.json extended, never replaced; products that are not available said in the report
instead of raised."""

from __future__ import annotations

import json
import math
import re
import shutil
from html.parser import HTMLParser
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from PIL import Image

from tasks.report import FIGURES_DIR, JSON_KEY, ReportOutcome, make_report, write_report
from tasks.report_doc import MAX_INLINE
from tasks.report_tables import EVAL_KEYS, STATS, WINDOW_KEYS

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
FIGURES = {"tie_points", "profile", "relief", "correlation_surface", "gcp_residuals",
           "checkpoint_residuals", "histograms", "le68"}
REL = 5.001e-4  # the report prints 4 significant digits (one decimal from 1000 up)


# ---------------------------------------------------------------------------- fixtures


def copy_orient_output(src: Path, dst: Path) -> Path:
    """An orient output folder copied (the session's stays read-only), without any report:
    no report.html, report.md, figures, nor the key ``report`` in report.json."""
    shutil.copytree(src, dst, ignore=shutil.ignore_patterns("report.html", "report.md",
                                                            FIGURES_DIR))
    doc = json.loads((dst / "report.json").read_text())
    if doc.pop(JSON_KEY, None) is not None:
        (dst / "report.json").write_text(json.dumps(doc))
    return dst


@pytest.fixture(scope="module")
def evaluation(tiny_oriented, tmp_path_factory) -> Path:
    """``gcpfree evaluate`` of the final DSM against the scene's simulated lidar (LAS
    classes): a real eval.json."""
    from tasks.evaluate import EvaluationOptions, evaluate_lidar, write_evaluation

    scene, out, _ = tiny_oriented
    report = evaluate_lidar.fn(EvaluationOptions(dem=out / "dsm.tif",
                                                 lidar=scene / "truth" / "lidar.laz"))
    return write_evaluation.fn(report, tmp_path_factory.mktemp("eval") / "eval.json")


@pytest.fixture(scope="module")
def run(tiny_oriented, evaluation, tmp_path_factory):
    """The report of the orientation (pushbroom, lens self-calibration, check points) with
    everything given: (scene, out, outcome, report.json as orient wrote it)."""
    scene, src, _ = tiny_oriented
    out = copy_orient_output(src, tmp_path_factory.mktemp("report") / "out")
    original = json.loads((out / "report.json").read_text())
    outcome = make_report(out, reference=scene / "reference.tif",
                          checkpoints=scene / "truth" / "checkpoints.json",
                          evaluation=evaluation)
    return scene, out, outcome, original


# ---------------------------------------------------------------------------- reading back


Tables = dict[str, tuple[list[str], list[list[str]]]]


def md_tables(text: str) -> Tables:
    """The tables of report.md by caption (the ``**caption**`` line above; "" for none)."""
    def cells(line: str) -> list[str]:
        parts = re.split(r"(?<!\\)\|", line.strip()[1:-1])
        return [p.strip().replace("\\|", "|").replace("\\\\", "\\") for p in parts]

    tables: Tables = {}
    lines, caption, i = text.splitlines(), "", 0
    while i < len(lines):
        line = lines[i]
        if line.startswith("**") and line.endswith("**") and len(line) > 4:
            caption = line[2:-2]
        elif line.startswith("| "):
            header, rows, i = cells(line), [], i + 2
            while i < len(lines) and lines[i].startswith("| "):
                rows.append(cells(lines[i]))
                i += 1
            assert caption not in tables or caption == "", caption
            tables.setdefault(caption, (header, rows))
            caption = ""
            continue
        i += 1
    return tables


class _HtmlTables(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.tables: Tables = {}
        self._cap: str | None = None
        self._rows: list[list[str]] = []
        self._cell: str | None = None
        self._in_caption = False

    def handle_starttag(self, tag, attrs):
        if tag == "table":
            self._cap, self._rows = "", []
        elif tag == "caption":
            self._in_caption = True
        elif tag == "tr":
            self._rows.append([])
        elif tag in ("td", "th"):
            self._cell = ""

    def handle_endtag(self, tag):
        if tag == "caption":
            self._in_caption = False
        elif tag in ("td", "th"):
            self._rows[-1].append(self._cell)
            self._cell = None
        elif tag == "table":
            self.tables.setdefault(self._cap, (self._rows[0], self._rows[1:]))

    def handle_data(self, data):
        if self._in_caption:
            self._cap += data
        elif self._cell is not None:
            self._cell += data


def html_tables(text: str) -> Tables:
    p = _HtmlTables()
    p.feed(text)
    return p.tables


def both_tables(out: Path) -> list[Tables]:
    md = md_tables((out / "report.md").read_text())
    html = html_tables((out / "report.html").read_text())
    assert md == html  # the twins hold the same tables
    return [md, html]


def at(doc: Any, path: str) -> Any:
    """The value at a key path ``a.b[2].c`` of a JSON document."""
    for key, index in re.findall(r"([^.\[\]]+)|\[(\d+)\]", path):
        doc = doc[int(index)] if index else doc[key]
    return doc


def same(cell: str, value: Any) -> bool:
    """Whether a printed cell shows ``value`` (read back as a number, not formatted again)."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return cell == "–"
    if isinstance(value, bool):
        return cell == ("yes" if value else "no")
    if isinstance(value, int):
        return cell == str(value)
    if isinstance(value, float):
        return cell != "–" and float(cell) == pytest.approx(value, rel=REL, abs=1e-300)
    if isinstance(value, str):
        return cell == value
    if isinstance(value, list) and all(not isinstance(v, (dict, list)) for v in value):
        if not value:
            return cell == "(none)"
        if len(value) > MAX_INLINE:
            m = re.fullmatch(r"(\d+) values(?:, (\S+) \.\. (\S+))? \(in the JSON file\)", cell)
            nums = [v for v in value if isinstance(v, (int, float)) and v is not None]
            return bool(m) and int(m[1]) == len(value) and (
                m[2] is None or (same(m[2], min(nums)) and same(m[3], max(nums))))
        parts = cell.split(", ")
        return len(parts) == len(value) and all(same(c, v) for c, v in
                                                 zip(parts, value, strict=True))
    if isinstance(value, list):
        return cell == f"{len(value)} entries (in the JSON file)"
    return False


def check_flat(table: tuple[list[str], list[list[str]]], doc: Any) -> int:
    """Every row ``key path | value`` of a two-column table equals ``doc`` at that path."""
    header, rows = table
    assert header == ["quantity", "value"]
    bad = [(k, c, at(doc, k)) for k, c in rows if not same(c, at(doc, k))]
    assert not bad, bad[:5]
    return len(rows)


def check_rows(table: tuple[list[str], list[list[str]]], keys: list[str],
               docs: list[dict[str, Any]]) -> None:
    """Row i, column k of a table equals ``docs[i][keys[k]]`` (the first ``len(keys)``
    columns)."""
    _, rows = table
    assert len(rows) == len(docs) and all(len(r) >= len(keys) for r in rows)
    bad = [(i, k, c, d.get(k)) for i, (r, d) in enumerate(zip(rows, docs, strict=True))
           for k, c in zip(keys, r[:len(keys)], strict=True) if not same(c, d.get(k))]
    assert not bad, bad[:5]


def images_of(report_dir: Path) -> tuple[list[str], list[str]]:
    html = (report_dir / "report.html").read_text()
    md = (report_dir / "report.md").read_text()
    return re.findall(r'<img src="([^"]+)"', html), re.findall(r"!\[[^\]]*\]\(([^)]+)\)", md)


def assert_valid_pngs(report_dir: Path, srcs: list[str]) -> None:
    for src in srcs:
        path = report_dir / src
        assert path.is_file() and path.stat().st_size > 1000, src
        assert path.read_bytes()[:8] == PNG_MAGIC, src
        with Image.open(path) as im:
            im.verify()
        with Image.open(path) as im:
            assert im.format == "PNG" and min(im.size) > 200, (src, im.size)
            assert np.asarray(im.convert("L")).std() > 5, f"{src} is blank"


# ---------------------------------------------------------------------------- tests


def test_report_and_its_figures_are_written(run):
    _, out, outcome, _ = run
    assert isinstance(outcome, ReportOutcome)
    assert (outcome.html, outcome.markdown, outcome.json) == (
        out / "report.html", out / "report.md", out / "report.json")
    assert outcome.not_available == ()
    html_imgs, md_imgs = images_of(out)
    assert html_imgs == md_imgs  # the twins show the same figures
    assert {Path(s).stem for s in html_imgs} == FIGURES
    assert sorted(outcome.figures) == sorted(out / s for s in html_imgs)
    assert all(s.startswith(f"{FIGURES_DIR}/") for s in html_imgs)
    assert_valid_pngs(out, html_imgs)
    html = outcome.html.read_text()
    assert html.startswith("<!DOCTYPE html>") and html.rstrip().endswith("</html>")
    assert "Not available" not in html and "could not be made" not in html
    assert "Relief sufficient" in html


def test_the_numbers_shown_are_those_of_the_json_products(run, evaluation):
    """Each table read back from report.md and report.html (they hold the same tables) equals
    the JSON it was made from: report.json, windows.json, eval.json."""
    _, out, _, original = run
    doc = json.loads((out / "report.json").read_text())
    windows = json.loads((out / "windows.json").read_text())["windows"]
    ev = json.loads(evaluation.read_text())
    rel, ab = doc["relative"], doc["absolute"]
    flat = {"Relative orientation (rel.json)": rel, "Relative adjustment": rel["adjustment"],
            "Right model after the relative orientation": rel["right_model"],
            "Relative DEM": doc["relative_dem"],
            "Surface matching and relief verdict": doc["surface_matching"],
            "Simulated GCPs": doc["gcps"], "Absolute adjustment": ab,
            "Lens self-calibration": ab["self_calibration"],
            **{f"Image {n}: residuals at the GCPs used (px)": ab["images"][n]
               for n in ("left", "right")},
            "Other entries": {k: original[k] for k in ("models", "dsm")},
            "Window drawn: grid maximum and the refined shift (windows.json)":
                doc[JSON_KEY]["correlation_surface"],
            **{f"Evaluation: {k.replace('_', ' ')}": ev
               for k in ("points", "inputs", "heights_compared", "transformation")}}
    for tables in both_tables(out):
        two_col = {c for c, (h, _) in tables.items() if h == ["quantity", "value"]}
        assert two_col == set(flat)  # no table left unchecked
        assert sum(check_flat(tables[c], d) for c, d in flat.items()) > 300
        # the paper's Table 2: check points per image, before and after
        cp = next(t for c, t in tables.items() if c.startswith("Check-point residuals"))
        assert cp[0] == ["image", "orientation", *STATS]
        check_rows(cp, ["image", "stage", *STATS],
                   [{"image": n, "stage": s, **doc[k][n]} for n in ("left", "right")
                    for s, k in (("before", "check_points_before"), ("after", "check_points"))])
        for n in ("left", "right"):
            img = ab["images"][n]
            check_rows(tables[f"Image {n}: parameters adjusted"],
                       ["param_names", "params_before", "params_after", "sigmas"],
                       [dict(zip(("param_names", "params_before", "params_after", "sigmas"),
                                 v, strict=True))
                        for v in zip(img["param_names"], img["params_before"],
                                     img["params_after"], img["sigmas"], strict=True)])
        win = next(t for c, t in tables.items() if c.startswith("Windows (windows.json"))
        assert win[0] == list(WINDOW_KEYS)
        check_rows(win, list(WINDOW_KEYS), windows)
        rejected = tables["GCPs rejected by the absolute orientation"]
        check_rows(rejected, ["id", "reason"], doc["gcps"]["rejected_ids"])
        # LE68 per class (Toutin): eval.json's classes and "all"
        lidar = next(t for c, t in tables.items() if c.startswith("DEM - lidar per class"))
        stats = {**ev["classes"], "all": ev["all"]}
        check_rows(lidar, ["class", "label", *EVAL_KEYS],
                   [{"class": k, "label": ev["class_labels"].get(k, ""), **s}
                    for k, s in stats.items()])
        for row, s in zip(lidar[1], stats.values(), strict=True):
            lo, hi = row[-1].split(" .. ")  # the bootstrap interval of LE68
            assert same(lo, s["le68_ci"][0]) and same(hi, s["le68_ci"][1])
        summary = dict(tables[""][1])  # the summary table has no caption
        g = doc["gcps"]
        assert summary["GCPs given / used / rejected"] == (
            f"{g['given']} / {g['used']} / {g['rejected']}")
        after = doc["check_points"]["left"]
        c, r, n = re.fullmatch(r"(\S+) / (\S+) \((\d+) points\)",
                               summary["check-point RMS left after: col / row (px)"]).groups()
        assert same(c, after["rms_col_px"]) and same(r, after["rms_row_px"])
        assert int(n) == after["n"]


def test_report_json_is_extended_not_replaced(run, evaluation):
    """The orientation's keys stay as orient wrote them; ``report`` holds what the report
    adds (the evaluation as read, the window drawn, the figures), and a second report
    replaces it."""
    scene, out, outcome, original = run
    doc = json.loads((out / "report.json").read_text())
    assert {k: v for k, v in doc.items() if k != JSON_KEY} == original
    rep = doc[JSON_KEY]
    assert rep["format"] == "gcpfree.report" and rep["not_available"] == []
    assert (rep["html"], rep["markdown"]) == ("report.html", "report.md")
    assert {n: out / p for n, p in rep["figures"].items()} == {p.stem: p
                                                              for p in outcome.figures}
    ev = json.loads(evaluation.read_text())
    assert rep["evaluation"] == {"file": str(evaluation), **ev}
    assert rep["inputs"]["reference"] == str(scene / "reference.tif")
    cs = rep["correlation_surface"]
    w = next(w for w in json.loads((out / "windows.json").read_text())["windows"]
             if w["tie_point"] == cs["tie_point"])
    assert w["status"] == "OK" and (cs["shift_lon_arcsec"], cs["correlation"]) == (
        w["shift_lon_arcsec"], w["correlation"])
    # the drawn surface's grid maximum is the node nearest the window's refined shift
    assert abs(cs["grid_peak_lon_arcsec"] - w["shift_lon_arcsec"]) <= 1.0
    assert abs(cs["grid_peak_lat_arcsec"] - w["shift_lat_arcsec"]) <= 1.0
    # the same correlations as the matching's (it searched a subset of this grid)
    assert cs["grid_peak_correlation"] == pytest.approx(w["correlation"], abs=1e-9)
    again = make_report(out)  # nothing optional given this time
    doc2 = json.loads(again.json.read_text())
    assert {k: v for k, v in doc2.items() if k != JSON_KEY} == original
    assert "evaluation" not in doc2[JSON_KEY] and doc2[JSON_KEY]["not_available"]
    make_report(out, reference=scene / "reference.tif",  # leave the module's report whole
                checkpoints=scene / "truth" / "checkpoints.json", evaluation=evaluation)


def test_products_not_available_are_said_not_raised(run, tmp_path):
    """Products removed and nothing optional given: the report is still written, says what is
    not available, and every image it shows exists."""
    _, out, _, _ = run
    copy = copy_orient_output(out, tmp_path / "out")
    for name in ("windows.json", "right.json", "relative/rel.tiepoints.json"):
        (copy / name).unlink()
    stale = copy / FIGURES_DIR / "le68.png"  # from an earlier report of this folder
    stale.parent.mkdir()
    stale.write_bytes(PNG_MAGIC)
    outcome = write_report.fn(copy, evaluation=tmp_path / "nope.json")
    assert not stale.exists()
    html = outcome.html.read_text()
    md = outcome.markdown.read_text()
    for text in ("Not available: windows.json", "Not available: right.json",
                 "Not available: relative/rel.tiepoints.json",
                 "Not available: the reference DEM (not given",
                 "Not available: the check-point file",
                 "Not available: a readable evaluation file"):
        assert text in html and text in md, text
    assert len(outcome.not_available) >= 6
    html_imgs, md_imgs = images_of(copy)
    assert html_imgs == md_imgs
    assert {Path(s).stem for s in html_imgs} == {"gcp_residuals", "histograms"}
    assert_valid_pngs(copy, html_imgs)
    # the check-point statistics come from report.json: still there
    doc = json.loads((copy / "report.json").read_text())
    for tables in both_tables(copy):
        cp = next(t for c, t in tables.items() if c.startswith("Check-point residuals"))
        assert same(cp[1][-1][STATS.index("rms_col_px") + 2],
                    doc["check_points"]["right"]["rms_col_px"])
    assert doc[JSON_KEY]["not_available"] == list(outcome.not_available)

    empty = tmp_path / "empty"
    empty.mkdir()
    outcome = make_report(empty)
    assert "report.json (the orientation did not finish?)" in outcome.html.read_text()
    assert outcome.markdown.is_file() and outcome.json is None
    assert not (empty / "report.json").exists()  # never made up


def test_the_report_renders_in_headless_chromium(run, tmp_path):
    """When playwright and its Chromium are installed: the page loads its images and a
    screenshot of it is not blank."""
    sync_api = pytest.importorskip("playwright.sync_api")
    _, _, outcome, _ = run
    try:
        with sync_api.sync_playwright() as p:
            browser = p.chromium.launch()
            page = browser.new_page(viewport={"width": 1200, "height": 2000})
            page.goto(outcome.html.resolve().as_uri())
            page.wait_for_load_state("load")
            broken = page.evaluate("Array.from(document.images).filter("
                                   "i => !i.complete || i.naturalWidth === 0).length")
            shot = page.screenshot(path=str(tmp_path / "report.png"), full_page=True)
            browser.close()
    except sync_api.Error as exc:  # no browser binary installed
        pytest.skip(f"headless Chromium unavailable: {exc}")
    assert broken == 0 and shot[:8] == PNG_MAGIC
    with Image.open(tmp_path / "report.png") as im:
        assert np.asarray(im.convert("L")).std() > 5
