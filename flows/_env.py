"""The one place that sets the process-wide Prefect and Dask defaults: local, offline, quiet.

Call :func:`configure_environment` before importing prefect (the CLI does it first thing,
the test suite in its conftest). Values the user set win, except the state folder when one is
given explicitly.
"""

from __future__ import annotations

import contextlib
import logging
import os
from collections.abc import Iterator
from pathlib import Path

DEFAULTS = {
    "PREFECT_SERVER_ANALYTICS_ENABLED": "false",  # server telemetry tries the internet otherwise
    "DO_NOT_TRACK": "1",  # SDK telemetry
    "PREFECT_LOGGING_TO_API_WHEN_MISSING_FLOW": "ignore",
    "PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS": "90",  # 20 s (default) times out
    "DASK_LOGGING__DISTRIBUTED": "warning",  # otherwise ~90 log lines per small flow
}


def configure_environment(prefect_home: str | Path | None = None, *,
                          verbose: bool | None = None) -> None:
    """Set offline, quiet defaults without overriding what the user set.

    With ``prefect_home``, Prefect's state (its SQLite database, profiles) and Dask's
    temporary files go to that folder, whatever the environment says (tests, benchmarks).
    ``verbose`` False (the command line's default) keeps Prefect's INFO chatter off the
    terminal, and only there: the console handler shows warnings and errors while the runs'
    INFO logs still reach the API, so the dashboard shows what a run did; True brings them back
    to the terminal; None leaves Prefect's own default.
    """
    for k, v in DEFAULTS.items():
        os.environ.setdefault(k, v)
    if verbose is not None:
        os.environ["PREFECT_LOGGING_LEVEL"] = "INFO"
        os.environ["PREFECT_LOGGING_HANDLERS_CONSOLE_LEVEL"] = "INFO" if verbose else "WARNING"
    if verbose is False:
        quiet_numeric_warnings()
    if prefect_home is not None:
        home = Path(prefect_home)
        os.environ["PREFECT_HOME"] = str(home)
        os.environ["DASK_TEMPORARY_DIRECTORY"] = str(home / "dask")


def quiet_numeric_warnings() -> None:
    """Keep NumPy's numeric warnings ("Mean of empty slice", "invalid value encountered...")
    off a user's terminal, in this process and in the worker processes it starts (through
    PYTHONWARNINGS): a window or tile without data is an expected case the products report,
    not news. ``--verbose`` and the test suite (where they are errors) keep them."""
    import warnings

    warnings.filterwarnings("ignore", category=RuntimeWarning)
    spec = "ignore::RuntimeWarning"
    current = os.environ.get("PYTHONWARNINGS", "")
    if spec not in current.split(","):
        os.environ["PYTHONWARNINGS"] = ",".join(filter(None, (current, spec)))


class _OurErrorsOnce(logging.Filter):
    """Drop Prefect's log records (with tracebacks) of our own errors: the command prints each
    as one line on the way out. Any other exception is left to Prefect's log."""

    def filter(self, record: logging.LogRecord) -> bool:
        from core.errors import GcpFreeError

        exc = record.exc_info[1] if record.exc_info else None
        if isinstance(exc, GcpFreeError):
            return False
        if record.levelno >= logging.ERROR:  # "Finished in state Failed(... InputError: ...)"
            message = record.getMessage()
            return not any(f"{name}:" in message for name in _error_names())
        return True


def _error_names() -> set[str]:
    from core.errors import GcpFreeError

    names, todo = set(), [GcpFreeError]
    while todo:
        cls = todo.pop()
        names.add(cls.__name__)
        todo.extend(cls.__subclasses__())
    return names


@contextlib.contextmanager
def one_line_errors() -> Iterator[None]:
    """While a command runs, Prefect does not print tracebacks for gcpfree's own errors."""
    loggers = [logging.getLogger(n) for n in ("prefect.task_runs", "prefect.flow_runs")]
    flt = _OurErrorsOnce()
    for log in loggers:
        log.addFilter(flt)
    try:
        yield
    finally:
        for log in loggers:
            log.removeFilter(flt)
