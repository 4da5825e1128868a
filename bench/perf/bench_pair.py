"""The whole chain on the `spot` pair (issue 13): `gcpfree pair` (orientation, DSMs, two orthos,
lidar evaluation, report, STAC) with 1 and with 2 workers; time, peak memory and speed-up.

Targets: <= 10 min and <= 4 GB with 2 workers, speed-up >= 1.7 (issue 21.5). The scene is
simulated once (about 9 minutes, with lidar) unless ``--scene`` names an existing
`gcpfree simulate --preset spot` output. Each run is a child process; its peak memory is the
resident memory of the whole process tree (worker processes included, Prefect's temporary API
server left out), sampled every 0.25 s. Where the time goes: each run has its own PREFECT_HOME,
and the start and end of every Prefect task run are read back from its database (prefect.db)
into a table of seconds and peak memory per step, 1 worker beside 2 ("rest": the flows' own
work between tasks, the API server's and Python's start-up). Each home's database is made
before its run, untimed, as for every run after a user's first (the first run's making of it,
about 7 s here, is measured by bench_dsm_wall.py). The load average is printed beside
each run; ``--repeat N`` repeats the 1-then-2 pair N times. Prints figures, asserts nothing.

    .venv/bin/python bench/perf/bench_pair.py [--scene DIR] [--repeat 1]
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from bench.common import (
    given_or_simulated,
    load,
    pair_args,
    read_report,
    workspace,
    worst_check_rms,
)
from bench.perf.meters import step_memory, watch


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


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", type=Path, default=None, help="a simulated spot scene folder")
    ap.add_argument("--repeat", type=int, default=1, help="rounds of 1 then 2 workers")
    args = ap.parse_args(argv)
    with workspace() as (tmp, env):
        env["PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS"] = "300"
        scene = given_or_simulated(args.scene, tmp, env, "spot", 2, "--lens", "--date-change",
                                   "0.1")
        for _ in range(args.repeat):
            times: dict[int, float] = {}
            steps: dict[int, dict[str, tuple[float, float, float]]] = {}
            cpus: dict[int, float] = {}
            for workers in (1, 2):
                out, home = tmp / f"pair_{workers}", tmp / f"prefect_{workers}"
                subprocess.run([sys.executable, "-m", "prefect", "server", "database", "upgrade",
                                "-y"], env=dict(env, PREFECT_HOME=str(home)), check=True,
                               capture_output=True)
                before = load()
                dt, rss, _, samples = watch([sys.executable, "-m", "flows.cli",
                                             *pair_args(scene, out, workers)],
                                            dict(env, PREFECT_HOME=str(home)),
                                            f"pair with {workers} worker(s)")
                times[workers] = dt
                cpus[workers] = samples[-1][2] if samples else math.nan
                steps[workers] = step_memory(home / "prefect.db", samples)
                worst = worst_check_rms(read_report(out))
                le68 = (json.loads((out / "eval.json").read_text())["all"]["le68"]
                        if (out / "eval.json").exists() else float("nan"))
                cmp = json.loads((out / "ortho_compare.json").read_text())["px"]["median_norm"]
                print(f"pair on {scene.name}, {workers} worker(s): {dt:.1f} s, peak RSS "
                      f"{rss:.0f} MB; check points worst RMS {worst:.2f} px, orthos median "
                      f"{cmp:.2f} px, LE68 {le68:.2f} m (targets: 600 s, 4096 MB, peak of the "
                      f"process tree); before: {before}, after: {load()}", flush=True)
                shutil.rmtree(out, ignore_errors=True)
                shutil.rmtree(home, ignore_errors=True)
            print("\n".join(step_table(steps, times, cpus)))
            print(f"speed-up of 2 workers over 1: {times[1] / times[2]:.2f}x (target >= 1.7)",
                  flush=True)


if __name__ == "__main__":
    main()
