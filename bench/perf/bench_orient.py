"""Time of `gcpfree orient` on the `spot` pair, and of its step 3-4 alone: surface matching of
all windows against the reference and the absolute orientation (with lens self-calibration).

Target (issue 11): surface matching + adjustment under 60 s on 2 cores. The scene is simulated
once into a temp dir (about 9 minutes) unless GCPFREE_BENCH_SCENE names an existing `gcpfree
simulate --preset spot` output (with its reference.tif). The CLI runs in a child process (peak
RSS from getrusage); steps 3-4 are then timed again in this process on the CLI's own relative
DEM and tie points. Prints figures, asserts nothing.
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


def run(cmd: list[str], env: dict[str, str]) -> float:
    t0 = time.perf_counter()
    r = subprocess.run(cmd, capture_output=True, text=True, env=env, check=False)
    if r.returncode != 0:
        print(r.stdout[-2000:], r.stderr[-2000:])
        raise SystemExit(f"{cmd[3]} failed")
    return time.perf_counter() - t0


def steps_3_4(scene: Path, out: Path) -> None:
    """Surface matching of every window and the adjustment, timed in-process."""
    from dataclasses import replace

    from core.matching.surface import SurfaceMatchConfig
    from core.sensors.pushbroom import PushbroomModel
    from tasks.absolute.orientation import orient_absolute
    from tasks.absolute.surface_match import TieGround, match_surfaces
    from tasks.io.dem import read_reference
    from tasks.io.sensors import load_model
    from tasks.relative.orientation import pair_box

    left = load_model(scene / "left.tif")
    rel = json.loads((out / "relative" / "rel.json").read_text())
    right = replace(load_model(scene / "right.tif"),
                    model=PushbroomModel.from_dict(rel["right_model"]))
    dem = json.loads((out / "relative_dem.json").read_text())
    cfg = SurfaceMatchConfig()
    t0 = time.perf_counter()
    box = pair_box(left, right, (dem["h_min_m"], dem["h_max_m"])).expanded(25 / 3600)
    reference = read_reference(scene / "reference.tif", box, "ellipsoidal")
    ties = TieGround.from_tiepoints_json(out / "relative" / "rel.tiepoints.json")
    t1 = time.perf_counter()
    matched = match_surfaces.fn(out / "relative_dem.tif", ties, reference, cfg)
    t2 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        absolute = orient_absolute.fn(left, right, matched.gcps, Path(tmp), lens=True,
                                      ties=ties, along_track=True)  # as the CLI does
    t3 = time.perf_counter()
    print(f"steps 3-4 in-process: reference read {t1 - t0:.1f} s, surface matching "
          f"{len(matched.matches)} windows ({len(matched.gcps)} GCPs) {t2 - t1:.1f} s, "
          f"adjustment with self-calibration, tie points and along-track {t3 - t2:.1f} s; "
          f"total {t3 - t0:.1f} s "
          f"(target < 60 s); sigma0 {absolute.adjustment.sigma0:.2f}")


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        env = dict(os.environ, PREFECT_HOME=str(Path(tmp) / "prefect"))
        scene = os.environ.get("GCPFREE_BENCH_SCENE")
        if scene is None:
            scene = str(Path(tmp) / "spot")
            run([sys.executable, "-m", "flows.cli", "simulate", "--preset", "spot", "--seed", "2",
                 "--lens", "--date-change", "0.1", "--no-lidar", "--out", scene], env)
        scene_dir = Path(scene)
        out = Path(tmp) / "orient"
        before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
        dt = run([sys.executable, "-m", "flows.cli", "orient", "--left",
                  str(scene_dir / "left.tif"), "--right", str(scene_dir / "right.tif"),
                  "--reference", str(scene_dir / "reference.tif"), "--checkpoints",
                  str(scene_dir / "truth" / "checkpoints.json"), "--self-calibrate",
                  "--no-progress", "--out", str(out)], env)
        peak = max(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss, before)
        r = json.loads((out / "report.json").read_text())
        cp = r.get("check_points", {})
        print(f"orient (pushbroom, self-calibration) on {scene_dir.name}: {dt:.1f} s, peak RSS "
              f"{peak / 1024:.0f} MB; {r['gcps']['used']} GCPs used, {r['gcps']['rejected']} "
              "rejected; check points " + ", ".join(
                  f"{n} P {c['rms_col_px']:.2f} L {c['rms_row_px']:.2f} px"
                  for n, c in cp.items()))
        steps_3_4(scene_dir, out)


if __name__ == "__main__":
    main()
