"""Time and peak memory of ``gcpfree simulate --preset spot`` over the bundled N44E005 tile.

Target (issue 4): peak memory below 3 GB. The simulation runs in a child process; its peak is
the resident memory of the child and its descendants (Prefect's temporary API server left
out), sampled every 0.25 s (:mod:`bench.perf.meters`). Prints figures, asserts nothing.
``--preset`` measures another preset (hrs, hrg or tiny: the flow is called directly, so any
preset of ``core.simulation.scene.PRESETS`` works), ``--no-lidar`` skips the lidar.

    .venv/bin/python bench/perf/bench_simulate_preset.py [--preset spot] [--no-lidar]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from bench.common import load, workspace
from bench.perf.meters import watch

CHILD = """
import sys
from pathlib import Path
from flows.simulate_scene import SimulationParams, simulate_scene
s = simulate_scene(SimulationParams(out=Path(sys.argv[1]), preset=sys.argv[2], seed=1,
                                    lens=True, jitter=True, date_change=0.1,
                                    lidar=sys.argv[3] == "1"))
print("\\n".join(s.lines()))
"""


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--preset", default="spot", help="the preset simulated (default spot)")
    ap.add_argument("--no-lidar", dest="lidar", action="store_false", help="skip the lidar")
    args = ap.parse_args(argv)
    with workspace() as (tmp, env):
        env["PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS"] = "300"
        cmd = [sys.executable, "-c", CHILD, str(tmp / "scene"), args.preset,
               "1" if args.lidar else "0"]
        dt, peak_mb, stdout, _ = watch(cmd, env, "simulate")
        summary = [ln for ln in stdout.splitlines() if not ln[:2].isdigit()]
        print("\n".join(summary))
        print(f"simulate --preset {args.preset}: {dt:.0f} s, peak tree RSS {peak_mb:.0f} MB "
              f"(target < 3072 MB); {load()}")


if __name__ == "__main__":
    main()
