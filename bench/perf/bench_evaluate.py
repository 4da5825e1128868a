"""Time and peak memory of the lidar evaluation (``tasks.evaluation.lidar``) as the point count grows.

A synthetic scene is written once in a temporary folder: a 4000x4000 DSM (2 m cells, UTM 31N,
ellipsoidal heights, tiled GeoTIFF) and LAZ files of 2 M and 20 M points (UTM 31N + EGM96
heights, three classes, written 1 M points at a time) scattered over the whole DSM in random
order, the worst case for the DEM windows. Each evaluation runs in a child process (no
Prefect: the task's own function) whose peak RSS is read from
``getrusage(RUSAGE_CHILDREN)``. Memory should not grow with the point count. Prints figures,
asserts nothing.

    .venv/bin/python bench/perf/bench_evaluate.py [--millions 2 20]
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))

X0, Y1, CELL, SIZE = 680_000.0, 4_900_000.0, 2.0, 4000
CHUNK = 1_000_000

CHILD = """
import sys, time
from pathlib import Path
from tasks.evaluation.lidar import EvaluationOptions, evaluate_plan, plan_evaluation
t0 = time.perf_counter()
options = EvaluationOptions(dem=Path(sys.argv[1]), lidar=Path(sys.argv[2]))
r = evaluate_plan(plan_evaluation(options))
dt = time.perf_counter() - t0
s = r.classes["2"]
print(f"{dt:.2f} {r.points.evaluated} {s.mean_m:.4f} {s.method}")
"""


def write_dem(path: Path) -> None:
    import rasterio
    from affine import Affine

    r, c = np.mgrid[0:SIZE, 0:SIZE].astype(np.float32)
    z = 400.0 + 0.01 * c - 0.02 * r + 5.0 * np.sin(c / 50.0) * np.cos(r / 70.0)
    with rasterio.open(path, "w", driver="GTiff", width=SIZE, height=SIZE, count=1,
                       dtype="float32", crs="EPSG:32631", tiled=True, blockxsize=512,
                       blockysize=512, nodata=np.nan,
                       transform=Affine(CELL, 0, X0, 0, -CELL, Y1)) as dst:
        dst.write(z, 1)
        dst.update_tags(vertical_datum="WGS84 ellipsoid")


def write_laz(path: Path, n_points: int, seed: int = 0) -> None:
    """Points at random over the DSM, heights 50 m below the DSM's mean level (a constant
    EGM96 height suffices: the figures here are time and memory)."""
    import laspy
    import pyproj

    rng = np.random.default_rng(seed)
    header = laspy.LasHeader(point_format=6, version="1.4")
    header.scales = np.array([0.001, 0.001, 0.001])
    header.offsets = np.array([X0, Y1 - SIZE * CELL, 0.0])
    header.add_crs(pyproj.CRS("EPSG:32631+5773"))
    with laspy.open(path, mode="w", header=header) as w:
        for start in range(0, n_points, CHUNK):
            n = min(CHUNK, n_points - start)
            rec = laspy.ScaleAwarePointRecord.zeros(n, header=header)
            rec.x = X0 + rng.uniform(1.0, SIZE * CELL - 1.0, n)
            rec.y = Y1 - rng.uniform(1.0, SIZE * CELL - 1.0, n)
            rec.z = 360.0 + rng.normal(0.0, 0.5, n)
            rec.classification = rng.choice(np.array([2, 5, 6], np.uint8), n)
            w.write_points(rec)


def measure(dem: Path, laz: Path) -> tuple[float, float, str]:
    """(seconds inside the child, peak RSS MB, the child's line)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    r = subprocess.run([sys.executable, "-c", CHILD, str(dem), str(laz)], cwd=REPO,
                       capture_output=True, text=True, check=False)
    if r.returncode != 0:
        print(r.stdout, r.stderr)
        raise SystemExit("evaluation failed")
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
    peak = max(before, peak)
    return float(r.stdout.split()[0]), peak / 1024, r.stdout.strip()


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--millions", type=float, nargs="+", default=[2, 20],
                    help="point counts in millions, smallest first (default 2 20)")
    sizes = sorted(int(m * 1e6) for m in ap.parse_args(argv).millions)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        dem = tmp / "dsm.tif"
        write_dem(dem)
        rows = []
        for n in sizes:  # smallest first: RUSAGE_CHILDREN keeps the running maximum
            laz = tmp / f"points_{n}.laz"
            t0 = time.perf_counter()
            write_laz(laz, n)
            t_write = time.perf_counter() - t0
            dt, peak_mb, line = measure(dem, laz)
            rows.append((n, laz.stat().st_size / 1e6, t_write, dt, peak_mb, line.split()[-1]))
            os.remove(laz)
        for n, mb, tw, dt, peak, method in rows:
            print(f"evaluate {n / 1e6:>4.0f} M points (LAZ {mb:.0f} MB, written in {tw:.1f} s) "
                  f"against a {SIZE}x{SIZE} DSM: {dt:.1f} s ({n / dt / 1e6:.2f} M points/s), "
                  f"peak RSS {peak:.0f} MB, order statistics {method}")


if __name__ == "__main__":
    main()
