"""What the speed benchmarks measure a child process with: the resident memory and CPU seconds
of it and its descendants (Prefect's temporary API server left out), sampled while it runs, and
per Prefect task the seconds, peak memory and CPU read back from the run's own database."""

from __future__ import annotations

import itertools
import os
import re
import resource
import sqlite3
import subprocess
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]

def _status_kb(pid: int, key: str = "VmRSS") -> float:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith(key):
                return float(line.split()[1])
    except OSError:
        pass
    return 0.0


def tree_pids(root: int) -> Iterator[int]:
    """A process and its descendants, Prefect's temporary API server (uvicorn) left out (its
    children still walked); a process gone meanwhile is skipped with its children."""
    todo, seen = [root], set()
    while todo:
        pid = todo.pop()
        if pid in seen:
            continue
        seen.add(pid)
        try:
            cmd = Path(f"/proc/{pid}/cmdline").read_bytes()
        except OSError:
            continue
        if b"uvicorn" not in cmd:
            yield pid
        for f in Path(f"/proc/{pid}/task").glob("*/children"):
            try:
                todo += [int(x) for x in f.read_text().split()]
            except OSError:
                pass


def tree_rss_mb(root: int) -> float:
    """Resident memory of a process and its descendants, Prefect's temporary API server
    (uvicorn) left out: what the DEM itself holds, its worker processes included."""
    return sum(_status_kb(pid) for pid in tree_pids(root)) / 1024.0


_TICK = os.sysconf("SC_CLK_TCK")


def tree_cpu_s(root: int) -> float:
    """CPU seconds (user + system, with the children each process has reaped) of a process
    and its descendants, Prefect's temporary API server (uvicorn) left out, as
    :func:`tree_rss_mb` counts memory."""
    total = 0
    for pid in tree_pids(root):
        try:
            stat = Path(f"/proc/{pid}/stat").read_text()
        except OSError:
            continue
        fields = stat.rsplit(")", 1)[1].split()
        total += sum(int(f) for f in fields[11:15])  # utime stime cutime cstime
    return total / _TICK


def watch(cmd: list[str], env: dict[str, str], label: str, quiet: bool = False
          ) -> tuple[float, float, str, list[tuple[float, float, float]]]:
    """(seconds, peak tree RSS in MB, stdout, samples (epoch seconds, MB, tree CPU seconds))
    of one child; exits on failure. The whole run's CPU seconds (every descendant reaped,
    the API server included) are printed unless ``quiet``."""
    t0 = time.perf_counter()
    cpu0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    samples: list[tuple[float, float, float]] = []
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        proc = subprocess.Popen(cmd, stdout=out, stderr=err, text=True, env=env, cwd=REPO)
        while proc.poll() is None:
            samples.append((time.time(), tree_rss_mb(proc.pid), tree_cpu_s(proc.pid)))
            time.sleep(0.25)
        cpu1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        dt = time.perf_counter() - t0
        out.seek(0)
        err.seek(0)
        stdout, stderr = out.read(), err.read()
    cpu = (cpu1.ru_utime - cpu0.ru_utime) + (cpu1.ru_stime - cpu0.ru_stime)
    if not quiet:
        print(f"{label}: wall {dt:.1f} s, CPU {cpu:.1f} s (user+system of the whole process "
              f"tree), CPU/wall {cpu / max(dt, 1e-9):.2f}", flush=True)
    if proc.returncode != 0:
        print(stdout[-3000:], stderr[-3000:])
        raise SystemExit(f"{label} failed")
    return dt, max((s[1] for s in samples), default=0.0), stdout, samples


def _union(spans: list[tuple[float, float]]) -> list[tuple[float, float]]:
    out: list[tuple[float, float]] = []
    for a, b in sorted(spans):
        if out and a <= out[-1][1]:
            out[-1] = (out[-1][0], max(out[-1][1], b))
        else:
            out.append((a, b))
    return out


def step_cpu(spans: list[tuple[float, float]], samples: list[tuple[float, float, float]]
             ) -> float:
    """CPU seconds the process tree spent while any of ``spans`` ran (each sampling interval
    whose middle falls inside one; a step that overlaps another shares that CPU with it)."""
    u = _union(spans)
    cpu = 0.0
    for (ta, _, ca), (tb, _, cb) in itertools.pairwise(samples):
        mid = 0.5 * (ta + tb)
        if any(a <= mid <= b for a, b in u):
            cpu += max(cb - ca, 0.0)
    return cpu


def step_memory(db: Path, samples: list[tuple[float, float, float]]
                ) -> dict[str, tuple[float, float, float]]:
    """Per Prefect task name: (seconds, peak tree RSS in MB while one of its runs ran, CPU
    seconds of the process tree while one ran), from the run's Prefect database and the
    samples."""
    con = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
    try:
        rows = con.execute(
            "SELECT name, (julianday(start_time) - 2440587.5) * 86400.0, "
            "(julianday(end_time) - 2440587.5) * 86400.0 FROM task_run WHERE start_time IS NOT "
            "NULL AND end_time IS NOT NULL AND id NOT IN (SELECT parent_task_run_id FROM "
            "flow_run WHERE parent_task_run_id IS NOT NULL) ORDER BY start_time").fetchall()
    finally:
        con.close()
    out: dict[str, tuple[float, float, float]] = {}
    spans: dict[str, list[tuple[float, float]]] = {}
    for name, t0, t1 in rows:
        base = re.sub(r"-[0-9a-f]{3}$", "", name)
        inside = [s[1] for s in samples if t0 <= s[0] <= t1]
        if not inside and samples:  # shorter than the sampling step: the nearest sample
            inside = [min(samples, key=lambda s: abs(s[0] - 0.5 * (t0 + t1)))[1]]
        peak = max(inside, default=0.0)
        sec, mb, _ = out.get(base, (0.0, 0.0, 0.0))
        out[base] = (sec + t1 - t0, max(mb, peak), 0.0)
        spans.setdefault(base, []).append((t0, t1))
    return {n: (sec, mb, step_cpu(spans[n], samples)) for n, (sec, mb, _) in out.items()}
