"""Test-wide settings: Prefect and Dask local, offline and quiet; a session Prefect harness."""

from __future__ import annotations

import atexit
import shutil
import tempfile
from pathlib import Path

from flows._env import configure_environment

_PREFECT_HOME = tempfile.mkdtemp(prefix="gcpfree-tests-prefect-")
configure_environment(prefect_home=_PREFECT_HOME)
# the session's Prefect database and logs go with it
atexit.register(shutil.rmtree, _PREFECT_HOME, ignore_errors=True)

import pytest

DATA = Path(__file__).parent / "data"
REPO = Path(__file__).resolve().parents[1]


# a simulated scene takes 30-40 s to render and its orientation 20-30 s more: every test that
# needs one (directly or through another fixture) is slow, wherever it is written; tests slow
# by themselves carry the mark. ``pytest -m "not slow"`` is the quick loop; CI runs them all.
SCENE_FIXTURES = frozenset({"tiny_scene", "tiny_clean_scene", "tiny_oriented"})


@pytest.hookimpl(tryfirst=True)  # before ``-m`` deselects
def pytest_collection_modifyitems(config, items):
    for item in items:
        if SCENE_FIXTURES.intersection(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.slow)


def pytest_collection_finish(session):
    """The docs site's build (a minute) started as soon as the session is known to have tests
    that look at it: it runs in a child beside the tests before them (tests/docs/test_docs.py,
    the fixture ``site`` waits for it)."""
    if session.config.option.collectonly:
        return
    if any("site" in getattr(item, "fixturenames", ()) and item.path.parent.name == "docs"
           for item in session.items):
        from tests.docs.test_docs import start_site_build

        start_site_build()


@pytest.fixture(scope="session")
def prefect_harness():
    """Run flows against a temporary local Prefect server (one per test session)."""
    from prefect.testing.utilities import prefect_test_harness

    with prefect_test_harness(server_startup_timeout=90):
        yield


@pytest.fixture(scope="session")
def data_dir() -> Path:
    return DATA


@pytest.fixture(scope="session")
def tiny_scene(tmp_path_factory):
    """The tiny preset with everything the metadata do not know: lens distortion, attitude
    jitter, 10 % changed between the dates (seed 11). (out_dir, SceneDef)."""
    from tests.scenes import run_scene

    out = tmp_path_factory.mktemp("tiny")
    return out, run_scene(out, date_change=0.1)


@pytest.fixture(scope="session")
def tiny_clean_scene(tmp_path_factory):
    """The tiny preset whose truth differs from its metadata only by what the orientation
    adjusts and the lens (no jitter, no date change; seed 12, no lidar). (out_dir, SceneDef)."""
    from tests.scenes import run_scene

    out = tmp_path_factory.mktemp("tiny_clean")
    return out, run_scene(out, seed=12, jitter=False, lidar=False)


@pytest.fixture(scope="session")
def tiny_oriented(tiny_scene, tmp_path_factory, prefect_harness):
    """``gcpfree orient`` run once on the tiny pair (rigorous family, lens self-calibration,
    check points): (scene_dir, out_dir, OrientOutcome). Tests only read its products; a test
    that writes copies the folder first."""
    from flows.orient import OrientParams, orient_flow
    from tasks.io.pair import PairInputs

    scene, _ = tiny_scene
    out = tmp_path_factory.mktemp("orient")
    outcome = orient_flow(OrientParams(
        pair=PairInputs(scene / "left.tif", scene / "right.tif",
                        reference=scene / "reference.tif"),
        out=out, checkpoints=scene / "truth" / "checkpoints.json", self_calibrate=True,
        progress=False))
    return scene, out, outcome
