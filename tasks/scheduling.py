"""The one place that decides how Dask runs a step's parallel work: threads or processes, and
how many workers.

:func:`schedule` is the rule; every step goes through it:

- workers: the number asked (``--workers``), else one per core this process may use (Dask's
  count, which heeds CPU affinity and container limits); never more than there are
  tasks when their number is known (an idle worker still costs its start), at least one;
- processes when asked (``True``), threads when not (``False``); left to the rule (``None``),
  processes from :data:`PROCESS_MIN_TASKS` tasks on. The dense matching's per-tile
  resampling holds Python's lock, so threads alone gained only 10 % on 2 cores, while a small
  job does not repay the processes' start-up.

Who asks what (each step's behaviour as it was before this module):

==========================================  =========================================
step                                        work
==========================================  =========================================
dense matching, final-DSM triangulation     :func:`compute`, ``processes`` from the
(:mod:`tasks.dense.dem`)                    config (default: the rule)
tile planning, tie points, surface          :func:`compute` in threads (their tasks
matching, ortho comparison                  share in-memory models and DEMs)
DEM and ortho writing (:func:`threads`)     array graphs stored into open rasters:
                                            threads of this process, always
the archive (:func:`archive_task_runner`)   a Dask cluster, one pair per worker
==========================================  =========================================

On the local scheduler a single worker always runs in a thread (a pool of one process would
only add its start-up); the archive's LocalCluster keeps its worker processes even alone,
so that a pair that kills its process never takes the flow with it.

Worker processes are spawned once per command and size (:func:`process_pool`) and serve every
later step: each spawn imports NumPy, OpenCV and the task modules and loads the Numba kernels,
about 1.5 CPU-seconds a process, which a pool per step paid again at every step.
"""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import dask
from dask.system import CPU_COUNT  # the cores this process may use (affinity, cgroups)

from core.errors import InputError

PROCESS_MIN_TASKS = 8  # from this many tasks on, the rule runs them in processes


@dataclass(frozen=True)
class Schedule:
    """How a piece of work runs: in ``workers`` worker processes or threads."""

    processes: bool
    workers: int

    @property
    def scheduler(self) -> str:
        """The local Dask scheduler: ``"processes"``, or ``"threads"`` (always for one
        worker)."""
        return "processes" if self.processes and self.workers > 1 else "threads"

    def compute_kwargs(self) -> dict[str, Any]:
        """``dask.compute``'s arguments: in processes, one task per process call (Dask's
        default batches 6 ready tasks per call, which sent a step's 6 runs to one worker)."""
        if self.scheduler == "processes":
            return {"scheduler": "processes", "pool": process_pool(self.workers),
                    "chunksize": 1}
        return {"scheduler": self.scheduler, "num_workers": self.workers}


_POOLS: dict[int, Any] = {}  # workers -> the command's ProcessPoolExecutor of that size


def process_pool(workers: int) -> Any:
    """The pool of ``workers`` spawned processes this command's steps share: made as Dask's
    processes scheduler makes its own (spawned, the same hash seed and initializer), kept
    until the command exits; a pool broken by a lost worker is replaced at the next step."""
    import os
    from concurrent.futures import ProcessPoolExecutor
    from functools import partial

    from dask.multiprocessing import get_context, initialize_worker_process

    pool = _POOLS.get(workers)
    if pool is not None and not getattr(pool, "_broken", False):
        return pool
    if os.environ.get("PYTHONHASHSEED") in (None, "0"):
        os.environ["PYTHONHASHSEED"] = "6640"  # what Dask sets for its own pools
    pool = ProcessPoolExecutor(workers, mp_context=get_context(),
                               initializer=partial(initialize_worker_process,
                                                   user_initializer=None))
    _POOLS[workers] = pool
    return pool


def schedule(n_tasks: int | None = None, workers: int | None = None,
             processes: bool | None = False) -> Schedule:
    """The rule of this module: ``workers`` asked (default one per core, never more than
    ``n_tasks``), processes when asked or, with ``processes=None``, for ``n_tasks`` of
    :data:`PROCESS_MIN_TASKS` or more."""
    if workers is not None and workers < 1:
        raise InputError(f"--workers must be at least 1 (got {workers})")
    n = workers or CPU_COUNT
    if n_tasks is not None:
        n = max(1, min(n, n_tasks))
    if processes is None:
        processes = n_tasks is not None and n_tasks >= PROCESS_MIN_TASKS
    return Schedule(bool(processes), n)


def compute(parts: Sequence[Any], *, workers: int | None = None,
            processes: bool | None = False, progress: bool = False,
            label: str | None = None) -> list[Any]:
    """``dask.compute`` of the delayed ``parts`` as :func:`schedule` decides, their results in
    order. ``progress``: a bar on stderr, after the line ``label: N tasks`` when given.

    OpenCV's thread count is restored after: the parts set it to one (their parallelism is
    the workers'), and in threads of this process that setting is process-wide."""
    s = schedule(len(parts), workers, processes)
    with contextlib.ExitStack() as stack:
        stack.enter_context(_opencv_threads_restored())
        if progress:
            from dask.diagnostics import ProgressBar

            if label:
                print(f"{label}: {len(parts)} tiles", file=sys.stderr, flush=True)
            stack.enter_context(ProgressBar(out=sys.stderr, dt=1.0))
        return list(dask.compute(*parts, **s.compute_kwargs()))


@contextlib.contextmanager
def _opencv_threads_restored() -> Iterator[None]:
    cv2 = sys.modules.get("cv2")  # never imported here: only restored when a part uses it
    n = cv2.getNumThreads() if cv2 is not None else None
    try:
        yield
    finally:
        cv2 = sys.modules.get("cv2")
        if cv2 is not None:
            cv2.setNumThreads(n if n is not None else -1)  # -1: OpenCV's default


@contextlib.contextmanager
def threads(workers: int | None = None) -> Iterator[Schedule]:
    """Array graphs (``map_blocks`` stored into rasters open in this process) computed in
    threads of this process, which share the open dataset and its lock as processes cannot.
    ``workers`` None keeps the number an enclosing :func:`threads` set, else one per core."""
    s = schedule(None, workers if workers is not None else dask.config.get("num_workers", None),
                 processes=False)
    with dask.config.set(scheduler="threads", num_workers=s.workers):
        yield s


def archive_task_runner(address: str | None, n_pairs: int, workers: int | None = None,
                        processes: bool = True, dashboard_address: str = ":8787"):
    """prefect-dask's runner for the archive: the cluster at ``address``, or a LocalCluster of
    single-threaded workers as :func:`schedule` sizes them for ``n_pairs`` (processes unless
    ``processes`` is False)."""
    from prefect_dask import DaskTaskRunner

    if address:
        return DaskTaskRunner(address=address)
    s = schedule(n_pairs, workers, processes)
    return DaskTaskRunner(cluster_kwargs={
        "n_workers": s.workers, "threads_per_worker": 1, "processes": s.processes,
        "dashboard_address": dashboard_address})
