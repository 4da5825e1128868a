"""Time and peak memory of the tie-point search on the simulated `spot` pair (6000x6000, 10 m).

Target (issue 9, with the relative orientation): under 60 s and 1.5 GB on 2 cores. The pair is
simulated once into a temporary folder (about 8 min) unless ``--scene`` names the folder of an
existing `gcpfree simulate --preset spot` scene. The reference DEM is the bundled
SRTM tile made ellipsoidal by prepare-reference's tasks. The search runs in a child process
(its own peak RSS, VmHWM at its end: getrusage's ru_maxrss, in the child or in the parent,
keeps what the forked child held before its exec, the parent's 2 GB after the one-block timing
below); then the tie points are scored against
the scene's truth here: with the measure ``--tie-measure auto`` takes for the pair (orientation
correlation on the spot preset's two suns), then with NCC when that was another. Prints
figures, asserts nothing.

    .venv/bin/python bench/perf/bench_tiepoints.py [--scene DIR]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from bench.common import REPO, given_or_simulated, workspace

CHILD = """
import json, resource, sys, time
from pathlib import Path
from core.matching.tiepoints import TiePointConfig
from tasks.io.sensors import load_model
from tasks.relative.tiepoints import find_tie_points, tie_measure
scene, ref, out = (Path(a) for a in sys.argv[1:4])
left, right = load_model(scene / "left.tif"), load_model(scene / "right.tif")
measure = tie_measure(sys.argv[4], left.sun, right.sun)[0]
t0 = time.perf_counter()
res = find_tie_points.fn(scene / "left.tif", scene / "right.tif", left.model, right.model, ref,
                         TiePointConfig(measure=measure), out=out)
hwm = [ln.split()[1] for ln in Path("/proc/self/status").read_text().splitlines()
       if ln.startswith("VmHWM:")]  # this image's own peak (ru_maxrss survives the exec)
peak = float(hwm[0]) if hwm else resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(json.dumps({"seconds": time.perf_counter() - t0, "measure": measure,
                  "peak_mb": peak / 1024}))
"""


def score(scene: Path, tie_json: Path) -> str:
    """Tie points against the truth: the left pixel ray-cast on the truth DSM, projected by the
    true right model; errors split across / along the epipolar line (right pixels)."""
    import rasterio
    from rasterio.warp import Resampling, calculate_default_transform, reproject

    from core.dem import GeoDEM
    from core.matching.tiepoint_results import TiePointResult
    from core.sensors.base import localize_on_dem
    from core.sensors.pushbroom import PushbroomModel

    tp = TiePointResult.from_dict(json.loads(tie_json.read_text())).tie_points
    with rasterio.open(scene / "truth" / "dsm.tif") as src:
        t, w, h = calculate_default_transform(src.crs, "EPSG:4326", src.width, src.height,
                                              *src.bounds)
        z = np.full((h, w), np.nan)
        reproject(src.read(1).astype(np.float64), z, src_transform=src.transform,
                  src_crs=src.crs, dst_transform=t, dst_crs="EPSG:4326",
                  resampling=Resampling.bilinear, src_nodata=np.nan, dst_nodata=np.nan)
    dsm = GeoDEM.from_transform(z, tuple(t)[:6])
    tl, tr = (PushbroomModel.from_json((scene / "truth" / f"{n}_truth.json").read_text())
              for n in ("left", "right"))
    lon, lat, hh = localize_on_dem(tl, tp.left_col, tp.left_row, dsm)
    c, r = tr.project(lon, lat, hh)
    c2, r2 = tr.project(*tl.localize(tp.left_col, tp.left_row, hh + 50.0), hh + 50.0)
    e = np.stack([c2 - c, r2 - r])
    e /= np.linalg.norm(e, axis=0)
    d = np.stack([tp.right_col - c, tp.right_row - r])
    ok = np.all(np.isfinite(d), axis=0)
    along = np.sum(d * e, axis=0)[ok]
    across = (e[0] * d[1] - e[1] * d[0])[ok]
    err = np.hypot(*d[:, ok])
    return (f"against the truth ({ok.sum()} points): across-epipolar RMS "
            f"{np.sqrt(np.mean(across**2)):.3f} px, along-epipolar RMS "
            f"{np.sqrt(np.mean(along**2)):.3f} px, 2-D median {np.median(err):.3f} px, "
            f"{np.sum(err > 1)} over 1 px, {np.sum(err > 3)} over 3 px")


def one_tile(scene: Path, ref: Path, measure: str) -> float:
    """Seconds for the central 1024x1024 block alone, one thread."""
    from core.matching.tiepoints import HeightPrior, TiePointConfig
    from tasks.io.sensors import load_model
    from tasks.relative.tiepoints import Block, block_matches, raster_info, reference_under

    cfg = TiePointConfig(measure=measure)
    left, right = load_model(scene / "left.tif"), load_model(scene / "right.tif")
    size, saturation = raster_info(scene / "left.tif")
    heights = HeightPrior.from_dem(reference_under(ref, left.model, size), cfg.search_radius_m,
                                   cfg.height_margin_m)
    c, r = size[0] // 2 - 512, size[1] // 2 - 512
    t0 = time.perf_counter()
    block_matches(Block(c, r, c + 1024, r + 1024), str(scene / "left.tif"),
                  str(scene / "right.tif"), left.model, right.model, heights, cfg, saturation)
    return time.perf_counter() - t0


def main(argv: list[str] | None = None) -> None:
    from core.geodesy import BBox
    from tasks.io.geoid import BUNDLED_SRTM_DIR
    from tasks.io.reference import build_reference, locate_tiles

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", type=Path, default=None, help="a simulated spot scene folder")
    args = ap.parse_args(argv)
    with workspace() as (tmp_path, env):
        scene = given_or_simulated(args.scene, tmp_path, env, "spot", 1, "--lens", "--jitter",
                                   "--date-change", "0.1", "--no-lidar")
        ref = tmp_path / "ref.tif"
        box = BBox(5.0, 44.0, 6.0, 45.0)  # the bundled tile
        build_reference.fn(locate_tiles.fn(BUNDLED_SRTM_DIR, box), box, ref)
        out = tmp_path / "tiepoints.json"
        from core.matching.tiepoint_results import TiePointResult

        for asked in ("auto", "ncc"):  # auto: orientation correlation on a two-sun pair
            before = resource.getrusage(resource.RUSAGE_CHILDREN)
            r = subprocess.run([sys.executable, "-c", CHILD, str(scene), str(ref), str(out),
                                asked], capture_output=True, text=True, env=env, check=False,
                               cwd=REPO)
            if r.returncode != 0:
                print(r.stdout[-3000:], r.stderr[-3000:])
                raise SystemExit("tie points failed")
            done = json.loads(r.stdout.strip().splitlines()[-1])
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            cpu_s = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
            peak_mb = done["peak_mb"]
            report = TiePointResult.from_dict(json.loads(out.read_text())).report
            print(f"tie points on the spot pair, {done['measure']}: {done['seconds']:.1f} s on "
                  f"{os.cpu_count()} cores (Dask threads; the child process used {cpu_s:.0f} s "
                  f"of CPU with its imports), its peak RSS {peak_mb:.0f} MB "
                  "(target with the relative orientation: < 60 s, < 1536 MB)")
            print(f"one 1024x1024 block alone: {one_tile(scene, ref, done['measure']):.2f} s")
            print("\n".join(report.lines()))
            print(score(scene, out))
            if done["measure"] == "ncc":
                break


if __name__ == "__main__":
    main()
