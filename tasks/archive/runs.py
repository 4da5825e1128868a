"""One pair of an archive as one Dask task: its files checked, then the chain the archive
flow hands over (``run``: ``gcpfree pair`` for that pair), and whatever happens, the pair's
outcome as a value: ``done``, or ``failed`` with its one-line reason. A failing pair never
stops the others, and Prefect never retries the task (it would fail the same way again); Dask
runs it again on another worker when the worker running it dies (see
``flows.reprocess_archive``), and when that keeps happening, :func:`failure_reason` says so.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from prefect import task
from prefect.cache_policies import NO_CACHE

from core.errors import GcpFreeError
from tasks.archive.catalog import PairEntry, check_pair_inputs, one_line


@dataclass(frozen=True)
class PairResult:
    """What happened to one pair processed in this run: ``done`` or ``failed`` (with why)."""

    id: str
    status: str
    reason: str = ""


def failure_reason(exc: BaseException) -> str:
    """One line: gcpfree's own errors as they say it, a pair whose Dask workers kept dying
    under it (``KilledWorker``) in words, others with their type."""
    from distributed import KilledWorker

    if isinstance(exc, KilledWorker):
        tries = getattr(exc, "allowed_failures", None)
        times = f"{tries + 1} times" if isinstance(tries, int) else "repeatedly"
        return (f"the Dask worker process running this pair died {times} (out of memory, or "
                "killed); see the workers' logs, give them more memory or fewer pairs at a "
                "time, then rerun to retry it")
    text = one_line(str(exc))
    return text if isinstance(exc, GcpFreeError) and text else f"{type(exc).__name__}: {text}"


@task(name="pair-of-archive", cache_policy=NO_CACHE, log_prints=True)  # no retries
def process_pair(entry: PairEntry, run: Callable[[PairEntry], object]) -> PairResult:
    """``run(entry)`` after the pair's files are checked (single-threaded: the archive's
    parallelism is over pairs); any failure becomes the pair's reason instead of an
    exception. ``run`` is pickled to the worker: a module-level function, or a
    ``functools.partial`` of one."""
    try:
        check_pair_inputs(entry)
        run(entry)
    except Exception as exc:  # noqa: BLE001 - a failing pair never stops the others
        return PairResult(entry.id, "failed", failure_reason(exc))
    return PairResult(entry.id, "done")
