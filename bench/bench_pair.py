"""The whole chain on the `spot` pair (issue 13): `gcpfree pair` (orientation, DSMs, two orthos,
lidar evaluation, report, STAC) with 1 and with 2 workers; time, peak memory and speed-up.

Targets: <= 10 min and <= 4 GB with 2 workers, speed-up >= 1.7. The scene is simulated once
(about 9 minutes, with lidar) unless GCPFREE_BENCH_SCENE names an existing `gcpfree simulate
--preset spot` output. Each run is a child process; its peak RSS is read from the kernel's
accounting of that child alone (`/usr/bin/time` when present, else getrusage). Prints figures,
asserts nothing.
"""

from __future__ import annotations

import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path


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


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(tmp_name)
        env = dict(os.environ, PREFECT_HOME=str(tmp / "prefect"))
        scene = Path(os.environ.get("GCPFREE_BENCH_SCENE") or tmp / "spot")
        if not (scene / "left.tif").exists():
            run([sys.executable, "-m", "flows.cli", "simulate", "--preset", "spot", "--seed",
                 "2", "--lens", "--date-change", "0.1", "--out", str(scene)], env, tmp)
        truth = scene / "truth"
        times = {}
        for workers in (1, 2):
            out = tmp / f"pair_{workers}"
            args = [sys.executable, "-m", "flows.cli", "pair", "--left", str(scene / "left.tif"),
                    "--right", str(scene / "right.tif"), "--reference",
                    str(scene / "reference.tif"), "--checkpoints",
                    str(truth / "checkpoints.json"), "--self-calibrate", "--workers",
                    str(workers), "--no-progress", "--out", str(out)]
            if (truth / "lidar.laz").exists():
                args[-2:-2] = ["--lidar", str(truth / "lidar.laz"), "--landcover",
                               str(truth / "landcover.tif")]
            dt, rss = run(args, env, tmp)
            times[workers] = dt
            report = json.loads((out / "report.json").read_text())
            cp = report.get("check_points", {})
            worst = max((max(c["rms_col_px"], c["rms_row_px"]) for c in cp.values()),
                        default=float("nan"))
            le68 = (json.loads((out / "eval.json").read_text())["all"]["le68"]
                    if (out / "eval.json").exists() else float("nan"))
            cmp = json.loads((out / "ortho_compare.json").read_text())["px"]["median_norm"]
            print(f"pair on {scene.name}, {workers} worker(s): {dt:.1f} s, peak RSS {rss:.0f} MB"
                  f"; check points worst RMS {worst:.2f} px, orthos median {cmp:.2f} px, "
                  f"LE68 {le68:.2f} m (targets: 600 s, 4096 MB)", flush=True)
        print(f"speed-up of 2 workers over 1: {times[1] / times[2]:.2f}x (target >= 1.7)")


if __name__ == "__main__":
    main()
