"""The simulate-scene flow end to end, and its determinism (same seed, same bytes)."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from core.geodesy import metres_per_degree
from core.sensors.pushbroom import PushbroomModel
from flows.simulate_scene import SimulationParams, simulate_scene
from tests.scenes import CENTRE, DEM


def test_flow_is_deterministic(prefect_harness, tmp_path, tiny_scene):
    a = tmp_path / "a"
    params = SimulationParams(out=a, seed=11, lens=True, jitter=True, date_change=0.1,
                              center=CENTRE)
    summary = simulate_scene(params)
    assert summary.checkpoints >= 50 and summary.lidar_points > 100_000
    assert all(100 <= e <= 300 for e in summary.centre_error_m.values())
    b, _ = tiny_scene  # the same scene through the tasks directly
    files = ["left.tif", "right.tif", "left.json", "right.json", "left.DIM", "right.DIM",
             "truth/dsm.tif",
             "truth/dtm.tif", "truth/landcover.tif", "truth/checkpoints.json",
             "truth/lidar.laz", "truth/left_truth.json", "reference.tif",
             "truth/reference_errors.json"]
    for f in files:
        assert (a / f).read_bytes() == (b / f).read_bytes(), f


def test_simulate_cli_help_and_bad_dem(tmp_path):
    r = subprocess.run([sys.executable, "-m", "flows.cli", "simulate", "--help"],
                       capture_output=True, text=True, timeout=60, check=False)
    for opt in ("--dem", "--out", "--preset", "--seed", "--lens", "--jitter", "--date-change",
                "--relief-factor", "--bits", "--center", "--no-lidar", "--errors"):
        assert opt in r.stdout
    r = subprocess.run([sys.executable, "-m", "flows.cli", "simulate", "--dem",
                        str(tmp_path / "none.tif"), "--out", str(tmp_path / "o")],
                       capture_output=True, text=True, timeout=60, check=False)
    assert r.returncode == 2 and "does not exist" in r.stderr and "Traceback" not in r.stderr
    assert not Path(tmp_path / "o").exists()


def test_simulate_errors_option_reaches_the_flow(monkeypatch, tmp_path):
    """``--errors`` is passed as given; absent, the flow takes the preset's default."""
    import flows.simulate_scene as F
    from flows.cli import main

    seen = []

    class Stop(Exception):
        pass

    def fake(params):
        seen.append(params.errors)
        raise Stop

    monkeypatch.setattr(F, "simulate_scene", fake)
    for extra in ([], ["--errors", "realistic"], ["--errors", "simple"]):
        try:
            main(["simulate", "--out", str(tmp_path / "o"), *extra])
        except Stop:
            pass
    assert seen == [None, "realistic", "simple"]


# ---------------------------------------------------------------------------- the block


@pytest.fixture(scope="module")
def tiny_block(tmp_path_factory):
    """A 2 x 1 tiny block over two dates (4 images, realistic errors, lens, jitter) through
    the block's tasks: its models, truth surface, check points and the second date's images
    (the geometry needs no more). (out_dir, SceneDef)."""
    from core.simulation.block import BlockLayout
    from core.simulation.scene import ErrorConfig
    from tasks.simulate import block as B
    from tasks.simulate.scene import build_truth_surface

    out = tmp_path_factory.mktemp("tiny_block")
    opts = B.BlockOptions(BlockLayout(2, 1, 2), "tiny", 7,
                          ErrorConfig(lens=True, jitter=True, realistic=True), date_change=0.1,
                          centre_lonlat=(5.3, 44.35))
    scene = B.define_block.fn(DEM, out, opts)
    B.write_block_metadata.fn(scene, out)
    scene = build_truth_surface.fn(scene, out)
    B.make_block_checkpoints.fn(scene, out)
    B.build_block_radiance.fn(scene, out, 1)
    B.render_block_images.fn(scene, out, 1)
    return out, scene


def test_block_lists_its_images_passes_and_truth(tiny_block):
    from tasks.io.sensors import load_model

    out, scene = tiny_block
    doc = json.loads((out / "truth" / "block.json").read_text())
    assert (doc["rows"], doc["cols"], doc["dates"]) == (2, 1, 2)
    assert [im["name"] for im in doc["images"]] == list(scene.image_names) == [
        "r0c0d0", "r1c0d0", "r0c0d1", "r1c0d1"]
    for im in doc["images"]:
        assert im["pass"] == f"c0d{im['date']}" and im["scene_in_segment"] == im["row"]
        for key in ("model", "dimap", "truth_model"):
            assert (out / im[key]).is_file(), im[key]
        truth = PushbroomModel.from_json((out / im["truth_model"]).read_text())
        assert truth.to_dict() == PushbroomModel.from_json(
            (out / "truth" / f"{im['name']}_truth.json").read_text()).to_dict()
    assert [p["scenes"] for p in doc["passes"]] == [["r0c0d0", "r1c0d0"], ["r0c0d1", "r1c0d1"]]
    fig = doc["figures"]
    assert 8 < fig["along_track"][0]["overlap_pct"] < 12 and not fig["across_track"]
    assert all(0.8 < g["b_over_h"] < 0.9 for g in fig["stereo"])
    loaded = load_model(out / "images" / "r1c0d1.tif")  # the delivered model found beside
    assert loaded.size == (600, 600) and loaded.source.parent == out / "images"
    for name in ("dsm.tif", "dtm.tif", "landcover.tif", "scene.json"):
        assert (out / "truth" / name).is_file()


def test_block_check_points_are_where_the_truth_models_see_them(tiny_block):
    from tasks.io.products import CHECKPOINTS

    out, scene = tiny_block
    cps = CHECKPOINTS.read(out / "truth" / "checkpoints.json")
    assert len(cps.points) >= 80 and cps.images == scene.image_names
    models = {n: PushbroomModel.from_json((out / "truth" / f"{n}_truth.json").read_text())
              for n in scene.image_names}
    views = [len(p.image_points) for p in cps.points]
    assert min(views) >= 2 and max(views) >= 3  # some in the along-track overlap
    for p in cps.points:
        for name, ip in p.image_points.items():
            m = models[name]
            assert 0 < ip.col < m.n_cols - 1 and 0 < ip.row < m.n_rows - 1
            c, r = m.project(p.lon_deg, p.lat_deg, p.h_m)
            assert abs(c - ip.col) < 1e-6 and abs(r - ip.row) < 1e-6, (p.id, name)
            lon, lat = m.localize(ip.col, ip.row, p.h_m)  # the inverse, from the pixel
            m_lon, m_lat = metres_per_degree(p.lat_deg)
            assert np.hypot((lon - p.lon_deg) * m_lon, (lat - p.lat_deg) * m_lat) < 1e-6 * 40.0


def test_block_consecutive_scenes_continue_one_pass(tiny_block):
    out, _ = tiny_block
    a, b = (PushbroomModel.from_json((out / "truth" / f"r{r}c0d0_truth.json").read_text())
            for r in (0, 1))
    step = 540
    assert a.attitude == b.attitude and a.orbit.epoch_utc == b.orbit.epoch_utc
    np.testing.assert_array_equal(a.orbit.positions_m, b.orbit.positions_m)
    assert b.t0_s == pytest.approx(a.t0_s + step * a.line_period_s, abs=1e-9)
    cols = np.linspace(0, 599, 5)
    la = np.array(a.localize(cols, np.full(5, 599.0), np.full(5, 700.0)))
    lb = np.array(b.localize(cols, np.full(5, 599.0 - step), np.full(5, 700.0)))
    np.testing.assert_allclose(la, lb, rtol=0, atol=1e-12)


def test_block_command_refuses_what_it_cannot_make(tmp_path, capsys):
    from flows.cli import main

    for extra, msg in ((["--block", "2by2"], "RxC"), (["--flat-scene", "r0c0"], "needs --block"),
                       (["--block", "2x2", "--flat-scene", "r2c0"], "must name a scene"),
                       (["--block", "2x2", "--sar", "ers"], "not a block's"),
                       (["--block", "2x2", "--dates", "7"], "--dates must be")):
        assert main(["simulate", "--out", str(tmp_path / "o"), *extra]) == 2
        err = capsys.readouterr().err
        assert msg in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "o").exists()
