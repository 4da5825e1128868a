"""Test-wide settings: Prefect and Dask local, offline and quiet; a session Prefect harness."""

from __future__ import annotations

import tempfile
from pathlib import Path

from flows._env import configure_environment

configure_environment(prefect_home=tempfile.mkdtemp(prefix="gcpfree-tests-prefect-"))

import pytest  # noqa: E402  (after the environment is configured)

DATA = Path(__file__).parent / "data"
REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="session")
def prefect_harness():
    """Run flows against a temporary local Prefect server (one per test session)."""
    from prefect.testing.utilities import prefect_test_harness

    with prefect_test_harness(server_startup_timeout=90):
        yield


@pytest.fixture(scope="session")
def data_dir() -> Path:
    return DATA
