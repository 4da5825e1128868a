"""``gcpfree report OUT_DIR``: the report of an existing orient output made again from its
files (the parser built from ``flows.commands.report.add_parser``), with and without the
optional inputs; bad input one line (exit 2) with nothing written; a light import."""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import pytest

from core.errors import GcpFreeError
from flows.commands.report import add_parser, run
from tests.tasks.test_report import (
    FIGURES,
    assert_valid_pngs,
    both_tables,
    copy_orient_output,
    images_of,
    same,
)

REPO = Path(__file__).resolve().parents[2]


def _cli(argv: list[str]) -> int:
    """What flows/cli.py does with the module: its parser under ``gcpfree``, GcpFreeError ->
    one line on stderr, exit 2."""
    parser = argparse.ArgumentParser(prog="gcpfree")
    add_parser(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(["report", *argv])
    try:
        return run(args)
    except GcpFreeError as exc:
        print(f"gcpfree report: error: {exc}", file=sys.stderr)
        return 2


@pytest.fixture
def out(tiny_oriented, tmp_path) -> Path:
    return copy_orient_output(tiny_oriented[1], tmp_path / "out")


def test_report_of_an_orient_output_with_every_input(tiny_oriented, out, tmp_path, capsys):
    scene = tiny_oriented[0]
    ev = {"format": "gcpfree.evaluation", "version": 1,
          "classes": {"2": {"count": 812, "mean": -0.25, "le68": 1.625, "le90": 2.875,
                            "le68_ci": [1.5, 1.75]}},
          "class_labels": {"2": "ground"}}
    evaluation = tmp_path / "eval.json"
    evaluation.write_text(json.dumps(ev))
    assert _cli([str(out), "--reference", str(scene / "reference.tif"), "--checkpoints",
                 str(scene / "truth" / "checkpoints.json"), "--evaluation", str(evaluation),
                 "--max-shift", "15"]) == 0
    printed = capsys.readouterr().out
    assert f"report                {out / 'report.html'}" in printed
    assert "not available" not in printed
    html_imgs, md_imgs = images_of(out)
    assert html_imgs == md_imgs and {Path(s).stem for s in html_imgs} == FIGURES
    assert_valid_pngs(out, html_imgs)
    rep = json.loads((out / "report.json").read_text())["report"]
    assert rep["inputs"]["evaluation"] == str(evaluation) and rep["not_available"] == []
    assert rep["correlation_surface"]["shift_max_arcsec"] == 15.0  # --max-shift reached it
    for tables in both_tables(out):
        lidar = next(t for c, t in tables.items() if c.startswith("DEM - lidar per class"))
        (row,) = lidar[1]
        assert row[:2] == ["2", "ground"] and same(row[2], 812)
        assert same(row[7], 1.625) and same(row[8], 2.875)  # le68, le90 as in eval.json


def test_optional_inputs_missing_give_not_available_lines(out, capsys):
    assert _cli([str(out)]) == 0
    printed = capsys.readouterr().out
    html = (out / "report.html").read_text()
    md = (out / "report.md").read_text()
    for what in ("the reference DEM (not given", "the check-point file",
                 "the lidar evaluation (not given"):
        assert f"not available         {what}" in printed, what
        assert f"Not available: {what}" in html and f"Not available: {what}" in md, what
    assert {Path(s).stem for s in images_of(out)[0]} == {
        "tie_points", "relief", "gcp_residuals", "row_profile", "histograms"}


def test_bad_input_is_one_line_and_writes_nothing(out, tmp_path, capsys):
    empty = tmp_path / "empty"
    empty.mkdir()
    not_eval = tmp_path / "not_eval.json"
    not_eval.write_text(json.dumps({"all": {}}))
    cases = [([str(tmp_path / "nope")], "is not a folder"),
             ([str(empty)], "holds no gcpfree orient products"),
             ([str(out), "--evaluation", str(not_eval)], "not an eval.json"),
             ([str(out), "--evaluation", str(tmp_path / "no.json")], "cannot read the evaluation"),
             ([str(out), "--checkpoints", str(tmp_path / "cp.json")], "cp.json"),
             ([str(out), "--reference", str(tmp_path / "ref.tif")], "does not exist")]
    for argv, message in cases:
        assert _cli(argv) == 2, argv
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and message in err, (argv, err)
    assert not (out / "report.html").exists() and not (empty / "report.html").exists()
    assert "report" not in json.loads((out / "report.json").read_text())


def test_importing_the_command_is_light():
    code = ("import sys, flows.commands.report; "
            "print(sorted(m for m in ('prefect', 'matplotlib', 'rasterio', 'numpy') "
            "if m in sys.modules))")
    res = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True,
                         text=True, check=True)
    assert res.stdout.strip() == "[]"
