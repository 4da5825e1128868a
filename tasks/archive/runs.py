"""One pair of an archive as one Dask task: its files checked, then the chain the archive
flow hands over (``run``: ``gcpfree pair`` for that pair), and whatever happens, the pair's
outcome as a value: ``done``; ``refused`` with its one-line reason when the method refuses the
pair's data (:data:`REFUSALS`: terrain too flat, a scene smaller than a window, too few
points), a property of the scene that a rerun does not change; or ``failed`` with its reason
(bad input, any other error). A failing pair never stops the others, and Prefect never
retries the task (it would fail the same way again); Dask runs it again on another worker when
the worker running it dies (see ``flows.reprocess_archive``), and when that keeps happening,
:func:`failure_reason` says so.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from prefect import task
from prefect.cache_policies import NO_CACHE

from core.errors import GcpFreeError, InsufficientDataError, InsufficientReliefError
from tasks.archive.catalog import PairEntry, check_pair_inputs, one_line

#: the errors by which the method refuses a pair's data (not a failure of the run)
REFUSALS = (InsufficientReliefError, InsufficientDataError)


@dataclass(frozen=True)
class PairResult:
    """What happened to one pair processed in this run: ``done``, ``refused`` or ``failed``
    (with why); ``started_s`` (seconds since the epoch, the worker's clock) and ``seconds``:
    when its worker started it and how long it took there (None: lost with its worker)."""

    id: str
    status: str
    reason: str = ""
    started_s: float | None = None
    seconds: float | None = None


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
    parallelism is over pairs); a refusal (:data:`REFUSALS`) or any failure becomes the
    pair's status and reason instead of an exception. ``run`` is pickled to the worker: a
    module-level function, or a ``functools.partial`` of one."""
    started = time.time()
    status, reason = "done", ""
    try:
        check_pair_inputs(entry)
        run(entry)
    except Exception as exc:  # noqa: BLE001 - a failing pair never stops the others
        status = "refused" if isinstance(exc, REFUSALS) else "failed"
        reason = failure_reason(exc)
    return PairResult(entry.id, status, reason, started, time.time() - started)


def running_ids(futures: Mapping[Any, PairEntry]) -> set[str]:
    """The pairs of ``futures`` (Prefect futures of :func:`process_pair` -> their entries)
    that a Dask worker is processing now, as the scheduler says; empty when the flow's task
    runner has no Dask client or the scheduler does not answer."""
    from prefect.context import FlowRunContext

    ctx = FlowRunContext.get()
    client = getattr(ctx.task_runner, "client", None) if ctx else None
    if client is None:
        return set()
    try:
        processing = {k for keys in client.processing().values() for k in keys}
    except Exception:  # noqa: BLE001 - only the map's running/queued split depends on it
        return set()
    return {e.id for f, e in futures.items()
            if getattr(getattr(f, "wrapped_future", None), "key", None) in processing}
