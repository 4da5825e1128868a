"""Time and peak memory of `gcpfree simulate --preset spot` over the bundled N44E005 tile.

Target (issue 4): peak memory below 3 GB. The CLI runs in a child process; its peak RSS
is read from getrusage(RUSAGE_CHILDREN). Prints figures, asserts nothing. Set
GCPFREE_BENCH_PRESET=hrs or tiny to measure another preset.
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def main() -> None:
    preset = os.environ.get("GCPFREE_BENCH_PRESET", "spot")
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "scene"
        cmd = [sys.executable, "-m", "flows.cli", "simulate", "--preset", preset, "--out",
               str(out), "--seed", "1", "--lens", "--jitter", "--date-change", "0.1"]
        env = dict(os.environ, PREFECT_HOME=str(Path(tmp) / "prefect"))
        t0 = time.perf_counter()
        r = subprocess.run(cmd, capture_output=True, text=True, env=env, check=False)
        dt = time.perf_counter() - t0
        if r.returncode != 0:
            print(r.stdout[-3000:], r.stderr[-3000:])
            raise SystemExit("simulate failed")
        peak_mb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
        summary = [ln for ln in r.stdout.splitlines() if not ln[:2].isdigit()]
        print("\n".join(summary))
        print(f"simulate --preset {preset}: {dt:.0f} s, peak RSS {peak_mb:.0f} MB "
              "(target < 3072 MB)")


if __name__ == "__main__":
    main()
