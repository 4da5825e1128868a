"""Test-wide settings: Prefect and Dask local, offline and quiet; a session Prefect harness."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

_HOME = Path(tempfile.mkdtemp(prefix="gcpfree-tests-prefect-"))
os.environ["PREFECT_HOME"] = str(_HOME)
os.environ["DASK_TEMPORARY_DIRECTORY"] = str(_HOME / "dask")
os.environ.setdefault("PREFECT_SERVER_ANALYTICS_ENABLED", "false")
os.environ.setdefault("DO_NOT_TRACK", "1")
os.environ.setdefault("PREFECT_LOGGING_TO_API_WHEN_MISSING_FLOW", "ignore")
os.environ.setdefault("PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS", "90")
os.environ.setdefault("DASK_LOGGING__DISTRIBUTED", "warning")

import pytest

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
