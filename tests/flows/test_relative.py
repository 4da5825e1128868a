"""`gcpfree relative` end to end: simulated pairs against their truth (both sensor families),
the real Ventoux Pleiades pair and its known RPC inconsistency, and bad input."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from core.orientation.relative import epipolar_fit
from core.sensors.pushbroom import PushbroomModel
from core.sensors.rpc import RPCModel
from flows.relative import RelativeParams, relative_flow
from tasks.geoid import BUNDLED_SRTM_DIR
from tasks.sensor_io import load_model

SRTM = BUNDLED_SRTM_DIR / "N44E005.hgt"
DATA = Path(__file__).resolve().parents[1] / "data"
VENTOUX = DATA / "pleiades_ventoux"


def check_point_parallax(out: Path, scene_dir: Path, rel_json: Path) -> float:
    """RMS y-parallax of the scene's check points (TRUE correspondences, not matched) under the
    left model and the adjusted right model: the relative orientation measured independently
    of the tie points."""
    doc = json.loads(rel_json.read_text())
    left = load_model(scene_dir / "left.tif", model=Path(doc["left"]["model"])).model
    d = doc["right_model"]
    right = (RPCModel.from_dict(d) if d.get("type") == "rpc" else PushbroomModel.from_dict(d))
    pts = json.loads((scene_dir / "truth" / "checkpoints.json").read_text())["points"]
    lc, lr = (np.array([p["left"][k] for p in pts]) for k in ("col", "row"))
    rc, rr = (np.array([p["right"][k] for p in pts]) for k in ("col", "row"))
    fit = epipolar_fit(left, right, lc, lr, rc, rr, np.array([p["h_m"] for p in pts]))
    return float(np.sqrt(np.mean(fit.parallax_px**2)))


@pytest.fixture(scope="module")
def clean_runs(prefect_harness, tiny_clean_scene, tmp_path_factory):
    """The clean tiny scene oriented from its SPOT metadata and from its RPC tags."""
    scene_dir, _ = tiny_clean_scene
    out = tmp_path_factory.mktemp("rel")
    runs = {}
    for family, models in (("pushbroom", (None, None)),
                           ("rpc", (scene_dir / "left.tif", scene_dir / "right.tif"))):
        runs[family] = relative_flow(RelativeParams(
            left=scene_dir / "left.tif", right=scene_dir / "right.tif",
            left_model=models[0], right_model=models[1], reference=SRTM, cell_m=1000.0,
            out=out / f"{family}.json"))
    return scene_dir, runs


@pytest.mark.parametrize("family", ["pushbroom", "rpc"])
def test_simulated_pair_is_relatively_oriented(clean_runs, family):
    scene_dir, runs = clean_runs
    outcome = runs[family]
    doc = json.loads(outcome.rel_json.read_text())
    assert doc["right"]["family"] == family
    for key in ("tie_points", "tie_points_rejected", "parallax_rms_before_px",
                "parallax_rms_after_px", "right_correction", "epipolar_direction",
                "along_epipolar_observable", "right_model"):
        assert key in doc, key
    assert {"col_shift_px", "row_shift_px", "across_epipolar_px", "along_epipolar_px",
            "affine"} <= set(doc["right_correction"])
    assert doc["parallax_rms_before_px"] > 1.5  # the metadata are off by 100-300 m each
    assert doc["parallax_rms_after_px"] <= 0.3
    search = doc["tie_point_search"]
    assert search["coverage_textured"] >= 0.8, search
    # the truth's own correspondences agree with the adjusted pair
    assert check_point_parallax(outcome.rel_json.parent, scene_dir, outcome.rel_json) <= 0.3
    # with a reference DEM the along-epipolar part is estimated, with its uncertainty
    assert doc["along_epipolar_observable"] is True
    assert doc["along_epipolar"]["sigma_px"] > 0
    ties = json.loads(outcome.rel_json.with_suffix(".tiepoints.json").read_text())
    assert len(ties["relative_ground"]["h_m"]) == doc["tie_points"] + doc["tie_points_rejected"]


def test_without_reference_the_along_epipolar_part_is_held(prefect_harness, tiny_clean_scene,
                                                             tmp_path):
    scene_dir, _ = tiny_clean_scene
    outcome = relative_flow(RelativeParams(
        left=scene_dir / "left.tif", right=scene_dir / "right.tif", height_range_m=(0.0, 2500.0),
        cell_m=1000.0, out=tmp_path / "rel.json"))
    doc = json.loads(outcome.rel_json.read_text())
    assert doc["along_epipolar_observable"] is False
    assert abs(doc["right_correction"]["along_epipolar_px"]) < 0.05
    assert doc["parallax_rms_after_px"] <= 0.3


def test_ventoux_rpc_inconsistency_is_found_and_a_known_bias_recovered(prefect_harness, tmp_path):
    """The Ventoux pair's RPCs disagree by about 4.8 px across the epipolar lines; the answer
    holds when the tie-point set changes, and a bias added to the right RPC (tens of lines and
    columns) changes the across-epipolar correction by the bias's across part."""
    def run(right_geom: Path, cell_m: float, name: str) -> dict:
        right = tmp_path / f"{name}.tif"
        shutil.copy(VENTOUX / "right_image.tif", right)
        shutil.copy(right_geom, right.with_suffix(".geom"))
        outcome = relative_flow(RelativeParams(
            left=VENTOUX / "left_image.tif", right=right, reference=SRTM, cell_m=cell_m,
            out=tmp_path / f"{name}.json"))
        return json.loads(outcome.rel_json.read_text())

    a = run(VENTOUX / "right_image.geom", 50.0, "a")
    b = run(VENTOUX / "right_image.geom", 35.0, "b")
    across_a = a["right_correction"]["across_epipolar_px"]
    assert 4.0 < abs(across_a) < 5.5
    assert abs(across_a - b["right_correction"]["across_epipolar_px"]) < 0.05
    assert a["parallax_rms_after_px"] < 0.4
    # a known bias: 30 lines and -20 columns added to the right image's RPC (its offsets)
    geom = (VENTOUX / "right_image.geom").read_text().splitlines()
    shifted = []
    for line in geom:
        key, _, value = line.partition(":")
        if key.strip() == "line_off":
            line = f"{key}: {float(value) + 30.0}"
        elif key.strip() == "samp_off":
            line = f"{key}: {float(value) - 20.0}"
        shifted.append(line)
    biased = tmp_path / "biased.geom"
    biased.write_text("\n".join(shifted) + "\n")
    c = run(biased, 50.0, "c")
    t = np.array(a["epipolar_direction"])
    normal = np.array([-t[1], t[0]])
    bias_across = float(normal @ np.array([-20.0, 30.0]))
    change = c["right_correction"]["across_epipolar_px"] - across_a
    # the correction undoes the bias: it moves the right projections back by the bias
    assert change == pytest.approx(-bias_across, abs=0.2)


def cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "flows.cli", "relative", *args],
                          capture_output=True, text=True, timeout=300, check=False)


def test_bad_input_is_one_line(tiny_clean_scene, tmp_path):
    scene_dir, _ = tiny_clean_scene
    left, right = scene_dir / "left.tif", scene_dir / "right.tif"
    r = cli("--left", str(left), "--right", str(tmp_path / "none.tif"), "--out",
            str(tmp_path / "r.json"))
    assert r.returncode == 2 and "does not exist" in r.stderr and "Traceback" not in r.stderr
    # a model that does not belong to the image: the footprints are far apart
    r = cli("--left", str(left), "--right", str(right), "--right-model",
            str(DATA / "pleiades_gizeh" / "img1.geom"), "--reference", str(SRTM),
            "--out", str(tmp_path / "r.json"))
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert "do not overlap" in r.stderr or "does not cover" in r.stderr, r.stderr
    assert not (tmp_path / "r.json").exists()
    # a featureless right image (cloud): too few tie points, and the reasons
    import warnings

    import rasterio
    from rasterio.errors import NotGeoreferencedWarning

    blank = tmp_path / "blank.tif"
    with rasterio.open(right) as src:
        size, dtype = (src.height, src.width), src.dtypes[0]
    with warnings.catch_warnings():  # a raw Level 1A image has no georeferencing
        warnings.simplefilter("ignore", NotGeoreferencedWarning)
        with rasterio.open(blank, "w", driver="GTiff", width=size[1], height=size[0], count=1,
                           dtype=dtype) as dst:
            dst.write(np.full(size, 230, dtype), 1)
    shutil.copy(scene_dir / "right.DIM", tmp_path / "blank.DIM")
    r = cli("--left", str(left), "--right", str(blank), "--reference", str(SRTM),
            "--out", str(tmp_path / "r.json"))
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert "tie points" in r.stderr and "interest points" in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
