"""``--srtm-dir`` instead of ``--reference``: ``orient``, ``pair`` and ``archive`` on the tiny
pair with the folder of the bundled tile (``tasks/data``: N44E005.hgt, the DEM the scene was
simulated over, where ``reference.tif`` is a degraded copy of it). Each succeeds, agrees with
the session's ``--reference`` orientation to a fraction of a pixel, and its products name the
reference made from the tiles. One orientation runs; ``pair`` and ``archive`` resume from
it."""

from __future__ import annotations

import argparse
import csv
import io
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import rasterio

from flows.commands import archive as archive_command
from flows.commands import orient as orient_command
from flows.commands import pair as pair_command
from tasks.absolute.orientation import read_checkpoints
from tasks.io.geoid import BUNDLED_SRTM_DIR
from tasks.io.sensors import load_model

MADE = Path("relative") / "rel.reference.tif"  # where the orientation writes its reference


def parse(module, command: str, *argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="gcpfree")
    module.add_parser(parser.add_subparsers(dest="command"))
    return parser.parse_args([command, *argv])


def pair_args(scene: Path) -> list[str]:
    return ["--left", str(scene / "left.tif"), "--right", str(scene / "right.tif"),
            "--srtm-dir", str(BUNDLED_SRTM_DIR), "--checkpoints",
            str(scene / "truth" / "checkpoints.json"), "--self-calibrate", "--no-progress"]


@pytest.fixture(scope="module")
def srtm_oriented(tiny_scene, tmp_path_factory, prefect_harness):
    """``gcpfree orient --srtm-dir tasks/data`` on the tiny pair, options as the session's
    ``tiny_oriented``: (scene, out, report)."""
    scene, _ = tiny_scene
    out = tmp_path_factory.mktemp("srtm") / "orient"
    assert orient_command.run(parse(orient_command, "orient", *pair_args(scene),
                                    "--out", str(out))) == 0
    return scene, out, json.loads((out / "report.json").read_text())


def check_point_pixels(models, scene: Path) -> list[np.ndarray]:
    """Where each model puts the check points' ground, (n, 2) per image."""
    pts = read_checkpoints(scene / "truth" / "checkpoints.json").points
    lon, lat, h = (np.array([getattr(p, k) for p in pts]) for k in ("lon_deg", "lat_deg", "h_m"))
    return [np.stack(m.project(lon, lat, h), axis=1) for m in models]


def resumed(srtm_oriented, folder: Path) -> Path:
    """A copy of the ``--srtm-dir`` orientation for a command to resume from."""
    _, out, _ = srtm_oriented
    shutil.copytree(out, folder)
    return folder


def test_orient_with_srtm_dir_agrees_with_the_reference_run(srtm_oriented, tiny_oriented):
    """Measured: 26 of 34 GCPs kept (28 of 36 with the reference); check points 0.65/0.48 px
    left, 0.37/0.37 px right (col/row RMS; 0.66/0.46, 0.38/0.30 with the reference); the two
    runs' models put the check points 0.10 px apart (median; at most 0.6 px), a 40 m pixel's
    few metres: the same GCP-free orientation on another copy of the same ground."""
    scene, out, report = srtm_oriented
    _, ref_out, ref_outcome = tiny_oriented
    assert report["gcps"]["used"] >= 8
    for name in ("left", "right"):
        cp = report["check_points"][name]
        assert cp["n"] >= 50 and cp["rms_col_px"] < 0.7 and cp["rms_row_px"] < 0.7, cp
        ours = [load_model(out / f"{name}.json").model]
        theirs = [load_model(ref_out / f"{name}.json").model]
        gap = np.hypot(*(check_point_pixels(ours, scene)[0]
                         - check_point_pixels(theirs, scene)[0]).T)
        assert np.median(gap) < 0.3 and gap.max() < 1.0, (name, np.median(gap), gap.max())
    assert report["dsm"]["summary"]["completeness_pct"] == pytest.approx(
        ref_outcome.report.dsm.summary.completeness_pct, abs=2.0)
    # the products name the reference made from the tiles, and it says what it was made of
    assert report["report"]["inputs"]["reference"] == str(out / MADE)
    assert report["reference"]["srtm_dir"] == str(BUNDLED_SRTM_DIR)
    assert report["reference"]["path"] == str(out / MADE) and report["reference"]["given"] is None
    made = json.loads((out / MADE).with_suffix(".json").read_text())
    assert made["tiles"] == ["N44E005.hgt"] and made["coverage_pct"] > 90.0
    with rasterio.open(out / MADE) as src:
        assert "ellipsoid" in src.tags()["vertical_datum"].lower()


def test_pair_with_srtm_dir_resumes_and_orthorectifies_on_the_made_reference(
        srtm_oriented, tmp_path):
    """``gcpfree pair --srtm-dir``: the orientation kept, both orthos over the reference the
    orientation made (not the SRTM tile as such, not another one), and they agree as the
    ``--reference`` pair's do (median 0.57 px there)."""
    from tasks.archive.pair import pair_complete

    scene, _, report = srtm_oriented
    out = resumed(srtm_oriented, tmp_path / "tiny")
    assert pair_command.run(parse(pair_command, "pair", *pair_args(scene),
                                  "--out", str(out))) == 0
    assert pair_complete(out)
    manifest = json.loads((out / "pair.json").read_text())
    assert manifest["params"]["srtm_dir"] == str(BUNDLED_SRTM_DIR)
    assert manifest["params"]["reference"] is None
    assert json.loads((out / "report.json").read_text())["gcps"] == report["gcps"]  # kept
    for name in ("left", "right"):
        with rasterio.open(out / f"ortho_{name}.tif") as src:
            assert src.tags()["dem"] == MADE.name
    cmp = json.loads((out / "ortho_compare.json").read_text())
    assert cmp["n_valid"] >= 50 and cmp["px"]["median_norm"] < 1.0


def test_archive_with_srtm_dir(srtm_oriented, tmp_path, capsys):
    """``gcpfree archive --srtm-dir`` on a CSV catalog of the tiny pair (its orientation
    already there): done, the summary's figures are the orientation's, the pair's manifest
    names the tile folder and its orthos the made reference."""
    scene, _, report = srtm_oriented
    cat = tmp_path / "catalog.csv"
    cat.write_text("id,left,right,checkpoints\n"
                   f"tiny,{scene / 'left.tif'},{scene / 'right.tif'},"
                   f"{scene / 'truth' / 'checkpoints.json'}\n")
    root = tmp_path / "root"
    resumed(srtm_oriented, root / "tiny")
    rc = archive_command.run(parse(
        archive_command, "archive", "--catalog", str(cat), "--out", str(root), "--srtm-dir",
        str(BUNDLED_SRTM_DIR), "--self-calibrate", "--workers", "1", "--threads",
        "--dashboard-address", ":0", "--no-progress"))
    assert rc == 0, capsys.readouterr().out
    (row,) = csv.DictReader(io.StringIO((root / "summary.csv").read_text()))
    assert row["status"] == "done" and int(row["gcps"]) == report["gcps"]["used"]
    for side in ("left", "right"):
        assert float(row[f"cp_{side}_rms_col_px"]) == pytest.approx(
            report["check_points"][side]["rms_col_px"], rel=1e-5)
    manifest = json.loads((root / "tiny" / "pair.json").read_text())
    assert manifest["params"]["srtm_dir"] == str(BUNDLED_SRTM_DIR.resolve())
    with rasterio.open(root / "tiny" / "ortho_left.tif") as src:
        assert src.tags()["dem"] == MADE.name
