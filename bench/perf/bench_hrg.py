"""A scene four times larger in the same memory (issue 21.6): the `hrg` preset (SPOT 5 HRG-like,
12000x12000 px at 5 m, two dates) simulated, then run through `gcpfree pair`.

Targets: `gcpfree pair` on hrg peaks at <= 4096 MB for the whole process tree (the spot scene,
6000x6000, peaks at about 1.5 GB) and takes about 4x the time of spot. The simulator's own peak
is printed too. Peak memory is the resident memory of the child and all its descendants
(Dask worker processes included, Prefect's temporary API server left out), sampled every
0.25 s (bench/perf/bench_dsm.py's tree_rss_mb).

    python bench/perf/bench_hrg.py [--scene DIR] [--spot DIR] [--workers N] [--skip-pair]

--scene reuses (or resumes) an hrg scene folder (default: a temporary one, simulated without
lidar: four times the spot preset's pixels, so about four times its simulation); --spot also
times `gcpfree pair` on that spot scene in the same run, right before hrg, for the time ratio.
A table gives each step's seconds and the peak memory while it ran (Prefect task runs read back
from each run's own prefect.db, matched with the RSS samples), so what grows with the scene
shows. Prints figures, asserts nothing.
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import re
import resource
import sqlite3
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_dsm import tree_pids, tree_rss_mb

REPO = Path(__file__).resolve().parents[2]

SIMULATE = """
import sys
from pathlib import Path
from flows.simulate_scene import SimulationParams, simulate_scene
s = simulate_scene(SimulationParams(out=Path(sys.argv[1]), preset="hrg", seed=2, lens=True,
                                    date_change=0.1, lidar=False))
print("\\n".join(s.lines()))
"""


def load() -> str:
    try:
        return " ".join(Path("/proc/loadavg").read_text().split()[:3])
    except OSError:
        return "?"


_TICK = os.sysconf("SC_CLK_TCK")


def tree_cpu_s(root: int) -> float:
    """CPU seconds (user + system, with the children each process has reaped) of a process
    and its descendants, Prefect's temporary API server (uvicorn) left out, as
    :func:`bench_dsm.tree_rss_mb` counts memory."""
    total = 0
    for pid in tree_pids(root):
        try:
            stat = Path(f"/proc/{pid}/stat").read_text()
        except OSError:
            continue
        fields = stat.rsplit(")", 1)[1].split()
        total += sum(int(f) for f in fields[11:15])  # utime stime cutime cstime
    return total / _TICK


def watch(cmd: list[str], env: dict[str, str], label: str
          ) -> tuple[float, float, str, list[tuple[float, float, float]]]:
    """(seconds, peak tree RSS in MB, stdout, samples (epoch seconds, MB, tree CPU seconds))
    of one child; exits on failure. The whole run's CPU seconds (every descendant reaped,
    the API server included) are printed."""
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


def pair(scene: Path, out: Path, workers: int, env: dict[str, str]
         ) -> tuple[float, float, dict[str, tuple[float, float, float]]]:
    """Run `gcpfree pair` on a scene (its own PREFECT_HOME); (seconds, peak MB, per step)."""
    truth = scene / "truth"
    home = out.with_name(out.name + "_prefect")
    args = [sys.executable, "-m", "flows.cli", "pair", "--left", str(scene / "left.tif"),
            "--right", str(scene / "right.tif"), "--reference", str(scene / "reference.tif"),
            "--checkpoints", str(truth / "checkpoints.json"), "--self-calibrate",
            "--workers", str(workers), "--no-progress", "--out", str(out)]
    if (truth / "lidar.laz").exists():
        args[-2:-2] = ["--lidar", str(truth / "lidar.laz"), "--landcover",
                       str(truth / "landcover.tif")]
    before = load()
    dt, peak, _, samples = watch(args, dict(env, PREFECT_HOME=str(home)), f"pair on {scene}")
    report = json.loads((out / "report.json").read_text())
    cp = report.get("check_points", {})
    worst = max((max(c["rms_col_px"], c["rms_row_px"]) for c in cp.values()),
                default=float("nan"))
    print(f"pair on {scene.name} ({workers} workers): {dt:.0f} s, peak tree RSS {peak:.0f} MB, "
          f"check points worst RMS {worst:.2f} px; load before {before}, after {load()}",
          flush=True)
    return dt, peak, step_memory(home / "prefect.db", samples)


def step_lines(runs: dict[str, dict[str, tuple[float, float, float]]]) -> list[str]:
    """Seconds, CPU seconds and peak MB of each step, one column triple per scene."""
    names = list(dict.fromkeys(n for r in runs.values() for n in r))
    head = f"{'step':26s}" + "".join(f" {k + ' s':>10s} {k + ' CPU s':>10s} {k + ' MB':>10s}"
                                     for k in runs)
    lines = [head]
    zero = (0.0, 0.0, 0.0)
    for n in names:
        lines.append(f"{n:26s}" + "".join(f" {r.get(n, zero)[0]:10.1f} "
                                          f"{r.get(n, zero)[2]:10.1f} "
                                          f"{r.get(n, zero)[1]:10.0f}"
                                          for r in runs.values()))
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", type=Path, default=None)
    ap.add_argument("--spot", type=Path, default=None)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--skip-pair", action="store_true")
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        env = dict(os.environ, PREFECT_HOME=str(tmp / "prefect"),
                   DASK_TEMPORARY_DIRECTORY=str(tmp / "dask"),
                   PREFECT_SERVER_ANALYTICS_ENABLED="false",
                   PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS="300")
        scene = a.scene or tmp / "hrg"
        if not (scene / "left.tif").exists() or not (scene / "reference.tif").exists():
            dt, peak, stdout, _ = watch([sys.executable, "-c", SIMULATE, str(scene)], env,
                                        "simulate hrg")
            print("\n".join(ln for ln in stdout.splitlines() if not ln[:2].isdigit()))
            print(f"simulate --preset hrg (no lidar): {dt:.0f} s, peak tree RSS {peak:.0f} MB; "
                  f"load {load()}", flush=True)
        if a.skip_pair:
            return
        runs: dict[str, dict[str, tuple[float, float, float]]] = {}
        t_spot = None
        if a.spot is not None:
            t_spot, _, runs["spot"] = pair(a.spot, tmp / "pair_spot", a.workers, env)
        t_hrg, peak, runs["hrg"] = pair(scene, tmp / "pair_hrg", a.workers, env)
        print("\n".join(step_lines(runs)))
        print(f"hrg: peak {peak:.0f} MB (target <= 4096 MB)"
              + (f", time {t_hrg / t_spot:.2f}x spot's (target about 4x)" if t_spot else ""))

if __name__ == "__main__":
    main()
