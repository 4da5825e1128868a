"""The one place that sets the process-wide Prefect and Dask defaults: local, offline, quiet;
and the Prefect API a command's flow runs report to (:func:`prefect_api`).

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
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # imported where used: ``gcpfree --help`` loads this module
    import subprocess

DEFAULTS = {
    "PREFECT_SERVER_ANALYTICS_ENABLED": "false",  # server telemetry tries the internet otherwise
    "DO_NOT_TRACK": "1",  # SDK telemetry
    "PREFECT_LOGGING_TO_API_WHEN_MISSING_FLOW": "ignore",
    "PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS": "90",  # 20 s (default) times out
    "DASK_LOGGING__DISTRIBUTED": "warning",  # otherwise ~90 log lines per small flow
    # one BLAS thread per worker: the parallelism is Dask's (tasks.scheduling), and OpenBLAS's
    # own threads on the chain's small products only spin (spot surface matching, one worker:
    # 59.7 s wall and 88 CPU-s with them, 52.7 s and 49 CPU-s without; two workers 43.8 ->
    # 30.5 s). Read when NumPy loads: the CLI sets it before; worker processes inherit it.
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",  # the same for a NumPy built on MKL
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


class PrefectApi:
    """The Prefect API of one command's flow runs (see :func:`prefect_api`): the server the
    user configured (``url`` set, nothing to start), or a temporary server of this command
    (``process``), started at once and waited for by :meth:`ready`."""

    def __init__(self, url: str | None = None, startup_timeout_s: float = 90.0) -> None:
        self.url = url
        self.process: subprocess.Popen | None = None
        self.startup_timeout_s = startup_timeout_s
        self._env: dict[str, str] = {}
        self._settings = contextlib.ExitStack()  # Prefect pointed at the temporary server
        self._pointed = False
        self._log: Any = None  # the server's stdout and stderr

    @property
    def temporary(self) -> bool:
        return self.process is not None

    def start(self, env: dict[str, str]) -> None:
        """Start the temporary server: Prefect's own ephemeral server, the same uvicorn
        command and environment :class:`prefect.server.api.server.SubprocessASGIServer`
        runs (pinned Prefect 3.8), on a free port of 127.0.0.1. Its messages go to a
        temporary file (quoted if it fails), not to the command's terminal."""
        import importlib.util
        import socket
        import subprocess
        import sys
        import tempfile

        spec = importlib.util.find_spec("prefect")
        app_dir = Path(next(iter(spec.submodule_search_locations))).parent  # type: ignore
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
        self._env = env
        if self._log is None:
            self._log = tempfile.TemporaryFile()  # noqa: SIM115 -- closed by close()
        self.url = f"http://127.0.0.1:{port}/api"
        self.process = subprocess.Popen(
            [sys.executable, "-m", "uvicorn", "--app-dir", str(app_dir), "--factory",
             "prefect.server.api.server:create_app", "--host", "127.0.0.1", "--port", str(port),
             "--log-level", "error", "--lifespan", "on"],
            env={**os.environ, **env, "PREFECT_UI_ENABLED": "0", "PREFECT__SERVER_EPHEMERAL": "1",
                 "PREFECT__SERVER_FINAL": "1"},
            stdin=subprocess.DEVNULL, stdout=self._log, stderr=subprocess.STDOUT)

    def _messages(self) -> str:
        if self._log is None:
            return ""
        self._log.seek(0)
        text = self._log.read().decode("utf-8", "replace").strip()
        return f": {text[-2000:]}" if text else ""

    def ready(self) -> str | None:
        """The API's address once it answers (the temporary server healthy and Prefect in
        this process, its threads and its child processes pointed at it); None when Prefect
        is left to its own settings. Call it right before the first flow."""
        if self.process is None or self._pointed:
            return self.url
        import time

        end = time.monotonic() + self.startup_timeout_s
        while not self._healthy():
            code = self.process.poll()
            if code == 3:  # uvicorn could not bind: the port was taken meanwhile
                self.start(self._env)
            elif code is not None:
                raise RuntimeError(f"Prefect's temporary API server exited with code {code} "
                                   f"while starting{self._messages()}")
            if time.monotonic() > end:
                raise RuntimeError(
                    f"Prefect's temporary API server did not answer in "
                    f"{self.startup_timeout_s:.0f} s; raise "
                    "PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS or start a server "
                    f"(prefect server start) and set PREFECT_API_URL{self._messages()}")
            time.sleep(0.05)
        self._point_prefect_at(self.url)
        return self.url

    def _healthy(self) -> bool:
        import urllib.error
        import urllib.request

        try:
            with urllib.request.urlopen(f"{self.url}/health", timeout=2) as r:
                return r.status == 200
        except (urllib.error.URLError, ConnectionError, TimeoutError):
            return False

    def _point_prefect_at(self, url: str) -> None:
        import prefect.context
        from prefect.settings import PREFECT_API_URL, temporary_settings

        previous = os.environ.get("PREFECT_API_URL")

        def restore() -> None:
            if previous is None:
                os.environ.pop("PREFECT_API_URL", None)
            else:
                os.environ["PREFECT_API_URL"] = previous
            prefect.context.refresh_global_settings_context()

        # the environment (child processes) and Prefect's global settings (its worker
        # threads) first, then this context's settings
        os.environ["PREFECT_API_URL"] = url
        prefect.context.refresh_global_settings_context()
        self._settings.callback(restore)
        self._settings.enter_context(temporary_settings(updates={PREFECT_API_URL: url}))
        self._pointed = True

    def close(self) -> None:
        """Drain Prefect's log and event workers into the temporary server (as Prefect's test
        harness does), then stop it (SIGTERM) and give Prefect its settings back."""
        if self.process is None:
            return
        import subprocess

        try:
            if self._pointed:
                from prefect.events.worker import EventsWorker
                from prefect.logging.handlers import APILogWorker

                APILogWorker.drain_all(timeout=10, at_exit=False)
                EventsWorker.drain_all(timeout=10, at_exit=False)
        finally:
            self._settings.close()
            self._pointed = False
            self.process.terminate()
            try:
                self.process.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
            self.process = None
            if self._log is not None:
                self._log.close()
                self._log = None


@contextlib.contextmanager
def prefect_api() -> Iterator[PrefectApi]:
    """The Prefect API a command's flow runs report to: call ``ready()`` on it right before
    the first flow.

    With a server configured (``PREFECT_API_URL``, a Prefect profile, the test harness) that
    server, as Prefect would. Without one, Prefect 3.8 cannot run a flow at all (with
    ``PREFECT_SERVER_ALLOW_EPHEMERAL_MODE=false``: "No Prefect API URL provided"): its
    ephemeral mode starts a temporary API server inside the first flow call, after importing
    the whole server into this process, and waits for it. Here that same server (same
    command, same database in ``PREFECT_HOME``: the runs are recorded as with Prefect's own
    mode and show on a dashboard started later) is started at once, before Prefect is even
    imported when the environment names no server, so that it boots on the other core while
    the command imports its modules and checks its inputs (stopped again if Prefect's
    settings then name a server); the command's process never imports the server. Stopped on
    exit, its logs and events drained first. With ephemeral mode off and no server, Prefect is
    left to say so.
    """
    import sys

    api = PrefectApi()
    try:
        if "prefect" not in sys.modules and _no_server_in_environment():
            api.start({})  # before importing Prefect (a second): the server reads its settings
        from prefect.settings import get_current_settings

        settings = get_current_settings()
        api.startup_timeout_s = float(settings.server.ephemeral.startup_timeout_seconds)
        if settings.api.url is not None or not settings.server.ephemeral.enabled:
            api.close()  # a server configured in a profile or prefect.toml: not ours
            api.url = settings.api.url
        elif not api.temporary:
            api.start(settings.to_environment_variables(exclude_unset=True))
        yield api
    finally:
        api.close()


def _no_server_in_environment() -> bool:
    """What the environment alone says before Prefect is imported: no API URL, ephemeral mode
    not switched off (a Prefect profile or ``prefect.toml`` may still configure a server)."""
    if os.environ.get("PREFECT_API_URL"):
        return False
    return all(os.environ.get(name, "").strip().lower() not in ("0", "false", "no", "off")
               for name in ("PREFECT_SERVER_ALLOW_EPHEMERAL_MODE",
                            "PREFECT_SERVER_EPHEMERAL_ENABLED"))
