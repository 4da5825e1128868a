"""The simulate-scene flow end to end, and its determinism (same seed, same bytes)."""

import subprocess
import sys
from pathlib import Path

from flows.simulate_scene import SimulationParams, simulate_scene
from tests.scenes import CENTRE


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
