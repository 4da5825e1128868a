"""The one rule that decides how a step's parallel work runs (:mod:`tasks.scheduling`), and that
no step decides it elsewhere."""

from __future__ import annotations

import ast
import os
import signal
import time
from pathlib import Path

import dask
import pytest
from dask.system import CPU_COUNT

from core.errors import InputError
from tasks.scheduling import PROCESS_MIN_TASKS, compute, process_pool, schedule, threads

REPO = Path(__file__).resolve().parents[2]
CORES = CPU_COUNT


def test_the_rule():
    # workers: asked, else one per core, never more than the tasks, at least one
    assert schedule(100).workers == CORES and schedule(None, 3).workers == 3
    assert schedule(2, 16).workers == 2 and schedule(0).workers == 1
    # threads unless asked; left to the rule, processes from PROCESS_MIN_TASKS tasks on
    assert schedule(100, 4).scheduler == "threads"
    assert schedule(100, 4, processes=True).scheduler == "processes"
    assert schedule(PROCESS_MIN_TASKS - 1, 4, None).scheduler == "threads"
    assert schedule(PROCESS_MIN_TASKS, 4, None).scheduler == "processes"
    # one worker runs in a thread on the local scheduler, but stays a process for a cluster
    alone = schedule(100, 1, processes=True)
    assert alone.scheduler == "threads" and alone.processes
    with pytest.raises(InputError, match="--workers must be at least 1"):
        schedule(4, 0)


def test_compute_keeps_the_order_and_threads_keep_the_enclosing_workers():
    parts = [dask.delayed(lambda i: i * i)(i) for i in range(5)]
    assert compute(parts, workers=2) == [0, 1, 4, 9, 16]
    with threads(3) as outer:
        with threads() as inner:
            assert dask.config.get("scheduler") == "threads"
            assert inner.workers == outer.workers == 3


def test_no_step_chooses_its_own_scheduler():
    """A scheduler or a worker count (``dask.compute``'s arguments, ``dask.config``) and
    prefect-dask's runner appear in tasks/scheduling.py only (the COG writer's and the ortho
    comparison's array graphs compute inside its :func:`threads`)."""
    found = []
    for pkg in ("core", "tasks", "flows"):
        for path in (REPO / pkg).rglob("*.py"):
            if path == REPO / "tasks" / "scheduling.py":
                continue
            for node in ast.walk(ast.parse(path.read_text())):
                if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and \
                        node.func.attr in ("compute", "persist", "set") and \
                        any(k.arg in ("scheduler", "num_workers") for k in node.keywords):
                    found.append(f"{path.relative_to(REPO)}:{node.lineno} .{node.func.attr}()")
                elif isinstance(node, ast.Attribute) and node.attr == "config" \
                        and isinstance(node.value, ast.Name) and node.value.id == "dask":
                    found.append(f"{path.relative_to(REPO)}:{node.lineno} dask.{node.attr}")
                elif isinstance(node, ast.Name) and node.id == "DaskTaskRunner":
                    found.append(f"{path.relative_to(REPO)}:{node.lineno} DaskTaskRunner")
    assert found == []


def test_compute_restores_opencv_threads_its_parts_change():
    cv2 = pytest.importorskip("cv2")
    before = cv2.getNumThreads()
    cv2.setNumThreads(3)
    try:
        def part(i: int) -> int:
            cv2.setNumThreads(1)  # as the tie-point and dense blocks do, in a thread
            return cv2.getNumThreads() + i

        assert compute([dask.delayed(part)(i) for i in range(4)], workers=2) == [1, 2, 3, 4]
        assert cv2.getNumThreads() == 3
    finally:
        cv2.setNumThreads(before)


def test_worker_processes_serve_every_step_and_a_lost_one_is_replaced():
    def pids() -> set[int]:
        return set(compute([dask.delayed(os.getpid)() for _ in range(8)], workers=2,
                           processes=True))

    first = pids() | pids() | pids()  # the pool starts its processes as work comes
    assert os.getpid() not in first
    assert len(first) <= 2  # later steps run in the same processes: none spawned again
    pool = process_pool(2)
    os.kill(next(iter(first)), signal.SIGKILL)
    deadline = time.monotonic() + 30.0
    while process_pool(2) is pool:  # broken once the executor sees its worker gone
        assert time.monotonic() < deadline, "the lost worker was never noticed"
        time.sleep(0.05)
    assert pids().isdisjoint(first)  # a new pool, new processes


def _pid_after(seconds: float) -> int:
    time.sleep(seconds)
    return os.getpid()


def test_two_runs_on_two_worker_processes_go_to_both():
    """One task per process call: Dask's default sends ready tasks in batches of 6, which put
    a step's runs all in one worker (the tie points' runs at 2 workers took 1.00 CPU/s)."""
    deadline = time.monotonic() + 60.0
    while len(set(compute([dask.delayed(_pid_after)(0.2) for _ in range(4)], workers=2,
                          processes=True))) < 2:  # until both processes of the pool are up
        assert time.monotonic() < deadline, "the pool never started its second process"
    assert len(set(compute([dask.delayed(_pid_after)(1.0) for _ in range(2)], workers=2,
                           processes=True))) == 2
