"""``gcpfree dsm`` and CARS side by side on the Pleiades Reunion pair, in one run.

Both get the same ROI (the left image's pixels 150 150 700 700, as CARS's GeoJSON: that ROI's
ground footprint at the terrain height), the same RPCs (the GeoTIFF tags, used as they are:
``--no-orient``) and EPSG:32740 (ours at 0.5 m; CARS at its default 0.8 m: it fails when
given both a resolution and a ROI); CARS also gets the constant initial elevation it needs on
such a crop. Ours is made in EGM96 heights (``--vertical
egm96``), CARS's DSM is in EGM96 heights: the two are compared at our cells (CARS sampled
bilinearly), over the cells both have.

Prints both wall times (each a fresh process, Prefect's temporary server included for ours),
both completenesses over the ROI footprint, and the median and NMAD of ours minus CARS's.
Targets (issue 10): our time <= 1/5 of CARS's, completeness >= CARS's, NMAD <= 0.5 m.

    bash bench/peers/cars/install.sh             # once: CARS in bench/peers/cars/.venv
    .venv/bin/python bench/perf/bench_dsm_cars.py [--initial-elevation H] [--keep DIR]
        [--json FILE]

``--json`` writes both times (what ``bench/perf/run.py`` prints).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))

from bench.common import Comparison, load, write_comparisons

DATA = REPO / "tests" / "data" / "pleiades_reunion"
CARS = REPO / "bench" / "peers" / "cars" / ".venv" / "bin" / "cars"
ROI = (150, 150, 700, 700)
RES_M = 0.5
EPSG = 32740

def run_ours(out: Path, tmp: Path) -> float:
    argv = ["dsm", "--left", str(DATA / "img_01.tif"), "--right", str(DATA / "img_02.tif"),
            "--roi", *map(str, ROI), "--resolution", str(RES_M), "--vertical", "egm96",
            "--no-orient", "--no-progress", "--out", str(out)]
    env = dict(os.environ, PREFECT_HOME=str(tmp / "prefect"))
    t0 = time.perf_counter()
    # the command as a user runs it (its temporary Prefect server and a fresh PREFECT_HOME:
    # a first run; bench/perf/bench_dsm_wall.py times later runs and where the time goes)
    r = subprocess.run([sys.executable, "-m", "flows.cli", *argv], cwd=REPO, env=env,
                       capture_output=True, text=True, check=False)
    dt = time.perf_counter() - t0
    if r.returncode:
        raise SystemExit(f"gcpfree dsm failed:\n{r.stderr[-3000:]}")
    print("\n".join(ln for ln in r.stdout.splitlines() if not ln[:2].isdigit()))
    return dt


def roi_footprint(h_m: float) -> list[list[float]]:
    """The left ROI's corners on the ground at ellipsoidal height ``h_m`` (lon, lat)."""
    from tasks.io.sensors import load_model

    model = load_model(DATA / "img_01.tif").model
    c0, r0, w, h = ROI
    cols = np.array([c0, c0 + w - 1, c0 + w - 1, c0, c0], float)
    rows = np.array([r0, r0, r0 + h - 1, r0 + h - 1, r0], float)
    lon, lat = model.localize(cols, rows, np.full(5, h_m))
    return [[float(a), float(b)] for a, b in zip(lon, lat, strict=True)]


def constant_dem(path: Path, corners: list[list[float]], value_m: float) -> None:
    import rasterio
    from rasterio.transform import from_origin

    lon = [c[0] for c in corners]
    lat = [c[1] for c in corners]
    step = 0.001
    west, north = min(lon) - 0.02, max(lat) + 0.02
    n_cols = int((max(lon) + 0.02 - west) / step) + 1
    n_rows = int((north - min(lat) + 0.02) / step) + 1
    with rasterio.open(path, "w", driver="GTiff", width=n_cols, height=n_rows, count=1,
                       dtype="float32", crs="EPSG:4326",
                       transform=from_origin(west, north, step, step)) as dst:
        dst.write(np.full((n_rows, n_cols), value_m, np.float32), 1)


def run_cars(out_dir: Path, tmp: Path, corners: list[list[float]], elevation_m: float) -> float:
    dem = tmp / "initial_elevation.tif"
    constant_dem(dem, corners, elevation_m)
    from tasks.io.crs import Projection

    # the ROI in UTM: CARS 1.3 fails ("math domain error") on a lon/lat ROI south of the
    # equator (its conversion of the resolution to the ROI's units goes negative)
    x, y = Projection(EPSG).to_xy(np.array([c[0] for c in corners]),
                                  np.array([c[1] for c in corners]))
    roi = {"type": "FeatureCollection",
           "crs": {"type": "name", "properties": {"name": f"EPSG:{EPSG}"}},
           "features": [{"type": "Feature", "properties": {},
                         "geometry": {"type": "Polygon",
                                      "coordinates": [[[float(a), float(b)]
                                                       for a, b in zip(x, y, strict=True)]]}}]}
    config = {
        "input": {
            "sensors": {"one": {"image": str(DATA / "img_01.tif")},
                        "two": {"image": str(DATA / "img_02.tif")}},
            "pairing": [["one", "two"]],
            "initial_elevation": {"dem": str(dem)},
            "roi": roi,
        },
        "orchestrator": {"mode": "multiprocessing", "nb_workers": os.cpu_count() or 2},
        "output": {"directory": str(out_dir), "epsg": EPSG},  # 0.5 m by default
        # (CARS 1.3 fails when both "resolution" and a ROI are given: list / float)
    }
    conf = tmp / "cars.json"
    conf.write_text(json.dumps(config, indent=1))
    t0 = time.perf_counter()
    r = subprocess.run([str(CARS), str(conf)], capture_output=True, text=True, check=False)
    dt = time.perf_counter() - t0
    if r.returncode:
        raise SystemExit(f"CARS failed:\n{r.stdout[-2000:]}\n{r.stderr[-3000:]}")
    return dt


def compare(ours: Path, cars: Path, corners: list[list[float]]) -> dict[str, float]:
    import pyproj
    import rasterio
    import rasterio.io
    from matplotlib.path import Path as Polygon

    from core.dem import sample_bilinear
    from tasks.io.crs import Projection

    def horizontal_epsg(src: rasterio.io.DatasetReader) -> int | None:
        crs = pyproj.CRS.from_wkt(src.crs.to_wkt())  # UTM + EGM96 height: a compound CRS
        if "EGM96" not in crs.to_wkt():
            raise SystemExit(f"{src.name} does not hold EGM96 heights ({crs.name})")
        return (crs.sub_crs_list[0] if crs.is_compound else crs).to_epsg()

    with rasterio.open(ours) as src:
        z, t = src.read(1).astype(np.float64), src.transform
        epsg = horizontal_epsg(src)
    with rasterio.open(cars) as src:
        zc = src.read(1, masked=True).astype(np.float64).filled(np.nan)
        tc = src.transform
        if horizontal_epsg(src) != epsg:
            raise SystemExit(f"CARS wrote EPSG:{horizontal_epsg(src)}, ours EPSG:{epsg}")
    rows, cols = np.mgrid[0:z.shape[0], 0:z.shape[1]]
    x, y = t.c + (cols + 0.5) * t.a, t.f + (rows + 0.5) * t.e
    px, py = Projection(epsg).to_xy(np.array([c[0] for c in corners]),
                                   np.array([c[1] for c in corners]))
    inside = Polygon(np.stack([px, py], 1)).contains_points(
        np.stack([x.ravel(), y.ravel()], 1)).reshape(z.shape)
    fi, fj = (tc.f - y) / -tc.e - 0.5, (x - tc.c) / tc.a - 0.5
    z_cars = sample_bilinear(zc, fi, fj)
    ii, jj = np.rint(fi).astype(int), np.rint(fj).astype(int)
    on = (ii >= 0) & (ii < zc.shape[0]) & (jj >= 0) & (jj < zc.shape[1])
    cars_valid = on & np.isfinite(zc[np.clip(ii, 0, zc.shape[0] - 1),
                                     np.clip(jj, 0, zc.shape[1] - 1)])
    both = inside & np.isfinite(z) & np.isfinite(z_cars)
    dz = (z - z_cars)[both]
    med = float(np.median(dz))
    return {
        "footprint_cells": int(inside.sum()),
        "ours_completeness_pct": 100.0 * float((np.isfinite(z) & inside).sum() / inside.sum()),
        "cars_completeness_pct": 100.0 * float((cars_valid & inside).sum() / inside.sum()),
        "cars_own_valid_pct": 100.0 * float(np.isfinite(zc).mean()),
        "median_m": med, "nmad_m": float(1.4826 * np.median(np.abs(dz - med))),
        "p90_abs_m": float(np.percentile(np.abs(dz - med), 90)), "n_cells": int(both.sum()),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--initial-elevation", type=float, default=1290.0,
                    help="CARS's constant initial elevation (m, EGM96; default 1290, the "
                         "issue's figure: the RPC's height offset)")
    ap.add_argument("--keep", type=Path, default=None, help="keep the products in this folder")
    ap.add_argument("--json", type=Path, default=None, help="write the comparison there")
    args = ap.parse_args()
    if not CARS.exists():
        raise SystemExit(f"{CARS} is missing: run bash bench/peers/cars/install.sh first")
    with tempfile.TemporaryDirectory() as tmp_name:
        tmp = Path(args.keep) if args.keep else Path(tmp_name)
        tmp.mkdir(parents=True, exist_ok=True)
        ours = tmp / "gcpfree_dsm.tif"
        t_ours = run_ours(ours, tmp)
        import rasterio

        with rasterio.open(ours) as src:
            h_mid = float(np.nanmedian(src.read(1)))
        # the ROI's footprint at the terrain height (EGM96 + about N: close enough for a ROI)
        corners = roi_footprint(h_mid)
        t_cars = run_cars(tmp / "cars", tmp, corners, args.initial_elevation)
        print(f"times: gcpfree dsm {t_ours:.1f} s, CARS {t_cars:.1f} s", flush=True)
        figures = compare(ours, tmp / "cars" / "dsm" / "dsm.tif", corners)
        print(f"gcpfree dsm  {t_ours:7.1f} s   completeness {figures['ours_completeness_pct']:.1f}"
              " % of the ROI footprint")
        print(f"CARS         {t_cars:7.1f} s   completeness {figures['cars_completeness_pct']:.1f}"
              f" % (its own raster: {figures['cars_own_valid_pct']:.1f} % valid)")
        print(f"time ratio   {t_ours / t_cars:.2f} (target <= 0.2)")
        print(f"ours - CARS  median {figures['median_m']:+.2f} m, NMAD {figures['nmad_m']:.2f} m,"
              f" 90 % of |dz - median| <= {figures['p90_abs_m']:.2f} m over "
              f"{figures['n_cells']} cells (both EGM96; target NMAD <= 0.5 m); {load()}")
        write_comparisons(args.json, "bench_dsm_cars", [Comparison(
            "DSM of the Pleiades Reunion ROI, from the shell", "CARS", t_ours, t_cars)])


if __name__ == "__main__":
    main()
