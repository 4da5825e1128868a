"""The tie points' y-parallax bias from the two dates' illumination (issue 19).

An across-track pair from two dates is lit by two suns (the spot and tiny presets: 140 / 63
deg and 158 / 50 deg azimuth / elevation). Matching shaded relief under two suns moves the
matches off the true epipolar geometry by a common y-parallax, which the adjustment, weighting
hundreds of tie points, puts into the images' rows. This simulates the tiny pair twice, as the
preset has it and with the right image lit by the left's sun, finds the tie points of each
(``gcpfree relative``) and prints their mean y-parallax under the true models
(``prediction_check.mean_y_parallax``). About 3 minutes on 2 cores; asserts nothing.
"""

from __future__ import annotations

import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE.parent)]

import core.simulation.scene as scenes  # noqa: E402
from core.orientation.ties import TieObservations  # noqa: E402
from flows.cli import main as cli  # noqa: E402
from prediction_check import mean_y_parallax  # noqa: E402
from tasks.absolute.surface_match import TieGround  # noqa: E402
from tasks.io.sensors import read_model_file  # noqa: E402

ARGS = ["--preset", "tiny", "--seed", "1", "--center", "5.75", "44.75", "--lens", "--errors",
        "realistic", "--no-lidar"]


def bias(scene: Path, out: Path) -> tuple[int, float]:
    t = TieGround.from_tiepoints_json(out.with_suffix(".tiepoints.json"))
    ties = TieObservations(np.stack([t.left_col, t.right_col], 1),
                           np.stack([t.left_row, t.right_row], 1), t.lon_deg, t.lat_deg, t.h_m)
    truths = [read_model_file(scene / "truth" / f"{n}_truth.json").model
              for n in ("left", "right")]
    return ties.n, mean_y_parallax(truths, ties)


def main() -> None:
    preset = scenes.PRESETS["tiny"]
    left, right = preset.images
    one_sun = replace(preset, images=(left, replace(
        right, sun_azimuth_deg=left.sun_azimuth_deg, sun_elevation_deg=left.sun_elevation_deg)))
    with tempfile.TemporaryDirectory() as tmp:
        for label, p in (("two suns (the preset)", preset), ("one sun", one_sun)):
            scenes.PRESETS["tiny"] = p
            scene, out = Path(tmp) / label.split()[0], Path(tmp) / f"{label.split()[0]}.json"
            try:
                rc = cli(["simulate", *ARGS, "--out", str(scene)]) or cli([
                    "relative", "--left", str(scene / "left.tif"), "--right",
                    str(scene / "right.tif"), "--reference", str(scene / "reference.tif"),
                    "--out", str(out)])
            finally:
                scenes.PRESETS["tiny"] = preset
            if rc:
                raise SystemExit(f"{label}: gcpfree failed ({rc})")
            n, y = bias(scene, out)
            print(f"tiny, {label}: {n} tie points, mean y-parallax against the true models "
                  f"{y:+.3f} px")


if __name__ == "__main__":
    main()
