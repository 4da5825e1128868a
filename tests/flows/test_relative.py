"""`gcpfree relative` end to end: simulated pairs against their truth (both sensor families),
the real Ventoux Pleiades pair and its known RPC inconsistency, and bad input."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from core.matching.tiepoints import TiePointConfig
from core.orientation.relative import epipolar_fit
from core.sensors.pushbroom import PushbroomModel
from core.sensors.rpc import RPCModel
from flows.relative import RelativeParams, relative_flow
from tasks.io.geoid import BUNDLED_SRTM_DIR
from tasks.io.pair import PairInputs
from tasks.io.sensors import load_model

SRTM = BUNDLED_SRTM_DIR / "N44E005.hgt"
DATA = Path(__file__).resolve().parents[1] / "data"
VENTOUX = DATA / "pleiades_ventoux"
SHARED = Path(os.environ.get("GCPFREE_SHARED_DATA", "/work/shared/data"))
GIZEH = SHARED / "pleiades_gizeh"


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
            pair=PairInputs(scene_dir / "left.tif", scene_dir / "right.tif", models[0],
                            models[1], reference=SRTM),
            cell_m=1000.0, out=out / f"{family}.json"))
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


def test_the_tie_measure_follows_the_suns(clean_runs):
    """The tiny pair's DIMAP files state two suns (140 / 63 and 158 / 50 deg): orientation
    correlation; its RPC tags state none: NCC. Said in the output and recorded in rel.json."""
    _, runs = clean_runs
    for family, measure, why in (("pushbroom", "orientation", "16.2 deg apart"),
                                 ("rpc", "ncc", "not in both images' metadata")):
        outcome = runs[family]
        doc = json.loads(outcome.rel_json.read_text())
        assert doc["tie_point_search"]["measure"] == measure
        line = next(x for x in outcome.lines if x.startswith("tie-point measure"))
        assert why in line, line


def test_without_reference_the_along_epipolar_part_is_held(prefect_harness, tiny_clean_scene,
                                                             tmp_path):
    scene_dir, _ = tiny_clean_scene
    outcome = relative_flow(RelativeParams(
        pair=PairInputs(scene_dir / "left.tif", scene_dir / "right.tif"),
        height_range_m=(0.0, 2500.0), cell_m=1000.0, out=tmp_path / "rel.json"))
    doc = json.loads(outcome.rel_json.read_text())
    assert doc["along_epipolar_observable"] is False
    assert abs(doc["right_correction"]["along_epipolar_px"]) < 0.05
    assert doc["parallax_rms_after_px"] <= 0.3


def test_ventoux_rpc_inconsistency_is_found_and_a_known_bias_recovered(prefect_harness, tmp_path):
    """The Ventoux pair's RPCs disagree by about 4.8 px across the epipolar lines; the answer
    holds when the tie-point set changes (the default cell, cut to 8 x 8 cells of ~20 m over
    the ~500 px crops, or 35 m cells as given), and a bias added to the right RPC (tens of lines
    and columns) changes the across-epipolar correction by the bias's across part."""
    def run(right_geom: Path, name: str, cell_m: float = 2000.0, min_cells: int = 8) -> dict:
        right = tmp_path / f"{name}.tif"
        shutil.copy(VENTOUX / "right_image.tif", right)
        shutil.copy(right_geom, right.with_suffix(".geom"))
        outcome = relative_flow(RelativeParams(
            pair=PairInputs(VENTOUX / "left_image.tif", right, reference=SRTM), cell_m=cell_m,
            tie_points=TiePointConfig(min_cells_per_side=min_cells),
            out=tmp_path / f"{name}.json"))
        return json.loads(outcome.rel_json.read_text())

    a = run(VENTOUX / "right_image.geom", "a")
    b = run(VENTOUX / "right_image.geom", "b", cell_m=35.0, min_cells=0)
    assert a["tie_point_search"]["cell_m"] < 30.0 and b["tie_point_search"]["cell_m"] == 35.0
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
    c = run(biased, "c")
    t = np.array(a["epipolar_direction"])
    normal = np.array([-t[1], t[0]])
    bias_across = float(normal @ np.array([-20.0, 30.0]))
    change = c["right_correction"]["across_epipolar_px"] - across_a
    # the correction undoes the bias: it moves the right projections back by the bias
    assert change == pytest.approx(-bias_across, abs=0.2)


REAL_CROPS = [
    pytest.param(VENTOUX / "left_image.tif", VENTOUX / "right_image.tif", id="ventoux"),
    pytest.param(DATA / "pleiades_reunion" / "img_01.tif", DATA / "pleiades_reunion" / "img_02.tif",
                 id="reunion"),
    pytest.param(GIZEH / "img1.tif", GIZEH / "img2.tif", id="gizeh", marks=pytest.mark.skipif(
        not (GIZEH / "img1.tif").is_file(), reason="the shared Gizeh pair is not on this machine")),
]


@pytest.mark.parametrize(("left", "right"), REAL_CROPS)
def test_real_crops_without_reference(prefect_harness, left, right, tmp_path):
    """`gcpfree relative` with no reference on Pleiades crops of 250-520 m (regression: the
    default 2 km cell held no full cell of the overlap, so no tie point was searched): the
    overlap is judged over the RPCs' height range and cut into 8 x 8 cells. Measured (3
    candidates per cell, to keep the test short): Ventoux 28 tie points in 27.7 m cells,
    4.75 -> 0.13 px, across-epipolar -4.79 px (-4.83 px with the SRTM reference); Reunion 63,
    64.7 m, 0.70 -> 0.11 px; Gizeh 61, 52.6 m, 0.52 -> 0.06 px."""
    outcome = relative_flow(RelativeParams(
        pair=PairInputs(left, right), out=tmp_path / "rel.json",
        tie_points=TiePointConfig(candidates_per_cell=3)))
    doc = json.loads(outcome.rel_json.read_text())
    search = doc["tie_point_search"]
    assert search["cell_m"] < 100.0 and 49 <= search["n_cells"] <= 100, search
    assert doc["tie_points"] >= 20
    assert doc["along_epipolar_observable"] is False
    assert doc["parallax_rms_after_px"] < 0.5
    if left.parent == VENTOUX:  # the RPC inconsistency the reference run measures too
        assert 4.0 < abs(doc["right_correction"]["across_epipolar_px"]) < 5.5


def cli(*args: str, api: str | None = None) -> subprocess.CompletedProcess:
    """``gcpfree relative ARGS`` in a child; with ``api``, its Prefect API (no temporary
    server of its own: that server's start and stop on a refusal are the user's default case,
    tested first below and in tests/flows/test_refusals.py)."""
    env = {**os.environ, "PREFECT_API_URL": api} if api else None
    return subprocess.run([sys.executable, "-m", "flows.cli", "relative", *args], env=env,
                          capture_output=True, text=True, timeout=300, check=False)


def test_bad_input_is_one_line(tiny_clean_scene, prefect_harness, tmp_path):
    from prefect.settings import PREFECT_API_URL

    api = PREFECT_API_URL.value()  # the session's server: no boot per command
    scene_dir, _ = tiny_clean_scene
    left, right = scene_dir / "left.tif", scene_dir / "right.tif"
    r = cli("--left", str(left), "--right", str(tmp_path / "none.tif"), "--out",
            str(tmp_path / "r.json"))
    assert r.returncode == 2 and "does not exist" in r.stderr and "Traceback" not in r.stderr
    r = cli("--left", str(left), "--right", str(right), "--tie-measure", "census", "--out",
            str(tmp_path / "r.json"))
    assert r.returncode == 2 and "--tie-measure" in r.stderr and len(r.stderr.splitlines()) == 1
    # a model that does not belong to the image: the footprints are far apart
    r = cli("--left", str(left), "--right", str(right), "--right-model",
            str(DATA / "pleiades_gizeh" / "img1.geom"), "--reference", str(SRTM),
            "--out", str(tmp_path / "r.json"), api=api)
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
            "--out", str(tmp_path / "r.json"), api=api)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert "tie points" in r.stderr and "interest points" in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
