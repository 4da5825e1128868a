"""Time, throughput and peak memory of the relative DEM of a simulated SPOT pair, and its
accuracy against the truth DSM.

Targets (issue 10), on 2 cores: the full ``spot`` pair (6000 x 6000 px) in <= 120 s and
<= 3 GB, memory flat when the scene doubles (the top half, then the whole scene). Each run is
a child process (``flows.dsm.dsm_flow`` with the true models, ``--no-orient``: the relative
orientation has its own benchmark); its peak memory is the resident size of it and its tile
workers, sampled every 0.25 s (Prefect's temporary API server left out). The load average
is printed too: figures taken while other work shares the cores are slower. Then the DEM minus the
truth DSM after the best-fit 3-D offset and tilt: NMAD per land-cover class (target <= 1 GSD
on bare soil), and the % mismatched.

    .venv/bin/python bench/perf/bench_dsm.py [--scene DIR] [--preset spot]

``--scene`` is a simulated scene (``gcpfree simulate --preset spot --no-lidar --out DIR``,
about 8 minutes); without it one is simulated into a temporary folder (``--preset`` picks
another preset for that). Prints figures, asserts nothing.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from bench.common import given_or_simulated, load, workspace
from bench.perf.meters import watch

CHILD = """
import json, sys, time
from pathlib import Path
from flows._env import configure_environment
configure_environment()
from flows.dsm import DsmParams, dsm_flow
from tasks.io.pair import PairInputs
scene, out, roi, extra = sys.argv[1], sys.argv[2], json.loads(sys.argv[3]), json.loads(sys.argv[4])
t0 = time.perf_counter()
s = dsm_flow(DsmParams(
    pair=PairInputs(Path(scene) / "left.tif", Path(scene) / "right.tif",
                    Path(scene) / "truth" / "left_truth.json",
                    Path(scene) / "truth" / "right_truth.json",
                    reference=Path(extra["reference"])),
    orient=False, roi=tuple(roi) if roi else None, progress=False, out=Path(out)))
dt = time.perf_counter() - t0
print("RESULT " + json.dumps({"seconds": dt, "summary": s.to_dict()}))
"""


def run_child(scene: Path, out: Path, roi: list[int] | None, home: Path) -> dict:
    """One DEM in a child process: its flow's seconds and summary, the process's wall time and
    the peak memory of its process tree."""
    from tasks.io.geoid import BUNDLED_SRTM_DIR

    env = dict(os.environ, PREFECT_HOME=str(home), DASK_TEMPORARY_DIRECTORY=str(home / "dask"))
    extra = {"reference": str(BUNDLED_SRTM_DIR / "N44E005.hgt")}
    wall, peak, stdout, _ = watch([sys.executable, "-c", CHILD, str(scene), str(out),
                                   json.dumps(roi), json.dumps(extra)], env, "dsm")
    line = next(ln for ln in stdout.splitlines() if ln.startswith("RESULT "))
    return {**json.loads(line[len("RESULT "):]), "wall_s": wall, "peak_mb": peak}


def accuracy(scene: Path, dem_path: Path) -> dict[str, float]:
    """DEM minus truth DSM at the DEM cells, offset and tilt removed: NMAD and median per
    land-cover class."""
    import rasterio

    from core.dem import sample_bilinear
    from core.matching.grid import remove_offset_and_tilt
    from core.simulation.landcover import LandCover

    with rasterio.open(dem_path) as src:
        z, t = src.read(1), src.transform
    rows, cols = np.nonzero(np.isfinite(z))
    x, y = t.c + (cols + 0.5) * t.a, t.f + (rows + 0.5) * t.e
    with rasterio.open(scene / "truth" / "dsm.tif") as src:
        truth, tt = src.read(1).astype(np.float64), src.transform
    with rasterio.open(scene / "truth" / "landcover.tif") as src:
        classes = src.read(1)
    fi, fj = (tt.f - y) / -tt.e - 0.5, (x - tt.c) / tt.a - 0.5
    gy, gx = np.gradient(truth, -tt.e, tt.a)
    fit = remove_offset_and_tilt(z[rows, cols] - sample_bilinear(truth, fi, fj), x, y,
                                 sample_bilinear(gx, fi, fj), -sample_bilinear(gy, fi, fj))
    cls = classes[np.clip(np.rint(fi).astype(int), 0, classes.shape[0] - 1),
                  np.clip(np.rint(fj).astype(int), 0, classes.shape[1] - 1)]
    out = {"offset_dz_m": fit.dz_m, "shift_m": float(np.hypot(fit.dx_m, fit.dy_m))}
    for c in LandCover:
        r = fit.residual_m[(cls == c) & np.isfinite(fit.residual_m)]
        if r.size > 100:
            med = float(np.median(r))
            out[f"{c.name.lower()}_median_m"] = med
            out[f"{c.name.lower()}_nmad_m"] = float(1.4826 * np.median(np.abs(r - med)))
    return out


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", type=Path, default=None, help="a simulated scene folder")
    ap.add_argument("--preset", default="spot", help="the preset simulated without --scene")
    args = ap.parse_args(argv)
    with workspace() as (tmp_path, env):
        scene = given_or_simulated(args.scene, tmp_path, env, args.preset, 1, "--no-lidar")
        from core.simulation.scene import SceneDef

        sdef = SceneDef.from_json((scene / "truth" / "scene.json").read_text())
        spec = sdef.preset_spec
        gsd = spec.gsd_m
        runs = [("half", [0, 0, spec.n_cols, spec.n_rows // 2]), ("full", None)]
        print(f"scene {scene} (preset {sdef.preset}, {spec.n_cols} x {spec.n_rows} px, "
              f"{gsd:g} m), {os.cpu_count()} cores, {load()}")
        for name, roi in runs:
            out = tmp_path / f"dem_{name}.tif"
            res = run_child(scene, out, roi, tmp_path / f"prefect_{name}")
            s = res["summary"]
            px = (roi[2] * roi[3]) if roi else spec.n_cols * spec.n_rows
            acc = accuracy(scene, out)
            print(f"{name:5s} {px / 1e6:5.1f} Mpx: flow {res['seconds']:6.1f} s "
                  f"({px / 1e6 / res['seconds']:.2f} Mpx/s; process {res['wall_s']:.1f} s with "
                  f"Prefect start), peak RSS {res['peak_mb']:.0f} MB; {s['n_tiles']} tiles; "
                  f"{load()}")
            print(f"      matched {s['match_rate_pct']:.1f} %, mismatched {s['mismatched_pct']:.1f} "
                  f"%, occluded {s['occluded_pct']:.1f} %; completeness "
                  f"{s['completeness_pct']:.1f} %; y residual <= {s['y_residual_max_px']:.3f} px")
            figures = ", ".join(f"{k} {v:.2f}" for k, v in acc.items())
            print(f"      DEM - truth after offset/tilt: {figures} (target bare soil NMAD <= "
                  f"{gsd:g} m)")


if __name__ == "__main__":
    main()
