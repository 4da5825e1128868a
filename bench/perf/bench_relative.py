"""Time and peak memory of `gcpfree relative` (tie points + relative orientation) on the `spot`
pair, both sensor families.

Target (issue 9): under 60 s and 1.5 GB on 2 cores. The scene is simulated once into a temp
dir (about 8 minutes) unless ``--scene`` names an existing `gcpfree simulate --preset spot`
output. The CLI runs in a child process; its peak RSS is read from getrusage. Prints figures,
asserts nothing.

    .venv/bin/python bench/perf/bench_relative.py [--scene DIR]
"""

from __future__ import annotations

import argparse
import json
import resource
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from bench.common import REPO, cli, given_or_simulated, refusal, workspace

SRTM = REPO / "tasks" / "data" / "N44E005.hgt"


def run(args: list[str], env: dict[str, str]) -> float:
    t0 = time.perf_counter()
    r = cli(args, env)
    if r.returncode != 0:
        raise SystemExit(f"gcpfree {args[0]}: {refusal(r)}")
    return time.perf_counter() - t0


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", type=Path, default=None, help="a simulated spot scene folder")
    args = ap.parse_args(argv)
    with workspace() as (tmp, env):
        scene_dir = given_or_simulated(args.scene, tmp, env, "spot", 2, "--lens")
        for family, extra in (("pushbroom", []),
                              ("rpc", ["--left-model", str(scene_dir / "left.tif"),
                                       "--right-model", str(scene_dir / "right.tif")])):
            out = tmp / f"rel_{family}.json"
            before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
            dt = run(["relative", "--left", str(scene_dir / "left.tif"), "--right",
                      str(scene_dir / "right.tif"), "--reference", str(SRTM), "--out", str(out),
                      *extra], env)
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
