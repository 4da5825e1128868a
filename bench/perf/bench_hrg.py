"""A scene four times larger in the same memory (issue 21.6): the `hrg` preset (SPOT 5 HRG-like,
12000x12000 px at 5 m, two dates) simulated, then run through `gcpfree pair`.

Targets: `gcpfree pair` on hrg peaks at <= 4096 MB for the whole process tree (the spot scene,
6000x6000, peaks at about 1.5 GB) and takes about 4x the time of spot. The simulator's own peak
is printed too. Peak memory is the resident memory of the child and all its descendants
(Dask worker processes included, Prefect's temporary API server left out), sampled every
0.25 s (:mod:`bench.perf.meters`).

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
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from bench.common import load, pair_args, read_report, workspace, worst_check_rms
from bench.perf.meters import step_memory, watch

SIMULATE = """
import sys
from pathlib import Path
from flows.simulate_scene import SimulationParams, simulate_scene
s = simulate_scene(SimulationParams(out=Path(sys.argv[1]), preset="hrg", seed=2, lens=True,
                                    date_change=0.1, lidar=False))
print("\\n".join(s.lines()))
"""


def pair(scene: Path, out: Path, workers: int, env: dict[str, str]
         ) -> tuple[float, float, dict[str, tuple[float, float, float]]]:
    """Run `gcpfree pair` on a scene (its own PREFECT_HOME); (seconds, peak MB, per step)."""
    home = out.with_name(out.name + "_prefect")
    before = load()
    dt, peak, _, samples = watch([sys.executable, "-m", "flows.cli",
                                  *pair_args(scene, out, workers)],
                                 dict(env, PREFECT_HOME=str(home)), f"pair on {scene}")
    worst = worst_check_rms(read_report(out))
    print(f"pair on {scene.name} ({workers} workers): {dt:.0f} s, peak tree RSS {peak:.0f} MB, "
          f"check points worst RMS {worst:.2f} px; before: {before}, after: {load()}",
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
    with workspace() as (tmp, env):
        env.update(DASK_TEMPORARY_DIRECTORY=str(tmp / "dask"),
                   PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS="300")
        scene = a.scene or tmp / "hrg"
        if not (scene / "left.tif").exists() or not (scene / "reference.tif").exists():
            dt, peak, stdout, _ = watch([sys.executable, "-c", SIMULATE, str(scene)], env,
                                        "simulate hrg")
            print("\n".join(ln for ln in stdout.splitlines() if not ln[:2].isdigit()))
            print(f"simulate --preset hrg (no lidar): {dt:.0f} s, peak tree RSS {peak:.0f} MB; "
                  f"{load()}", flush=True)
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
