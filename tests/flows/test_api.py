"""The Python API (``flows.api``, issue 48 item 4): plain calls need no Prefect API at all (run
where Prefect has no server and may not start one), ``prefect=True`` makes the flow run a
server records, the options are the ones every other way of running gcpfree names, and the
results are the flows' typed values. The whole chain through the API runs in the docs build
(``docs/tutorials/python-api.md``, executed; ``tests/docs/test_docs.py``)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyproj
import pytest

from core.errors import InputError
from tests.tasks.test_evaluate import write_las, write_raster

REPO = Path(__file__).resolve().parents[2]
UTM31 = "EPSG:32631"
X0, Y1, CELL = 680_000.0, 4_896_000.0, 5.0
OFFSET_M = 1.5  # the DEM above the lidar


@pytest.fixture(scope="module")
def plane(tmp_path_factory) -> tuple[Path, Path]:
    """A tilted plane as a DEM (WGS84 ellipsoidal heights, 5 m cells) and 2000 lidar points
    OFFSET_M under it (bilinear interpolation is exact on a plane): (dem, laz)."""
    tmp = tmp_path_factory.mktemp("plane")
    r, c = np.mgrid[0:60, 0:80].astype(float)
    z = (400.0 + 0.3 * c - 0.2 * r).astype(np.float32)
    dem = write_raster(tmp / "dem.tif", z, UTM31, (CELL, 0.0, X0, 0.0, -CELL, Y1),
                       tags={"vertical_datum": "WGS84 ellipsoid", "units": "m"})
    rng = np.random.default_rng(3)
    x = X0 + rng.uniform(3.0, 397.0, 2000)
    y = Y1 - rng.uniform(3.0, 297.0, 2000)
    col, row = (x - X0) / CELL - 0.5, (Y1 - y) / CELL - 0.5  # pixel centres at the nodes
    h = 400.0 + 0.3 * col - 0.2 * row - OFFSET_M
    laz = write_las(tmp / "points.laz", x, y, h, np.full(x.size, 2), pyproj.CRS(UTM31))
    return dem, laz


CHILD = """
import json, sys
from flows import api
dem, laz, out = sys.argv[1:4]
report = api.evaluate(dem, laz, out, lidar_vertical="ellipsoidal")
try:
    api.evaluate(dem, laz, lidar_vertical="ellipsoidal", prefect=True)
    refusal = None
except Exception as exc:
    refusal = f"{type(exc).__name__}: {exc}"
print(json.dumps({"type": type(report).__name__, "bias": report.all.mean_m,
                  "le68": report.all.le68_m, "nmad": report.all.nmad_m,
                  "count": report.all.count,
                  "server": "prefect.server.api.server" in sys.modules, "refusal": refusal}))
"""


def test_plain_calls_need_no_prefect_api(plane, tmp_path):
    """In a Python where Prefect has no API and may not start one (ephemeral mode off), the
    plain call runs the flow and its tasks and returns the flow's typed report (the known
    offset, the eval.json written); the same call with prefect=True cannot run there."""
    dem, laz = plane
    env = {k: v for k, v in os.environ.items()
           if not k.startswith(("PREFECT_API_", "PREFECT_PROFILES"))}
    env.update(PREFECT_HOME=str(tmp_path / "prefect"), PYTHONPATH=str(REPO),
               PREFECT_SERVER_ALLOW_EPHEMERAL_MODE="false")
    done = subprocess.run([sys.executable, "-c", CHILD, str(dem), str(laz),
                           str(tmp_path / "eval.json")], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 0, done.stderr
    got = json.loads(done.stdout.strip().splitlines()[-1])
    assert got["type"] == "EvaluationReport" and got["count"] == 2000
    assert got["bias"] == pytest.approx(OFFSET_M, abs=1e-3)  # dz = DEM - lidar
    assert got["le68"] == pytest.approx(OFFSET_M, abs=1e-3) and got["nmad"] < 1e-3
    assert not got["server"]
    assert got["refusal"] and "No Prefect API URL" in got["refusal"]
    written = json.loads((tmp_path / "eval.json").read_text())
    assert written["all"]["mean"] == pytest.approx(OFFSET_M, abs=1e-3)


def _evaluate_runs() -> int:
    from prefect.client.orchestration import get_client
    from prefect.client.schemas.filters import FlowFilter, FlowFilterName

    with get_client(sync_client=True) as client:
        return len(client.read_flow_runs(flow_filter=FlowFilter(
            name=FlowFilterName(any_=["evaluate"]))))


def test_prefect_true_is_a_recorded_flow_run_and_plain_is_not(plane, prefect_harness):
    from flows import api

    dem, laz = plane
    before = _evaluate_runs()
    plain = api.evaluate(dem, laz, lidar_vertical="ellipsoidal")
    assert _evaluate_runs() == before
    run = api.evaluate(dem, laz, lidar_vertical="ellipsoidal", prefect=True)
    assert _evaluate_runs() == before + 1
    assert isinstance(run, api.EvaluationReport) and run == plain


def test_the_options_are_named_as_everywhere_else(monkeypatch, tmp_path):
    """The pair's files, the orientation's and the options by name (flows.options) land in
    the one parameter object; a misspelt option is refused with the right name."""
    from flows import api

    made = []
    monkeypatch.setattr(api, "run", lambda params, prefect=False: made.append(params))
    api.orient_pair("l.tif", "r.tif", tmp_path / "o", dem_dir="tiles",
                    checkpoints="cp.json", left_model="l.DIM", self_calibrate=True,
                    corrections="offset", options={"surface.radius_m": 3000,
                                                   "reference_sigma_m": "2 2 4"})
    (p,) = made
    assert isinstance(p, api.OrientParams) and p.out == tmp_path / "o"
    assert (p.pair.left, p.pair.left_model, p.pair.srtm_dir, p.checkpoints) == (
        Path("l.tif"), Path("l.DIM"), Path("tiles"), Path("cp.json"))
    assert (p.self_calibrate, p.corrections, p.surface.radius_m) == (True, "offset", 3000.0)
    assert p.absolute.reference_sigma_m == (2.0, 2.0, 4.0) and p.progress is False
    with pytest.raises(InputError, match="did you mean self_calibrate"):
        api.orient_pair("l.tif", "r.tif", "o", dem_dir="tiles", self_calibrat=True)
    with pytest.raises(InputError, match="min_windows|--min-windows"):
        api.orient_pair("l.tif", "r.tif", "o", dem_dir="tiles", min_windows=0)
    api.process_pair("l.tif", "r.tif", "o", reference="ref.tif", lidar="p.laz",
                     lidar_vertical="egm96", pair_id="north", min_windows=5)
    chain = made[-1]
    assert isinstance(chain, api.PairParams) and chain.lidar == Path("p.laz")
    assert (chain.lidar_vertical, chain.pair_id, chain.orient.min_windows) == ("egm96", "north",
                                                                                5)


def test_plain_calls_refuse_what_needs_a_task_runner_and_restore_prefect():
    from prefect import flow, task
    from prefect.tasks import Task

    from flows.api import plain_calls

    @task
    def double(x: int) -> int:
        return 2 * x

    @flow
    def fan_out(n: int) -> list[int]:
        return [f.result() for f in double.map(range(n))]

    @flow
    def inline(n: int) -> int:
        return double(n) + 1

    call = Task.__call__
    with plain_calls():
        assert inline(3) == 7
        with plain_calls():  # re-entrant
            assert double(4) == 8
        with pytest.raises(InputError, match="prefect=True"):
            fan_out(2)
    assert Task.__call__ is call


def test_the_block_refuses_what_gcpfree_block_refuses(tmp_path):
    """api.block reads the catalog as gcpfree block does: one without blocks, or without
    the block asked for, is refused in a line before anything is written."""
    import json

    from flows import api

    empty = tmp_path / "scenes.json"
    empty.write_text(json.dumps({"format": "gcpfree.scenes", "version": 1, "scenes": [],
                                 "pairs": [], "blocks": [], "rejected": []}))
    with pytest.raises(InputError, match="lists no blocks|catalog"):
        api.block(empty, tmp_path / "out", dem_dir=tmp_path)
    assert not (tmp_path / "out").exists()
