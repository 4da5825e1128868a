"""Time and peak memory of `gcpfree relative` (tie points + relative orientation) on the `spot`
pair, both sensor families.

Target (issue 9): under 60 s and 1.5 GB on 2 cores. The scene is simulated once into a temp
dir (about 8 minutes) unless GCPFREE_BENCH_SCENE names an existing `gcpfree simulate --preset
spot` output. The CLI runs in a child process; its peak RSS is read from getrusage. Prints
figures, asserts nothing.
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

SRTM = Path(__file__).resolve().parents[2] / "tasks" / "data" / "N44E005.hgt"


def run(cmd: list[str], env: dict[str, str]) -> float:
    t0 = time.perf_counter()
    r = subprocess.run(cmd, capture_output=True, text=True, env=env, check=False)
    if r.returncode != 0:
        print(r.stdout[-2000:], r.stderr[-2000:])
        raise SystemExit(f"{cmd[3]} failed")
    return time.perf_counter() - t0


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        env = dict(os.environ, PREFECT_HOME=str(Path(tmp) / "prefect"))
        scene = os.environ.get("GCPFREE_BENCH_SCENE")
        if scene is None:
            scene = str(Path(tmp) / "spot")
            run([sys.executable, "-m", "flows.cli", "simulate", "--preset", "spot", "--seed", "2",
                 "--lens", "--out", scene], env)
        scene_dir = Path(scene)
        for family, extra in (("pushbroom", []),
                              ("rpc", ["--left-model", str(scene_dir / "left.tif"),
                                       "--right-model", str(scene_dir / "right.tif")])):
            out = Path(tmp) / f"rel_{family}.json"
            before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
            dt = run([sys.executable, "-m", "flows.cli", "relative", "--left",
                      str(scene_dir / "left.tif"), "--right", str(scene_dir / "right.tif"),
                      "--reference", str(SRTM), "--out", str(out), *extra], env)
            peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
            doc = json.loads(out.read_text())
            search = doc["tie_point_search"]
            print(f"relative ({family}) on {scene_dir.name}: {dt:.1f} s, peak RSS "
                  f"{max(peak, before) / 1024:.0f} MB (children so far; target < 60 s, "
                  f"< 1536 MB); {doc['tie_points']} tie points ({doc['tie_points_rejected']} "
                  f"rejected), {100 * search['coverage_textured']:.0f} % of the textured cells; "
                  f"y-parallax {doc['parallax_rms_before_px']:.2f} -> "
                  f"{doc['parallax_rms_after_px']:.3f} px")


if __name__ == "__main__":
    main()
