"""Process-wide defaults for Prefect and Dask: local, offline, quiet. Call before importing prefect."""

from __future__ import annotations

import os

DEFAULTS = {
    "PREFECT_SERVER_ANALYTICS_ENABLED": "false",
    "DO_NOT_TRACK": "1",
    "PREFECT_LOGGING_TO_API_WHEN_MISSING_FLOW": "ignore",
    "PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS": "90",
    "DASK_LOGGING__DISTRIBUTED": "warning",
}


def configure_environment() -> None:
    """Set offline, quiet defaults without overriding what the user set."""
    for k, v in DEFAULTS.items():
        os.environ.setdefault(k, v)
