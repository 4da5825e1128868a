"""``gcpfree evaluate`` end to end: the parser built from ``flows.commands.evaluate``, the
flow under the Prefect harness writing eval.json, and bad input (one line on stderr, exit 2,
no traceback, nothing written) caught before Prefect starts."""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyproj
import pytest

from core.errors import GcpFreeError
from flows.cli import main
from flows.commands.evaluate import add_parser, run
from tests.tasks.test_evaluate import (
    AUTZEN,
    CELL,
    UTM31,
    X0,
    Y1,
    dem_at,
    dem_surface,
    egm96_n_m,
    write_las,
    write_raster,
)

REPO = Path(__file__).resolve().parents[2]


def _parser() -> argparse.ArgumentParser:
    """What flows/cli.py does with the module: its parser under ``gcpfree``."""
    parser = argparse.ArgumentParser(prog="gcpfree")
    add_parser(parser.add_subparsers(dest="command", required=True))
    return parser


def _cli(argv: list[str]) -> int:
    """``gcpfree.main`` for this command: GcpFreeError -> one line, exit 2."""
    args = _parser().parse_args(["evaluate", *argv])
    try:
        return run(args)
    except GcpFreeError as exc:
        print(f"gcpfree evaluate: error: {exc}", file=sys.stderr)
        return 2


@pytest.fixture(scope="module")
def scene(tmp_path_factory) -> dict[str, Path]:
    """A DEM (ellipsoidal) and 3000 lidar points 0.4 m below it (ground) or 1.5 m above it
    (class 5), in UTM 31N with EGM96 heights."""
    tmp = tmp_path_factory.mktemp("cli")
    z = dem_surface(60, 80)
    dem = write_raster(tmp / "dsm.tif", z, UTM31, (CELL, 0, X0, 0, -CELL, Y1),
                       tags={"vertical_datum": "WGS84 ellipsoid"})
    rng = np.random.default_rng(9)
    x = X0 + rng.uniform(2, 158, 3000)
    y = Y1 - rng.uniform(2, 118, 3000)
    cls = rng.choice([2, 5], 3000)
    h = dem_at(z, X0, Y1, CELL, x, y) - np.where(cls == 2, 0.4, -1.5)
    lon, lat = pyproj.Transformer.from_crs(UTM31, "EPSG:4326", always_xy=True).transform(x, y)
    H = h - egm96_n_m(np.asarray(lon), np.asarray(lat))
    laz = write_las(tmp / "points.laz", x, y, H, cls, pyproj.CRS(f"{UTM31}+5773"))
    nocrs = write_las(tmp / "nocrs.laz", x, y, H, cls, None)
    cut = tmp / "cut.laz"
    cut.write_bytes(laz.read_bytes()[: laz.stat().st_size // 2])
    far = write_raster(tmp / "far.tif", z, UTM31, (CELL, 0, X0 - 90_000, 0, -CELL, Y1),
                       tags={"vertical_datum": "WGS84 ellipsoid"})
    return {"dem": dem, "laz": laz, "nocrs": nocrs, "cut": cut, "far": far, "dir": tmp}


def test_evaluate_writes_eval_json(prefect_harness, scene, tmp_path, capsys):
    out = tmp_path / "eval.json"
    rc = _cli(["--dem", str(scene["dem"]), "--lidar", str(scene["laz"]), "--out", str(out),
               "--classes", "2,5", "--chunk-points", "1000", "--seed", "4"])
    printed = capsys.readouterr().out
    assert rc == 0
    assert "2 ground" in printed and "5 high vegetation" in printed and str(out) in printed
    d = json.loads(out.read_text())
    assert d["format"] == "gcpfree.evaluation" and d["heights_compared"] == "ellipsoidal"
    assert d["lidar"]["vertical"] == "egm96" and d["dem"]["vertical"] == "ellipsoidal"
    assert set(d["classes"]) == {"2", "5"} and d["class_filter"] == [2, 5]
    for block in (*d["classes"].values(), d["all"]):
        assert {"count", "mean", "std", "rmse", "nmad", "le68", "le90", "le68_ci"} <= set(block)
    assert d["classes"]["2"]["mean"] == pytest.approx(0.4, abs=2e-3)
    assert d["classes"]["5"]["mean"] == pytest.approx(-1.5, abs=2e-3)
    assert d["all"]["count"] == 3000 == d["points"]["evaluated"]
    assert d["statistics"]["seed"] == 4


def _bad(capsys, argv: list[str], match: str, out: Path) -> None:
    assert _cli([*argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("gcpfree evaluate: error: ")
    assert "Traceback" not in err and match in err, err
    assert not out.exists()


def test_bad_input_is_one_line_and_exit_2(scene, tmp_path, capsys):
    out = tmp_path / "eval.json"
    dem, laz = str(scene["dem"]), str(scene["laz"])
    _bad(capsys, ["--dem", dem, "--lidar", str(tmp_path / "none.laz")], "does not exist", out)
    _bad(capsys, ["--dem", str(tmp_path / "none.tif"), "--lidar", laz], "does not exist", out)
    _bad(capsys, ["--dem", dem, "--lidar", str(scene["nocrs"])], "--lidar-crs", out)
    _bad(capsys, ["--dem", str(scene["far"]), "--lidar", laz], "does not cover the lidar (x",
         out)
    _bad(capsys, ["--dem", dem, "--lidar", str(scene["cut"])], "truncated", out)
    _bad(capsys, ["--dem", dem, "--lidar", laz, "--lidar-crs", "EPSG:0"], "not a CRS", out)
    _bad(capsys, ["--dem", dem, "--lidar", laz, "--ci-level", "1.5"], "confidence level", out)
    blocker = tmp_path / "file"
    blocker.write_text("")
    _bad(capsys, ["--dem", dem, "--lidar", laz, "--landcover", str(blocker)], "cannot read",
         out)
    assert _cli(["--dem", dem, "--lidar", laz, "--out", str(blocker / "e.json")]) == 2
    assert "cannot write" in capsys.readouterr().err


def test_parser_help_and_bad_classes(capsys):
    with pytest.raises(SystemExit) as exc:
        _parser().parse_args(["evaluate", "--help"])
    assert exc.value.code == 0
    text = capsys.readouterr().out
    for opt in ("--dem", "--lidar", "--out", "--landcover", "--landcover-names",
                "--lidar-vertical", "--dem-vertical", "--lidar-crs", "--lidar-z-unit",
                "--classes", "--mask", "--gcps", "--chunk-points", "--ci-level", "--seed"):
        assert opt in text
    with pytest.raises(SystemExit) as exc:
        _parser().parse_args(["evaluate", "--dem", "a", "--lidar", "b", "--out", "c",
                              "--classes", "2,x"])
    assert exc.value.code == 2 and "LAS codes" in capsys.readouterr().err


def test_command_imports_light_and_refuses_in_one_line(scene, tmp_path):
    """The command module (what the gcpfree parser imports) loads no Prefect, rasterio or
    laspy; ``python -m flows.cli evaluate``: bad input is one line and exit 2."""
    code = ("import sys; import flows.cli, flows.commands.evaluate; "
            "sys.exit(10 * any(m in sys.modules for m in ('prefect', 'rasterio', 'laspy')))")
    proc = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True,
                          text=True, timeout=120, check=False)
    assert proc.returncode == 0, proc.stderr
    proc = subprocess.run([sys.executable, "-m", "flows.cli", "evaluate", "--dem",
                           str(scene["dem"]), "--lidar", str(AUTZEN), "--out",
                           str(tmp_path / "e.json")],
                          cwd=REPO, capture_output=True, text=True, timeout=120, check=False)
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1
    assert "does not cover the lidar" in proc.stderr and "Traceback" not in proc.stderr
    assert main(["evaluate", "--dem", str(tmp_path / "x.tif"), "--lidar", str(AUTZEN),
                 "--out", str(tmp_path / "e.json")]) == 2
