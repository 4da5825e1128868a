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

from core.errors import InputError
from core.jsonio import json_ready, to_json
from core.matching.relief import ReliefVerdict
from core.orientation.checkpoints import CheckPointStats
from core.orientation.frames import FrameEstimate
from core.orientation.result import AbsoluteOrientation, ImageResiduals
from core.orientation.selfcal import SelfCalibration
from core.orientation.uncertainty import PredictedAccuracy, VarianceComponents
from tasks.absolute.report import REPORT, Absolute, LensCalibration, read_report
from tasks.io.documents import adapter, plain
from tasks.report.build import FIGURES_DIR, JSON_KEY, ReportOutcome, make_report, write_report
from tasks.report.doc import MAX_INLINE, Table
from tasks.report.tables import (
    EVAL_KEYS,
    SECTIONS,
    STATS,
    WINDOW_KEYS,
    relative_tables,
)
from tests.flows.reports import finished_report

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
FIGURES = {"tie_points", "profile", "relief", "correlation_surface", "gcp_residuals",
           "row_profile", "checkpoint_residuals", "histograms", "le68"}
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
    from tasks.evaluation.lidar import EvaluationOptions, evaluate_lidar, write_evaluation

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


# the relative orientation's curated table: each row's cell as a pattern, and the rel.json
# values (key paths) its groups show, in order
REL_TABLE = "Tie points and the right image adjusted to the left"
REL_ROWS = {
    "sensor models left / right": (r"(\S+) / (\S+)", ("left.family", "right.family")),
    "tie points used / rejected": (r"(\S+) / (\S+)", ("tie_points", "tie_points_rejected")),
    "tie-point grid: one point per ground cell of (m)": (r"(\S+)",
                                                         ("tie_point_search.cell_m",)),
    "ground cells with a tie point / with texture / in all": (
        r"(\S+) / (\S+) / (\S+)", ("tie_point_search.n_cells_with_point",
                                   "tie_point_search.n_cells_textured",
                                   "tie_point_search.n_cells")),
    "interest points searched / matched": (
        r"(\S+) / (\S+)", ("tie_point_search.n_candidates", "tie_point_search.n_matched")),
    "tie-point correlation: median (5 % .. 95 %)": (
        r"(\S+) \((\S+) \.\. (\S+)\)", ("tie_point_search.correlation_p50",
                                         "tie_point_search.correlation_p05",
                                         "tie_point_search.correlation_p95")),
    "y-parallax RMS before / after (px)": (
        r"(\S+) / (\S+)", ("parallax_rms_before_px", "parallax_rms_after_px")),
    "robust sigma of the y-parallaxes after (px)": (r"(\S+)", ("adjustment.sigma_px",)),
    "iterations / converged": (r"(\S+) / (\S+)",
                               ("adjustment.n_iterations", "adjustment.converged")),
    "right image moved at its centre: across / along the epipolar line (px)": (
        r"(\S+) / (\S+)", ("right_correction.across_epipolar_px",
                           "right_correction.along_epipolar_px")),
    "along the epipolar line: set from the reference DEM (px)": (
        r"(\S+) ± (\S+)", ("along_epipolar.shift_px", "along_epipolar.sigma_px")),
    "tie-point heights - reference before, median (m) / reference sigma (m) / points": (
        r"(\S+) / (\S+) / (\S+)", ("along_epipolar.height_offset_m",
                                   "along_epipolar.reference_sigma_m",
                                   "along_epipolar.n_points")),
    "rays' miss distance at the tie points: median / 95 % (m)": (
        r"(\S+) / (\S+)", ("miss_distance_m.median", "miss_distance_m.p95")),
    "main parameter solved point by point (Goncalves's Table 1)": (
        r"(\S+): (\S+) ± (\S+) (\S+), (\S+) \.\. (\S+) \((\S+) points\)",
        tuple(f"adjustment.point_angle.{k}"
              for k in ("name", "mean", "std", "unit", "min", "max", "count"))),
}
REL_REFERENCE = {"reference DEM: vertical datum (decided by)": (
    r"(.+): (\S+) \((.+)\)", ("reference.path", "reference.vertical", "reference.vertical_source"))}
REASONS = "interest points rejected, by reason"
SEEN = "along the epipolar line: seen by the tie points"


def check_relative(tables: Tables, rel: dict[str, Any]) -> None:
    """The relative orientation's tables show rel.json's values: the curated table row by row
    (no row unchecked), the parameters with the square roots of the covariance's diagonal."""
    header, rows = tables[REL_TABLE]
    cells = dict(rows)
    assert header == ["", "value"] and len(cells) == len(rows)
    expected = {**REL_ROWS, **(REL_REFERENCE if rel.get("reference") else {})}
    assert set(cells) == {*expected, REASONS, SEEN}
    for label, (pattern, paths) in expected.items():
        m = re.fullmatch(pattern, cells[label])
        assert m, (label, cells[label])
        bad = [(p, c, at(rel, p)) for p, c in zip(paths, m.groups(), strict=True)
               if not same(c, at(rel, p))]
        assert not bad, (label, bad)
    reasons = dict(re.findall(r"([a-z ]+) (\d+)(?:, |$)", cells[REASONS]))
    assert reasons == {k.lower().replace("_", " "): str(v)
                       for k, v in rel["tie_point_search"]["rejected"].items()}
    # across-track stereo: the tie points cannot tell a roll from a height (Goncalves 3.1)
    unobservable = rel["adjustment"]["unobservable"]
    mostly = {k for u in unobservable for k, v in u["direction"].items() if abs(v) > 0.5}
    m = re.fullmatch(r"no: (\d+) directions? held \(mostly (.+)\)", cells[SEEN])
    assert m and int(m[1]) == len(unobservable) and set(m[2].split(", ")) == mostly
    assert "roll_bias" in mostly
    adj = rel["adjustment"]
    check_rows(tables["Right-image parameters from the tie points (sigma: the adjustment's, "
                      "within the directions the tie points see)"],
               ["name", "unit", "before", "after", "sigma"],
               [{"name": n, "unit": u, "before": b, "after": a, "sigma": math.sqrt(c[i])}
                for i, (n, u, b, a, c) in enumerate(zip(
                    adj["param_names"], adj["param_units"], adj["params_before"],
                    adj["params_after"], adj["covariance"], strict=True))])


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
    # the relative orientation is curated, not a dump of rel.json's keys
    relative = outcome.markdown.read_text().split("## Relative orientation\n")[1].split("\n## ")[0]
    for key in ("right_model", "tie_point_search", "| covariance", "left.image",
                "gcpfree.relative", "orbit.positions_m"):
        assert key not in relative, key


def test_the_numbers_shown_are_those_of_the_json_products(run, evaluation):
    """Each table read back from report.md and report.html (they hold the same tables) equals
    the JSON it was made from: report.json, windows.json, eval.json."""
    _, out, _, original = run
    doc = json.loads((out / "report.json").read_text())
    windows = json.loads((out / "windows.json").read_text())["windows"]
    ev = json.loads(evaluation.read_text())
    rel, ab = doc["relative"], doc["absolute"]
    flat = {"Relative DEM": doc["relative_dem"],
            "Surface matching and relief verdict": doc["surface_matching"],
            "Simulated GCPs": doc["gcps"], "Absolute adjustment": ab,
            "Lens self-calibration": ab["self_calibration"],
            "Along-track attitude: harmonics chosen by BIC": {
                k: ab["along_track"][k] for k in ("harmonics", "bic", "rms_row_px_without",
                                                  "rms_row_px_with", "tie_rms_px_without",
                                                  "tie_rms_px_with")},
            **{f"Image {n}: residuals at the GCPs used (px)": ab["images"][n]
               for n in ("left", "right")},
            "Other entries": {k: v for k, v in original.items() if k not in SECTIONS},
            "Window drawn: grid maximum and the refined shift (windows.json)":
                doc[JSON_KEY]["correlation_surface"],
            **{f"Evaluation: {k.replace('_', ' ')}": ev
               for k in ("points", "inputs", "heights_compared", "transformation")}}
    for tables in both_tables(out):
        two_col = {c for c, (h, _) in tables.items() if h == ["quantity", "value"]}
        assert two_col == set(flat)  # no table left unchecked
        assert sum(check_flat(tables[c], d) for c, d in flat.items()) > 150
        check_relative(tables, rel)
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
        if doc["gcps"]["rejected_ids"]:  # the table only when some were rejected
            rejected = tables["GCPs rejected by the absolute orientation"]
            check_rows(rejected, ["id", "reason"], doc["gcps"]["rejected_ids"])
        else:
            assert "GCPs rejected by the absolute orientation" not in tables
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
    assert {Path(s).stem for s in html_imgs} == {"gcp_residuals", "row_profile", "histograms"}
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


def test_the_relative_table_says_what_set_the_along_epipolar_part():
    """The tie points see every direction, or the reference DEM set those they cannot, or
    nothing did (held at the metadata): each is said. An empty rel.json gives dashes and no
    parameter table, never an error."""
    def rows(rel: dict[str, Any]) -> dict[str, str]:
        [table] = [b for b in relative_tables(rel) if isinstance(b, Table)
                   and b.caption == REL_TABLE]
        return dict(table.rows)

    roll = [{"direction": {"roll_bias": -0.99, "pitch_bias": 0.14}, "step": {},
             "observable_share": 0.0}]
    seen = rows({"adjustment": {"unobservable": []}, "along_epipolar": {"observable": True}})
    assert seen["along the epipolar line"] == "seen by the tie points" and SEEN not in seen
    held = rows({"adjustment": {"unobservable": roll},
                 "along_epipolar": {"observable": False, "sigma_px": None}})
    assert held[SEEN] == "no: 1 direction held (mostly roll_bias)"
    assert held["along the epipolar line: set from the reference DEM"] == (
        "no: held at the metadata (no reference DEM heights at 3 tie points or more)")
    empty = relative_tables({})
    assert [b.caption for b in empty if isinstance(b, Table)] == [REL_TABLE]
    assert rows({})["tie points used / rejected"] == "– / –"
    assert rows({})[REASONS] == "(none)"
    adj = {"param_names": ["a", "b"], "params_before": [0.0, 0.0], "params_after": [1.0, 2.0]}
    [_, params] = [b for b in relative_tables({"adjustment": adj}) if isinstance(b, Table)]
    assert params.rows == (("a", "", "0", "1", "–"), ("b", "", "0", "2", "–"))


# ---------------------------------------------------------------------------- report.json


def test_report_json_of_today_writes_back_byte_for_byte(tiny_oriented, run):
    """report.json as ``gcpfree orient`` wrote it today (the frames, the predicted parts, the
    lens's Wald statistics) and as the run report extended it: read through :data:`REPORT`
    and written back, the same bytes."""
    _, oriented, _ = tiny_oriented
    _, out, _, _ = run
    for path in (oriented / "report.json", out / "report.json"):
        text = path.read_text()
        report = REPORT.read(path)
        assert to_json(REPORT.dump(report)) == text, path
        assert report.absolute.frames and isinstance(report.absolute.frames[0], FrameEstimate)
        assert all(c.predicted_relative_rms_col_px is not None
                   for c in (report.check_points or {}).values())


def test_report_json_round_trips_and_refuses_what_it_cannot_read(tmp_path):
    """report.json through :data:`REPORT`: every key back as written; a newer version,
    another product, a missing or mistyped key refused in one line naming it."""
    doc = json.loads(json.dumps(finished_report(
        12, {"left": (0.25, 0.5), "right": (0.75, 0.125)},
        {"left": (0.375, 0.625), "right": (0.875, 0.0625)})))
    report = REPORT.load(doc)
    assert REPORT.dump(report) == doc and REPORT.load(REPORT.dump(report)) == report
    assert list(doc)[:2] == ["format", "version"] and (doc["format"], doc["version"]) == (
        "gcpfree.orient", 1)
    assert report.gcps.used == 12 and report.check_points["right"].rms_row_px == 0.0625
    assert report.absolute.images["left"].rms_col_px == 0.25
    path = REPORT.write(tmp_path / "report.json",
                        report.with_run_report({"format": "gcpfree.report"}))
    assert read_report(tmp_path).report == {"format": "gcpfree.report"}  # a folder or a file
    for bad, says in [
            ({**doc, "version": 2},
             "version 2, and this gcpfree reads report.json up to version 1; update gcpfree"),
            ({**doc, "version": "1"}, "version '1' is not 1"),
            ({**doc, "format": "gcpfree.pair"},
             "key 'format' is 'gcpfree.pair', not 'gcpfree.orient'"),
            ({k: v for k, v in doc.items() if k != "gcps"}, "key 'gcps' is missing"),
            ({**doc, "gcps": {**doc["gcps"], "used": "12"}},
             "key 'gcps.used' must be an integer, got '12'"),
            ({**doc, "check_points": {"left": {"n": 3}}},
             "key 'check_points.left.name' is missing"),
            ({**doc, "relative_dem": {**doc["relative_dem"], "format": "gcpfree.other"}},
             "key 'relative_dem.format' must be 'gcpfree.dem'")]:
        path.write_text(json.dumps(bad))
        with pytest.raises(InputError, match=re.escape(says)) as err:
            read_report(path)
        assert "\n" not in str(err.value) and str(path) in str(err.value)
    with pytest.raises(InputError, match="cannot read report.json .*; give the report.json "
                                         "gcpfree orient wrote"):
        read_report(tmp_path / "elsewhere")


def test_not_a_number_is_written_as_null_and_read_back():
    """A relief the verdict could not measure (NaN) is null in the file, NaN in the value,
    and null again when written back."""
    doc = finished_report(12, {"left": (0.25, 0.5)})
    doc["surface_matching"]["relief"].update(relief_needed_m=None, cell_m=None)
    report = REPORT.load(json.loads(json.dumps(doc)))
    relief = report.surface_matching.relief
    assert math.isnan(relief.relief_needed_m) and math.isnan(relief.cell_m)
    text = to_json(REPORT.dump(report))
    assert "NaN" not in text and json.loads(text) == doc


def _adjustment() -> AbsoluteOrientation:
    """A small adjustment of two images as core returns it (two GCPs kept, one rejected)."""
    res = [ImageResiduals(n, 2, 0.25, 0.5, 0.125, -0.0625, np.array([0.1, -0.2]),
                          np.array([0.3, 0.4]), 0.01, 0.02) for n in ("left", "right")]
    return AbsoluteOrientation(
        (), ("left", "right"), (("roll_bias", "pitch_bias"), ("roll_bias",)),
        (np.zeros(2), np.zeros(1)), (np.array([1e-5, 2e-5]), np.array([3e-5])),
        np.diag([4e-12, 9e-12, 1e-12]), 0.8, tuple(res), np.array([True, True, False]),
        {2: "normalised residual 5.1 > 3.5"}, 5, True, n_ties=140, tie_rms_px=0.07)


@pytest.mark.parametrize("kind", ["pushbroom", "rpc"])
def test_the_sections_are_the_schema_of_what_core_writes(kind):
    """``absolute`` read from core's records (:meth:`AbsoluteOrientation.to_dict`,
    :meth:`SelfCalibration.to_dict`) and written: every key core writes and no other, with
    its value, the images' residual figures those of :meth:`ImageResiduals.to_dict` (a key
    core adds would otherwise be dropped on the way into report.json). With RPCs the lens
    statistics are empty and their limits undefined (null)."""
    from types import SimpleNamespace

    adj = _adjustment()
    lens = (SelfCalibration(adj, None, {}, 3.0, {"left": 12.5, "right": 7.0}, 16.3,
                            {"n": 140.0, "rms_px_without": 0.07, "evidence": 0.0},
                            "none significant (GCPs: Wald left 12.5, right 7.0 against 16.3)",
                            {"left": 2.5, "right": 1.0}, 8.0) if kind == "pushbroom" else
            SelfCalibration(adj, None, {}, 3.0, decision="no pushbroom image: RPC images "
                                                         "take no lens terms"))
    products = SimpleNamespace(adjustment=adj, self_calibration=lens, along_track=None,
                               predicted={})
    section = Absolute.of(products, "linear")  # type: ignore[arg-type]
    core = json_ready({**adj.to_dict(), "corrections": "linear",
                       "self_calibration": lens.to_dict()})
    written = json_ready(plain(section))
    assert written == {k: v for k, v in core.items() if v is not None}  # absent when None
    for name, r in zip(adj.names, adj.residuals, strict=True):
        assert {k: written["images"][name][k] for k in r.to_dict()} == r.to_dict()
    assert all(isinstance(f, FrameEstimate) for f in section.frames or ())
    assert adapter(Absolute).validate_python(written) == section
    if kind == "rpc":
        assert written["self_calibration"]["wald_correlated"] == {}
        assert written["self_calibration"]["wald_correlated_limit"] is None
    old = {k: v for k, v in core["self_calibration"].items()  # a report before the keys
           if k not in ("decision", "wald_correlated", "wald_correlated_limit")}
    read = adapter(LensCalibration).validate_python(old)
    assert read.decision is None and read.wald_correlated is None
    assert json_ready(plain(read)) == old


def test_core_results_are_their_own_sections():
    """The relief verdict, the check-point table and the frames are core's classes, written as
    core writes them (with the verdict's ``enough`` and ``reason``, the predicted RMS only
    when there is one) and read back into equal values."""
    nan = math.nan
    for verdict in (ReliefVerdict(10, 9, 8, 50.0, 20.0, 10.0),
                    ReliefVerdict(10, 2, 8, 3.0, nan, 10.0, 1, 1, 900, 100, 90.0, math.inf)):
        assert json_ready(plain(verdict)) == verdict.to_dict()
        back = adapter(ReliefVerdict).validate_python(verdict.to_dict())
        assert json_ready(plain(back)) == verdict.to_dict() and back.reason == verdict.reason
    pred = PredictedAccuracy(3, 0.5, 0.25, 0.3, 0.2, 0.4, 0.15, 0.0, 0.0, (5.0, 5.0, 5.0), 0.0)
    for stats in (CheckPointStats("left", 3, *map(float, range(10))),
                  CheckPointStats("left", 3, *map(float, range(10))).with_prediction(pred)):
        assert plain(stats) == stats.to_dict()
        assert list(plain(stats)) == list(stats.to_dict())
        assert adapter(CheckPointStats).validate_python(stats.to_dict()) == stats
    frame = FrameEstimate("sar", (10.0, 10.0, 5.0), (1.5, -2.0, 0.0), (0.5, 0.5, 5.0), True,
                          "mission", "reference")
    assert plain(frame) == json_ready(frame.to_dict())
    assert adapter(FrameEstimate).validate_python(frame.to_dict()) == frame


def test_the_printed_lines_say_how_the_tie_points_were_matched():
    """``gcpfree orient`` prints the tie points in the adjustment with the measure they were
    matched with (``relative.tie_point_search.measure``); a report without it (rel.json
    before the measure was recorded) prints the line without it."""
    doc = finished_report(12, {"left": (0.25, 0.5)})
    doc["absolute"]["tie_points"] = {"n": 850, "rms_px": 0.125}
    doc["relative"]["tie_point_search"] = {"measure": "orientation"}
    line = "tie points            850 in the adjustment (orientation correlation), parallax " \
           "0.125 px RMS"
    assert line in REPORT.load(doc).lines()
    doc["relative"]["tie_point_search"] = {"measure": "ncc"}
    assert "(normalised cross-correlation)" in "\n".join(REPORT.load(doc).lines())
    del doc["relative"]["tie_point_search"]
    assert "tie points            850 in the adjustment, parallax 0.125 px RMS" in \
        REPORT.load(doc).lines()


def test_report_json_carries_the_predicted_accuracy_beside_the_measured():
    """The keys of the true uncertainties: ``check_points.<image>.predicted_rms_col_px`` and
    ``predicted_rms_row_px`` beside the measured RMS with their relative and reference parts,
    ``absolute.variance_components`` and ``absolute.predicted`` (per image over a grid, for
    users with no check point), ``reference.registration_estimate`` come back as written; a
    report without them (older runs) still reads, with None, and writes back without them."""
    comps = VarianceComponents(("gcp_col", "gcp_row"), np.array([0.56, 0.21]),
                               np.array([68, 68]), np.array([60.0, 58.0]), 4, True, "apart")
    pred = PredictedAccuracy(243, 0.16, 0.14, 0.08, 0.06, 0.14, 0.125, 0.0, 0.0, (5.0, 5.0, 5.0),
                             0.0)
    doc = finished_report(12, {"left": (0.25, 0.5)}, {"left": (0.375, 0.625)})
    doc["absolute"]["variance_components"] = comps.to_dict()
    doc["absolute"]["predicted"] = {"grid_points_per_side": 9, "heights_m": [1.0, 2.0, 3.0],
                                    "reference_sigma_m": [5.0, 5.0, 5.0],
                                    "images": {"left": pred.to_dict()}}
    stats = CheckPointStats("left", 3, *map(float, range(10))).with_prediction(pred)
    doc["check_points"] = {"left": stats.to_dict()}
    doc["reference"]["registration_estimate"] = {
        "shift_m": [-7.5, 1.0, 0.5], "sigma_m": [2.0, 2.0, 4.0],
        "prior_sigma_m": [10.0, 10.0, 5.0], "source": "srtm"}
    doc = json.loads(json.dumps(doc))
    report = REPORT.load(doc)
    assert REPORT.dump(report) == doc
    c = report.check_points["left"]
    assert (c.predicted_rms_col_px, c.predicted_rms_row_px) == (0.16, 0.14)
    assert (c.predicted_relative_rms_col_px, c.predicted_reference_rms_row_px) == (
        pred.predicted_relative_rms_col_px, 0.125)
    assert report.check_points_before["left"].predicted_rms_col_px is None
    assert "predicted_rms_col_px" not in doc["check_points_before"]["left"]
    img = report.absolute.predicted["images"]["left"]
    assert (img["predicted_rms_col_px"], img["predicted_relative_rms_row_px"]) == (
        0.16, pred.predicted_relative_rms_row_px)
    assert report.absolute.variance_components["groups"]["gcp_col"]["factor"] == 0.56
    assert report.reference.registration_estimate["shift_m"] == [-7.5, 1.0, 0.5]
    assert any(line.startswith("reference's shift     -7.5 +- 2.0") for line in report.lines())
    old = {**doc, "absolute": {k: v for k, v in doc["absolute"].items()
                               if k not in ("predicted", "variance_components")},
           "reference": {k: v for k, v in doc["reference"].items()
                         if k != "registration_estimate"}}
    back = REPORT.load(old)
    assert back.absolute.predicted is None and back.reference.registration_estimate is None
    assert REPORT.dump(back) == old
    bad = json.loads(json.dumps(doc))
    bad["absolute"]["predicted"]["images"]["left"]["predicted_rms_row_px"] = "0.1"
    with pytest.raises(InputError, match=re.escape(
            "report.json: key 'absolute.predicted.images.left.predicted_rms_row_px' must be a "
            "number, got '0.1'; give the report.json gcpfree orient wrote")):
        REPORT.load(bad)


# what a reader of the report sees in the browser
LOOK = """() => ({
  figures: Array.from(document.querySelectorAll('figure')).map(f => {
    const img = f.querySelector('img');
    return {src: img ? img.getAttribute('src') : null,
            loaded: !!img && img.complete && img.naturalWidth > 0,
            caption: (f.querySelector('figcaption') || {}).textContent || ''};
  }),
  images: document.images.length,
  sections: Array.from(document.querySelectorAll('h2')).map(h => h.textContent),
  pageWidth: document.documentElement.scrollWidth,
  windowWidth: window.innerWidth,
})"""


def look_at(page: Any, html: Path, shot: Path) -> dict[str, Any]:
    """What a reader of ``html`` sees once it has loaded: each figure with its image loaded or
    not, the sections, the page's width against the window's; a full-page screenshot in
    ``shot``."""
    page.goto(html.resolve().as_uri(), wait_until="load")
    seen = page.evaluate(LOOK)
    page.screenshot(path=str(shot), full_page=True)
    return seen


@pytest.mark.slow
def test_the_report_renders_in_headless_chromium(run, tmp_path):
    """report.html in headless Chromium (Debian's, as .ci/run installs it): every figure of
    the run is there with its image loaded and a caption, the page is no wider than the window
    (wide tables scroll in their own box), the screenshot is not blank; and the same look
    catches a figure whose PNG has gone."""
    from tests.browser import chromium

    _, out, outcome, _ = run
    gone = tmp_path / "gone"
    gone.mkdir()
    shutil.copy(outcome.html, gone)
    shutil.copytree(out / FIGURES_DIR, gone / FIGURES_DIR)
    (gone / FIGURES_DIR / "profile.png").unlink()
    shot = tmp_path / "report.png"
    with chromium() as browser:
        page = browser.new_page(viewport={"width": 1280, "height": 2400})
        seen = look_at(page, outcome.html, shot)
        missing = look_at(page, gone / "report.html", tmp_path / "gone.png")
    print(f"screenshot of the report: {shot}")
    assert {Path(f["src"]).stem for f in seen["figures"]} == FIGURES
    assert [f["src"] for f in seen["figures"] if not f["loaded"]] == []
    assert seen["images"] == len(FIGURES) and all(f["caption"] for f in seen["figures"])
    assert seen["sections"][:4] == ["Summary", "Inputs", "Tie points", "Relative orientation"]
    assert seen["pageWidth"] <= seen["windowWidth"], "the page scrolls sideways"
    with Image.open(shot) as im:
        assert im.width == 1280 and im.height > 2400
        assert np.asarray(im.convert("L")).std() > 5
    assert [f["src"] for f in missing["figures"] if not f["loaded"]] == [
        f"{FIGURES_DIR}/profile.png"]
