"""Time and peak memory of `gcpfree simulate --preset spot` over the bundled N44E005 tile.

Target (issue 4): peak memory below 3 GB. The simulation runs in a child process; its peak is
the resident memory of the child and its descendants (Prefect's temporary API server left
out), sampled every 0.25 s (bench/perf/bench_dsm.py's tree_rss_mb). Prints figures, asserts
nothing. Set GCPFREE_BENCH_PRESET=hrs, hrg or tiny to measure another preset (the flow is
called directly, so any preset of core.simulation.scene.PRESETS works), GCPFREE_BENCH_LIDAR=0
to skip the lidar.
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_hrg import load, watch

CHILD = """
import sys
from pathlib import Path
from flows.simulate_scene import SimulationParams, simulate_scene
s = simulate_scene(SimulationParams(out=Path(sys.argv[1]), preset=sys.argv[2], seed=1,
                                    lens=True, jitter=True, date_change=0.1,
                                    lidar=sys.argv[3] == "1"))
print("\\n".join(s.lines()))
"""


def main() -> None:
    preset = os.environ.get("GCPFREE_BENCH_PRESET", "spot")
    lidar = os.environ.get("GCPFREE_BENCH_LIDAR", "1")
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "scene"
        env = dict(os.environ, PREFECT_HOME=str(Path(tmp) / "prefect"),
                   PREFECT_SERVER_ANALYTICS_ENABLED="false",
                   PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS="300")
        cmd = [sys.executable, "-c", CHILD, str(out), preset, lidar]
        dt, peak_mb, stdout, _ = watch(cmd, env, "simulate")
        summary = [ln for ln in stdout.splitlines() if not ln[:2].isdigit()]
        print("\n".join(summary))
        print(f"simulate --preset {preset}: {dt:.0f} s, peak tree RSS {peak_mb:.0f} MB "
              f"(target < 3072 MB); load {load()}")


if __name__ == "__main__":
    main()
