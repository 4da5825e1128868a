"""Time of ``gcpfree orient`` on the ``spot`` pair, and of its steps 3-4 alone: surface matching
of all windows against the reference and the absolute orientation (with lens self-calibration).

Target (issue 11): surface matching + adjustment under 60 s on 2 cores. The scene is simulated
once into a temporary folder (about 9 minutes) unless ``--scene`` names an existing ``gcpfree
simulate --preset spot`` output (with its reference.tif). The command runs in a child process
(peak RSS from getrusage); steps 3-4 are then timed again in this process on the command's own
relative DEM and tie points, through the tasks ``gcpfree orient`` calls. Prints figures,
asserts nothing.

    .venv/bin/python bench/perf/bench_orient.py [--scene DIR]
"""

from __future__ import annotations

import argparse
import json
import resource
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from bench.common import given_or_simulated, orient, read_report, workspace


def steps_3_4(scene: Path, out: Path) -> None:
    """Surface matching of every window and the adjustment, timed in-process."""
    from core.geodesy import ARCSEC
    from core.matching.surface import SurfaceMatchConfig
    from core.orientation.absolute import AbsoluteConfig
    from core.orientation.adjust import AdjustConfig
    from core.sensors.pushbroom import PushbroomModel
    from tasks.absolute.control import ground_control
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
    margin = (cfg.shift_max_arcsec + 5.0) * ARCSEC  # as gcpfree orient reads it
    box = pair_box(left, right, (dem["h_min_m"], dem["h_max_m"])).expanded(margin)
    reference = read_reference(scene / "reference.tif", box, "ellipsoidal")
    ties = TieGround.from_tiepoints_json(out / "relative" / "rel.tiepoints.json")
    t1 = time.perf_counter()
    windows = match_surfaces.fn(out / "relative_dem.tif", ties, reference, cfg,
                                models=(left.model, right.model))
    t2 = time.perf_counter()
    absolute = AbsoluteConfig()
    control = ground_control.fn(windows, windows.verdict(cfg, 8, reference.cell_size_m()), None,
                                absolute)
    with tempfile.TemporaryDirectory() as tmp:  # as the command does
        result = orient_absolute.fn((("left", left), ("right", right)), control.sets, Path(tmp),
                                    AdjustConfig(absolute=absolute, lens=True, along_track=True),
                                    ties)
    t3 = time.perf_counter()
    print(f"steps 3-4 in-process: reference read {t1 - t0:.1f} s, surface matching "
          f"{len(windows.matches)} windows ({len(windows.gcps)} GCPs) {t2 - t1:.1f} s, "
          f"adjustment with self-calibration, tie points and along-track {t3 - t2:.1f} s; "
          f"total {t3 - t0:.1f} s (target < 60 s); sigma0 {result.adjustment.sigma0:.2f}")


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", type=Path, default=None, help="a simulated spot scene folder")
    args = ap.parse_args(argv)
    with workspace() as (tmp, env):
        scene = given_or_simulated(args.scene, tmp, env, "spot", 2, "--lens", "--date-change",
                                   "0.1", "--no-lidar")
        out = tmp / "orient"
        before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
        dt, refused = orient(scene, out, env)
        if refused is not None:
            raise SystemExit(f"gcpfree orient: {refused}")
        peak = max(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss, before)
        r = read_report(out)
        print(f"orient (pushbroom, self-calibration) on {scene.name}: {dt:.1f} s, peak RSS "
              f"{peak / 1024:.0f} MB; {r['gcps']['used']} GCPs used, {r['gcps']['rejected']} "
              "rejected; check points " + ", ".join(
                  f"{n} P {c['rms_col_px']:.2f} L {c['rms_row_px']:.2f} px"
                  for n, c in r.get("check_points", {}).items()))
        steps_3_4(scene, out)


if __name__ == "__main__":
    main()
