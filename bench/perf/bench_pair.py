"""The whole chain on the `spot` pair (issue 13): `gcpfree pair` (orientation, DSMs, two orthos,
lidar evaluation, report, STAC) with 1 and with 2 workers; time, peak memory and speed-up.

Targets: <= 10 min and <= 4 GB with 2 workers, speed-up >= 1.7 (issue 21.5). The scene is
simulated once (about 9 minutes, with lidar) unless GCPFREE_BENCH_SCENE names an existing
`gcpfree simulate --preset spot` output. Each run is a child process; its peak memory is the
resident memory of the whole process tree (worker processes included, Prefect's temporary API
server left out), sampled every 0.25 s. Where the time goes: each run has its own PREFECT_HOME,
and the start and end of every Prefect task run are read back from its database (prefect.db)
into a table of seconds and peak memory per step, 1 worker beside 2 ("rest": the flows' own
work between tasks, the API server's and Python's start-up). Each home's database is made
before its run, untimed, as for every run after a user's first (the first run's making of it,
about 7 s here, is measured by bench_dsm_wall.py). The load average is printed beside
each run; GCPFREE_BENCH_REPEAT=N repeats the 1-then-2 pair N times. Prints figures, asserts
nothing.
"""

from __future__ import annotations

import json
import math
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_hrg import load, step_memory, watch


def run(cmd: list[str], env: dict[str, str], tmp: Path) -> tuple[float, float]:
    """(seconds, peak RSS in MB) of one child."""
    timer = shutil.which("time") or ("/usr/bin/time" if Path("/usr/bin/time").exists() else None)
    rss_file = tmp / "rss.txt"
    full = [timer, "-f", "%M", "-o", str(rss_file), *cmd] if timer else cmd
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    t0 = time.perf_counter()
    r = subprocess.run(full, capture_output=True, text=True, env=env, check=False)
    dt = time.perf_counter() - t0
    if r.returncode != 0:
        print(r.stdout[-2000:], r.stderr[-2000:])
        raise SystemExit(f"{' '.join(cmd[3:5])} failed")
    if timer:
        rss = float(rss_file.read_text().split()[-1]) / 1024.0
    else:  # only a rise of the children's maximum is visible this way
        rss = max(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss, before) / 1024.0
    return dt, rss


def step_table(steps: dict[int, dict[str, tuple[float, float, float]]],
               total: dict[int, float], cpu_total: dict[int, float]) -> list[str]:
    """Per-step wall time and CPU time, 1 worker beside 2, the wall ratio, the CPU use (CPU
    seconds per wall second: 2 is both cores busy) and each step's peak memory."""
    names = list(dict.fromkeys(n for w in sorted(steps) for n in steps[w]))
    head = (f"{'step':26s} {'1w s':>7s} {'2w s':>7s} {'ratio':>6s} {'1w CPU':>7s} "
            f"{'2w CPU':>7s} {'1w use':>6s} {'2w use':>6s} {'1w MB':>6s} {'2w MB':>6s}")
    lines = [head]
    zero = (0.0, 0.0, 0.0)
    rows = [(n, steps[1].get(n, zero), steps[2].get(n, zero)) for n in names]
    rest = [(total[w] - sum(v[0] for v in steps[w].values()), math.nan,
             cpu_total[w] - sum(v[2] for v in steps[w].values())) for w in (1, 2)]
    rows.append(("rest (flows, start-up)", rest[0], rest[1]))
    rows.append(("whole run", (total[1], math.nan, cpu_total[1]),
                 (total[2], math.nan, cpu_total[2])))
    for n, (a, ma, ca), (b, mb, cb) in rows:
        ratio = f"{a / b:6.2f}" if b > 0.05 else "     -"
        ua = f"{ca / a:6.2f}" if a > 0.05 else "     -"
        ub = f"{cb / b:6.2f}" if b > 0.05 else "     -"
        lines.append(f"{n:26s} {a:7.1f} {b:7.1f} {ratio} {ca:7.1f} {cb:7.1f} {ua} {ub} "
                     f"{ma:6.0f} {mb:6.0f}")
    return lines


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        env = dict(os.environ, PREFECT_HOME=str(tmp / "prefect"),
                   PREFECT_SERVER_ANALYTICS_ENABLED="false",
                   PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS="300")
        scene = Path(os.environ.get("GCPFREE_BENCH_SCENE") or tmp / "spot")
        if not (scene / "left.tif").exists():
            run([sys.executable, "-m", "flows.cli", "simulate", "--preset", "spot", "--seed",
                 "2", "--lens", "--date-change", "0.1", "--out", str(scene)], env, tmp)
        truth = scene / "truth"
        repeats = int(os.environ.get("GCPFREE_BENCH_REPEAT", "1"))
        for rep in range(repeats):
            times: dict[int, float] = {}
            steps: dict[int, dict[str, tuple[float, float, float]]] = {}
            cpus: dict[int, float] = {}
            for workers in (1, 2):
                out = tmp / f"pair_{workers}_{rep}"
                home = tmp / f"prefect_{workers}_{rep}"
                args = [sys.executable, "-m", "flows.cli", "pair", "--left",
                        str(scene / "left.tif"), "--right", str(scene / "right.tif"),
                        "--reference", str(scene / "reference.tif"), "--checkpoints",
                        str(truth / "checkpoints.json"), "--self-calibrate", "--workers",
                        str(workers), "--no-progress", "--out", str(out)]
                if (truth / "lidar.laz").exists():
                    args[-2:-2] = ["--lidar", str(truth / "lidar.laz"), "--landcover",
                                   str(truth / "landcover.tif")]
                subprocess.run([sys.executable, "-m", "prefect", "server", "database", "upgrade",
                                "-y"], env=dict(env, PREFECT_HOME=str(home)), check=True,
                               capture_output=True)
                before = load()
                dt, rss, _, samples = watch(args, dict(env, PREFECT_HOME=str(home)),
                                            f"pair with {workers} worker(s)")
                times[workers] = dt
                cpus[workers] = samples[-1][2] if samples else math.nan
                steps[workers] = step_memory(home / "prefect.db", samples)
                report = json.loads((out / "report.json").read_text())
                cp = report.get("check_points", {})
                worst = max((max(c["rms_col_px"], c["rms_row_px"]) for c in cp.values()),
                            default=float("nan"))
                le68 = (json.loads((out / "eval.json").read_text())["all"]["le68"]
                        if (out / "eval.json").exists() else float("nan"))
                cmp = json.loads((out / "ortho_compare.json").read_text())["px"]["median_norm"]
                print(f"pair on {scene.name}, {workers} worker(s): {dt:.1f} s, peak RSS "
                      f"{rss:.0f} MB; check points worst RMS {worst:.2f} px, orthos median "
                      f"{cmp:.2f} px, LE68 {le68:.2f} m (targets: 600 s, 4096 MB, peak of the "
                      f"process tree); load before "
                      f"{before}, after {load()}", flush=True)
                shutil.rmtree(out, ignore_errors=True)
            print("\n".join(step_table(steps, times, cpus)))
            print(f"speed-up of 2 workers over 1: {times[1] / times[2]:.2f}x (target >= 1.7)",
                  flush=True)


if __name__ == "__main__":
    main()
