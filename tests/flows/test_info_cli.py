"""``gcpfree info`` end to end: a real stereo pair with --json, SPOT metadata, bad input
(one line on stderr, exit 2, no traceback), and no Prefect on the way."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

from flows.cli import main

REPO = Path(__file__).resolve().parents[2]
VENTOUX = REPO / "tests" / "data" / "pleiades_ventoux"
SHARED = REPO.parent / "shared" / "data" / "spot_dimap"


def test_ventoux_pair_with_json(tmp_path, capsys):
    out = tmp_path / "info.json"
    rc = main(["info", str(VENTOUX / "left_image.tif"), str(VENTOUX / "right_image.tif"),
               "--json", str(out)])
    printed = capsys.readouterr()
    assert rc == 0 and printed.err == ""
    assert "B/H" in printed.out and str(out) in printed.out
    d = json.loads(out.read_text())
    assert d["family"] == "rpc" and d["size"] == {"cols": 500, "rows": 500}
    assert [(c["col"], c["row"]) for c in d["corners"]] == [(0, 0), (499, 0), (499, 499),
                                                            (0, 499)]
    assert all(set(c) == {"col", "row", "lon_deg", "lat_deg"} for c in d["corners"])
    assert all(5.19 < c["lon_deg"] < 5.20 and 44.20 < c["lat_deg"] < 44.21 for c in d["corners"])
    for key in ("source", "incidence_deg", "azimuth_deg", "gsd_m", "acquisition_utc",
                "metadata_corner_check_m", "reference", "image2"):
        assert key in d
    assert d["image2"]["size"] == {"cols": 498, "rows": 495}
    assert {"b_over_h", "convergence_deg", "overlap_pct"} <= set(d["pair"])
    assert 0.15 < d["pair"]["b_over_h"] < 0.8


@pytest.mark.skipif(not SHARED.is_dir(), reason="../shared/data/spot_dimap is absent")
def test_spot_metadata_file_alone(tmp_path, capsys):
    out = tmp_path / "spot5.json"
    assert main(["info", str(SHARED / "SPOT5.DIM"), "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "SPOT 5 HRG" in text and "corner check" in text
    d = json.loads(out.read_text())
    assert d["metadata_corner_check_m"]["max"] < 1.0 and d["mission"] == "SPOT 5"
    assert d["acquisition_utc"].startswith("2005-03-13T05:21:")


def _bad(capsys, argv: list[str], match: str) -> None:
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("gcpfree info: error: ")
    assert "Traceback" not in err and match in err


def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys):
    _bad(capsys, ["info", str(tmp_path / "missing.tif")], "does not exist")
    junk = tmp_path / "scene.foo"
    junk.write_text("not an image")
    _bad(capsys, ["info", str(junk)], "cannot read image")
    _bad(capsys, ["info", str(VENTOUX / "left_image.tif"), "--model", str(junk)],
         "unknown model format")
    bad_json = tmp_path / "model.json"
    bad_json.write_text("{}")
    _bad(capsys, ["info", str(bad_json)], "model.json")
    _bad(capsys, ["info", str(VENTOUX / "left_image.tif"), "--model2", str(junk)], "IMAGE2")
    _bad(capsys, ["info", str(VENTOUX / "left_image.tif"), "--reference", str(junk)],
         "reference DEM")
    blocker = tmp_path / "file"
    blocker.write_text("")
    _bad(capsys, ["info", str(VENTOUX / "left_image.tif"), "--json",
                  str(blocker / "info.json")], "cannot write")


def test_the_command_runs_without_prefect():
    code = ("import sys; from flows.cli import main; "
            f"rc = main(['info', {str(VENTOUX / 'left_image.tif')!r}]); "
            "sys.exit(rc if rc else 10 * ('prefect' in sys.modules))")
    proc = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "incidence" in proc.stdout
