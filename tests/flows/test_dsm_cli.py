"""``gcpfree dsm`` end to end: orientation first (stubbed here: the relative orientation has its
own tests), the DSM of the tiny simulated pair against its truth, the real Pleiades pairs,
and bad input stopped in one line before anything runs."""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import types
from pathlib import Path

import numpy as np
import pyproj
import pytest
import rasterio

from core.dem import sample_bilinear
from core.errors import InputError
from core.sensors.pushbroom import PushbroomModel
from flows.commands import dsm
from tasks.io.crs import Projection
from tasks.io.geoid import BUNDLED_SRTM_DIR, load_geoid
from tasks.io.sensors import LoadedModel
from tests.scenes import dsm_against_truth

SRTM = BUNDLED_SRTM_DIR / "N44E005.hgt"
REPO = Path(__file__).resolve().parents[2]
# a command's Prefect API when none is configured: a flow that logs, run between
# prefect_api() and ready(), then the run and its log read back from a second temporary server
# on the same PREFECT_HOME (what a dashboard started later would show)
PROBE = """
import json, os, sys
from flows._env import configure_environment, prefect_api
configure_environment(verbose=False)

out = {}
with prefect_api() as api:  # as a command does: before Prefect is imported
    from prefect import flow, get_run_logger
    from prefect.client.orchestration import get_client

    @flow(name="probe-flow")
    def probe(x: int) -> int:
        get_run_logger().warning("probe says %d", x)
        return x + 1

    out["temporary"] = api.temporary
    out["url"] = api.ready()
    out["env_url_inside"] = os.environ.get("PREFECT_API_URL")
    out["result"] = probe(41)
    pid = api.process.pid
out["server_gone"] = not os.path.exists(f"/proc/{pid}") or \\
    open(f"/proc/{pid}/stat").read().split()[2] == "Z"
out["env_url_after"] = os.environ.get("PREFECT_API_URL")
out["server_module_imported"] = "prefect.server.api.server" in sys.modules
with prefect_api() as api:  # Prefect imported by now
    out["second_url"] = api.ready()
    with get_client(sync_client=True) as client:
        runs = [r for r in client.read_flow_runs() if r.name and r.state_name]
        out["runs"] = [(client.read_flow(r.flow_id).name, r.state_name) for r in runs]
        logs = client.read_logs()
        out["logs"] = [lg.message for lg in logs]
print("PROBE " + json.dumps(out))
"""
# a server named by a Prefect profile only (not the environment): the temporary server started
# before Prefect's import is stopped again and the profile's server is the API
PROFILE_PROBE = """
import json, os
from flows._env import configure_environment, prefect_api
configure_environment(verbose=False)
with prefect_api() as api:
    out = {"url": api.ready(), "temporary": api.temporary}
tasks = os.listdir("/proc/self/task")
out["children"] = "".join(open(f"/proc/self/task/{t}/children").read() for t in tasks).split()
print("PROBE " + json.dumps(out))
"""


def parse(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="gcpfree")
    dsm.add_parser(parser.add_subparsers(dest="command"))
    return parser.parse_args(["dsm", *argv])


@pytest.fixture
def stub_orientation(monkeypatch, tiny_clean_scene):
    """``flows.relative.relative_models`` answering with the scene's true models."""
    scene_dir, _ = tiny_clean_scene
    calls = []

    def relative_models(pair, out_dir, workers=None):
        calls.append({"left": pair.left, "right": pair.right, "reference": pair.reference,
                      "reference_vertical": pair.reference_vertical, "out_dir": out_dir})
        loaded = []
        for name, image in (("left", pair.left), ("right", pair.right)):
            path = scene_dir / "truth" / f"{name}_truth.json"
            m = PushbroomModel.from_json(path.read_text())
            loaded.append(LoadedModel(m, "pushbroom", path, Path(image), (m.n_cols, m.n_rows)))
        return types.SimpleNamespace(left=loaded[0], right=loaded[1], reference=pair.reference,
                                     rel_json=Path(out_dir) / "rel.json")

    import flows.relative as module

    monkeypatch.setattr(module, "relative_models", relative_models)
    return calls


def test_dsm_orients_the_pair_then_writes_an_egm96_dsm(prefect_harness, tiny_clean_scene,
                                                      stub_orientation, tmp_path, capsys):
    scene_dir, _scene = tiny_clean_scene
    out = tmp_path / "dsm.tif"
    args = parse("--left", str(scene_dir / "left.tif"), "--right", str(scene_dir / "right.tif"),
                 "--reference", str(SRTM), "--roi", "100", "100", "400", "400",
                 "--resolution", "100", "--vertical", "egm96", "--no-progress",
                 "--out", str(out))
    assert dsm.run(args) == 0
    assert len(stub_orientation) == 1 and stub_orientation[0]["reference"] == SRTM
    printed = capsys.readouterr().out
    assert "completeness" in printed and "EPSG:" in printed
    with rasterio.open(out) as src:
        assert "EGM96" in src.tags()["vertical_datum"] and src.res == (100.0, 100.0)
        z = src.read(1)
        crs = pyproj.CRS.from_wkt(src.crs.to_wkt())
        assert crs.is_compound and "EGM96" in crs.sub_crs_list[1].name
        t, epsg = src.transform, crs.sub_crs_list[0].to_epsg()
    doc = json.loads(out.with_suffix(".json").read_text())
    assert doc["vertical"] == "egm96" and doc["completeness_pct"] > 90.0
    # against the truth DSM (ellipsoidal) brought to EGM96 with the geoid
    rows, cols = np.nonzero(np.isfinite(z))
    x, y = t.c + (cols + 0.5) * t.a, t.f + (rows + 0.5) * t.e
    with rasterio.open(scene_dir / "truth" / "dsm.tif") as src:
        truth, tt = src.read(1).astype(np.float64), src.transform
        assert src.crs.to_epsg() == epsg
    h_true = sample_bilinear(truth, (tt.f - y) / -tt.e - 0.5, (x - tt.c) / tt.a - 0.5)
    lon, lat = Projection(epsg).to_lonlat(x, y)
    dz = z[rows, cols] - load_geoid().ellipsoidal_to_orthometric(lon, lat, h_true)
    assert abs(np.nanmedian(dz)) < 10.0  # ~50 m if the geoid were forgotten


@pytest.mark.parametrize("pair", ["reunion", "ventoux"])
def test_real_pleiades_pairs(prefect_harness, data_dir, tmp_path, pair):
    """RPCs used as they are (consistent to a few pixels; the pointing correction takes the
    rest): completeness and heights of the DSMs."""
    out = tmp_path / f"{pair}.tif"
    if pair == "reunion":
        d = data_dir / "pleiades_reunion"
        argv = ["--left", str(d / "img_01.tif"), "--right", str(d / "img_02.tif"),
                "--roi", "150", "150", "700", "700", "--resolution", "0.5"]
        epsg, h_range, completeness = 32740, (2200.0, 2450.0), 90.0
    else:
        d = data_dir / "pleiades_ventoux"
        argv = ["--left", str(d / "left_image.tif"), "--right", str(d / "right_image.tif"),
                "--reference", str(SRTM)]
        epsg, h_range, completeness = 32631, (400.0, 650.0), 85.0
    assert dsm.run(parse(*argv, "--no-orient", "--no-progress", "--out", str(out))) == 0
    doc = json.loads(out.with_suffix(".json").read_text())
    assert doc["epsg"] == epsg and doc["completeness_pct"] > completeness
    assert h_range[0] < doc["h_min_m"] < doc["h_max_m"] < h_range[1]
    assert abs(doc["pointing_dy_px"][0]) < 10.0


def test_three_views_of_the_marseille_triplet(prefect_harness, data_dir, tmp_path):
    """``--images`` on crops of the real Pleiades triplet: with the delivered RPCs the pairs'
    heights disagree (02-01 and 02-03 5 m apart, 01-03 between them: each pair's along-track
    error, which no y-parallax shows); one joint relative orientation (02 fixed, 01 and 03
    adjusted to the tracks the three see) brings every two pairs within 0.5 m, and the fused
    DSM has heights in more cells than any pair alone, most from all three images."""
    d = data_dir / "pleiades_marseille_triplet"
    out = tmp_path / "views.tif"
    images = [str(d / f"img_{k}.tif") for k in ("02", "01", "03")]
    assert dsm.run(parse("--images", *images, "--resolution", "0.5", "--no-progress",
                         "--out", str(out))) == 0
    doc = json.loads(out.with_suffix(".json").read_text())
    pm = doc["pairwise_median_m"]
    assert list(pm) == ["0-1 minus 0-2", "0-1 minus 1-2", "0-2 minus 1-2"]
    # measured: -4.96, -2.49, +2.49 m before; -0.29, -0.20, +0.12 m after
    assert pm["0-1 minus 0-2"]["before"] < -4.0
    assert abs(pm["0-1 minus 1-2"]["before"]) > 1.5 and abs(pm["0-2 minus 1-2"]["before"]) > 1.5
    assert all(abs(v["after"]) < 0.5 and v["cells"] > 50_000 for v in pm.values()), pm
    with rasterio.open(out) as src:
        z = src.read(1)
    with rasterio.open(tmp_path / "views_views.tif") as src:
        views = src.read(1)
    with rasterio.open(tmp_path / "views_mask.tif") as src:
        mask = src.read(1)
    assert set(np.unique(views)) <= {0, 2, 3} and ((mask == 0) == np.isfinite(z)).all()
    assert not (views[~np.isfinite(z)] > 0).any()  # a count of views only with a height
    valid = int(np.isfinite(z).sum())
    best = max(p["cells"] for p in doc["pairs"])
    assert valid > 1.1 * best and (views == 3).sum() > 0.6 * valid  # measured 1.2x, 75 %
    assert [p["images"] for p in doc["pairs"]] == [[0, 1], [0, 2], [1, 2]]
    assert doc["pairs"][2]["b_over_h"] > 1.8 * doc["pairs"][0]["b_over_h"]  # 0.23 / 0.11
    rel = json.loads((tmp_path / "views_relative" / "relative.json").read_text())
    assert rel["format"] == "gcpfree.relative-views" and rel["tracks_multi"] > 30
    assert rel["rms_after_px"] < 0.15 < rel["rms_before_px"]
    assert not any(tmp_path.glob(".views.tif.work*"))  # the pairs' points are removed


def test_two_views_give_the_pair_dsm(prefect_harness, data_dir, tmp_path):
    """``--images L R`` is the pair: the same heights, cell for cell, as ``--left L --right
    R`` (its one pair's heights fused are its own), and a count of two views where there is
    a measured height (models as delivered on both: the orientation's N = 2 case has its own
    tests; with it, measured, the same DSM bytes too)."""
    d = data_dir / "pleiades_ventoux"
    left, right = str(d / "left_image.tif"), str(d / "right_image.tif")
    common = ("--reference", str(SRTM), "--no-orient", "--no-progress")
    assert dsm.run(parse("--left", left, "--right", right, *common, "--out",
                         str(tmp_path / "pair.tif"))) == 0
    assert dsm.run(parse("--images", left, right, *common, "--out",
                         str(tmp_path / "views.tif"))) == 0
    zs = []
    for name in ("pair", "views"):
        with rasterio.open(tmp_path / f"{name}.tif") as src:
            zs.append((src.read(1), src.transform))
    assert zs[0][1] == zs[1][1] and np.isfinite(zs[0][0]).sum() > 10_000
    np.testing.assert_array_equal(zs[0][0], zs[1][0])
    with rasterio.open(tmp_path / "views_views.tif") as src:
        views = src.read(1)
    finite = np.isfinite(zs[1][0])
    assert not views[~finite].any() and set(np.unique(views[finite])) <= {0, 2}
    assert (views[finite] == 2).mean() > 0.97  # 0: small holes filled from their neighbours
    doc = json.loads((tmp_path / "views.json").read_text())
    assert doc["pairwise_median_m"] == {} and doc["pairs"][0]["images"] == [0, 1]


def test_bad_input_is_one_line_before_anything_runs(tmp_path, data_dir):
    d = data_dir / "pleiades_ventoux"
    base = ["--left", str(d / "left_image.tif"), "--right", str(d / "right_image.tif"),
            "--no-orient"]
    cases = [
        (["--left", str(tmp_path / "none.tif"), "--right", str(d / "right_image.tif")],
         "does not exist"),
        ([*base, "--roi", "600", "0", "100", "100"], "outside the left image"),
        ([*base, "--reference", str(tmp_path / "none.hgt")], "does not exist"),
        ([*base, "--tile-px", "10"], "tile_px"),
        (["--no-orient"], "--left and --right"),
        (["--images", str(d / "left_image.tif")], "two different images or more"),
        (["--images", str(d / "left_image.tif"), str(d / "left_image.tif")], "two different"),
        ([*base, "--images", str(d / "left_image.tif"), str(d / "right_image.tif")],
         "replaces --left/--right"),
        (["--images", str(d / "left_image.tif"), str(tmp_path / "none.tif")], "does not exist"),
        (["--images", str(d / "left_image.tif"), str(d / "right_image.tif"), "--fusion",
          "mean"], None),
    ]
    for argv, message in cases:
        if message is None:  # refused by the parser, as every bad choice
            with pytest.raises(SystemExit):
                parse(*argv, "--out", str(tmp_path / "o.tif"))
            continue
        with pytest.raises(InputError, match=message) as err:
            dsm.run(parse(*argv, "--out", str(tmp_path / "o.tif")))
        assert "\n" not in str(err.value)
    with pytest.raises(InputError, match="does not exist"):
        dsm.run(parse(*base, "--out", str(tmp_path / "missing" / "o.tif")))
    assert not list(tmp_path.glob("*.tif"))


def test_help_lists_the_options(capsys):
    with pytest.raises(SystemExit):
        parse("--help")
    text = capsys.readouterr().out
    for opt in ("--left", "--right", "--left-model", "--right-model", "--roi", "--resolution",
                "--reference", "--srtm-dir", "--vertical", "--out", "--no-orient", "--images",
                "--fusion"):
        assert opt in text


def test_dsm_with_its_own_relative_orientation(prefect_harness, tiny_scene, tmp_path):
    """No stub: ``gcpfree dsm`` orients the tiny pair (lens, jitter, date change) itself, the
    right model adjusted to the left one and the along-epipolar part held by the reference,
    then matches the whole pair (80 m cells). Against the truth DSM, measured: median -2.9 m,
    NMAD 65 m over 73 000 cells (the left model keeps its 100-300 m metadata error: on the
    slopes that is height spread, which only the absolute orientation removes; ``orient``'s
    final DSM has 31 m). With ``--no-orient`` the models as delivered disagree along the
    epipolar lines: the same DSM 207 m low."""
    scene, _ = tiny_scene
    figures = {}
    for name, extra in (("own", ()), ("delivered", ("--no-orient",))):
        out = tmp_path / f"{name}.tif"
        assert dsm.run(parse("--left", str(scene / "left.tif"), "--right",
                             str(scene / "right.tif"), "--reference",
                             str(scene / "reference.tif"), "--no-progress", "--out", str(out),
                             *extra)) == 0
        assert json.loads(out.with_suffix(".json").read_text())["completeness_pct"] > 80.0
        figures[name] = dsm_against_truth(out, scene / "truth" / "dsm.tif")
    rel = json.loads((tmp_path / "own_relative" / "rel.json").read_text())
    # y-parallax RMS measured 6.6 px before, 0.36 px after
    assert rel["parallax_rms_after_px"] < 0.5 and rel["parallax_rms_before_px"] > 2.0
    assert not (tmp_path / "delivered_relative").exists()  # --no-orient: not oriented
    median, nmad, n = figures["own"]
    assert n > 50_000 and abs(median) < 15.0 and nmad < 90.0, figures
    median, _, _ = figures["delivered"]
    assert median < -100.0, figures  # the relative orientation is what puts it on the ground


def test_without_a_server_the_command_starts_prefects_temporary_server_at_once(tmp_path):
    """No Prefect server configured: ``prefect_api`` starts Prefect's temporary server itself
    (this process never imports the server), the flow runs against it, its log is drained
    into it before it stops, and the run is in PREFECT_HOME's database afterwards, where a
    later server (here a second temporary one) reads it back."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("PREFECT_API_")}
    env.update(PREFECT_HOME=str(tmp_path / "prefect"))
    proc = subprocess.run([sys.executable, "-c", PROBE], cwd=REPO, env=env,
                          capture_output=True, text=True, timeout=600, check=False)
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = json.loads(next(ln for ln in proc.stdout.splitlines()
                          if ln.startswith("PROBE "))[len("PROBE "):])
    assert out["temporary"] and out["url"].startswith("http://127.0.0.1:")
    assert out["env_url_inside"] == out["url"] and out["env_url_after"] is None
    assert out["result"] == 42 and out["server_gone"]
    assert not out["server_module_imported"]
    assert out["second_url"] != out["url"]
    assert ["probe-flow", "Completed"] in out["runs"]
    assert "probe says 41" in out["logs"]
    assert "Traceback" not in proc.stderr


def test_a_server_in_a_prefect_profile_is_used(tmp_path):
    profiles = tmp_path / "profiles.toml"
    profiles.write_text('active = "remote"\n[profiles.remote]\n'
                        'PREFECT_API_URL = "http://127.0.0.1:9/api"\n')
    env = {k: v for k, v in os.environ.items() if not k.startswith("PREFECT_API_")}
    env.update(PREFECT_HOME=str(tmp_path / "prefect"), PREFECT_PROFILES_PATH=str(profiles))
    proc = subprocess.run([sys.executable, "-c", PROFILE_PROBE], cwd=REPO, env=env,
                          capture_output=True, text=True, timeout=300, check=False)
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = json.loads(proc.stdout.split("PROBE ", 1)[1])
    assert out == {"url": "http://127.0.0.1:9/api", "temporary": False, "children": []}


def test_with_a_server_configured_nothing_is_started(prefect_harness):
    """The test harness's server is configured: the runs go there, no process is started."""
    from prefect.settings import PREFECT_API_URL

    from flows._env import prefect_api

    with prefect_api() as api:
        assert not api.temporary and api.process is None
        assert api.ready() == PREFECT_API_URL.value()
