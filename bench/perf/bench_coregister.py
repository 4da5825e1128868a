"""``gcpfree coregister`` beside xdem's ``NuthKaab`` (xdem 0.2.3, its own venv:
``bash bench/peers/xdem/install.sh``) on DEM pairs with known sub-pixel shifts.

Pairs: a real DEM and a copy of it moved by a known (col, row) shift in pixels, by a quintic
spline (an interpolation neither implementation uses: gcpfree samples with a cubic spline),
lowered by a known dz, with 0.3 m of Gaussian noise; voids stay voids where they move.

- ``srtm``: the SRTM tile ``tasks/data/N44E005.hgt`` (1201 x 1201, Mont Ventoux), its heights
  on a 30 m grid of UTM 31N (xdem's slopes want metres; both get the same grid);
- ``reunion``: the DSM ``gcpfree dsm`` makes of the Pleiades Reunion ROI (720 x 737 cells of
  0.5 m, UTM 40S, 9 % voids), made here first unless ``--reunion-dsm`` gives it.

Printed per pair: the shift error of both (pixels, metres up), the fit time of both in
process (the fit alone on arrays in memory, median of ``--repeat``; target issue 21: ours <=
0.5 x xdem's), then from the shell: one ``gcpfree coregister`` process per pair against one
xdem process fitting all the pairs (import and reading included; target: ours faster), with
the CPU seconds of each beside the wall time, and the load average.

    bash bench/peers/xdem/install.sh           # once: xdem in bench/peers/xdem/.venv
    .venv/bin/python bench/perf/bench_coregister.py [--reunion-dsm DSM.tif] [--repeat 3]
        [--rounds 2] [--json FILE]

``--json`` writes the fit times (medians) and the last shell round, ours and xdem's (what
``bench/perf/run.py`` prints).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import rasterio
from affine import Affine
from scipy.ndimage import shift as nd_shift

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))

from bench.common import Comparison, load, write_comparisons

XDEM_PY = REPO / "bench" / "peers" / "xdem" / ".venv" / "bin" / "python"
XDEM_FIT = REPO / "bench" / "peers" / "xdem" / "fit_pairs.py"
SRTM = REPO / "tasks" / "data" / "N44E005.hgt"
REUNION = REPO / "tests" / "data" / "pleiades_reunion"
NOISE_M = 0.3
# (name, col px, row px, dz m): the DEM is the reference moved by (col, row) and dz lower
SHIFTS = {"srtm": (0.30, -0.45, 2.0), "reunion": (-0.35, 0.28, -1.5)}


def write(path: Path, z: np.ndarray, transform: Affine, crs: str) -> None:
    with rasterio.open(path, "w", driver="GTiff", width=z.shape[1], height=z.shape[0], count=1,
                       dtype="float32", crs=crs, transform=transform, nodata=np.nan,
                       tiled=True) as dst:
        dst.write(z.astype(np.float32), 1)
        dst.update_tags(vertical_datum="EGM96 geoid")


def moved(z: np.ndarray, col_px: float, row_px: float, dz_m: float, seed: int) -> np.ndarray:
    """``out[i, j] = z[i + row, j + col] - dz`` (quintic spline) plus noise; voids moved."""
    void = ~np.isfinite(z)
    filled = np.where(void, np.nanmean(z), z)
    out = nd_shift(filled, (-row_px, -col_px), order=5, mode="nearest") - dz_m
    out += np.random.default_rng(seed).normal(0.0, NOISE_M, z.shape)
    out[nd_shift(void.astype(float), (-row_px, -col_px), order=1, mode="constant",
                 cval=1.0) > 0] = np.nan
    return out


def reunion_dsm(tmp: Path) -> Path:
    out = tmp / "reunion_dsm.tif"
    subprocess.run([sys.executable, "-m", "flows.cli", "dsm", "--left",
                    str(REUNION / "img_01.tif"), "--right", str(REUNION / "img_02.tif"),
                    "--roi", "150", "150", "700", "700", "--resolution", "0.5",
                    "--vertical", "egm96", "--no-orient", "--no-progress", "--out", str(out)],
                   cwd=REPO, check=True, capture_output=True,
                   env=dict(os.environ, PREFECT_HOME=str(tmp / "prefect")))
    return out


def make_pairs(tmp: Path, dsm: Path) -> dict[str, tuple[Path, Path]]:
    z = np.fromfile(SRTM, dtype=">i2").reshape(1201, 1201).astype(np.float64)
    z[z < -1000] = np.nan
    sources = {"srtm": (z, Affine(30.0, 0, 650_000.0, 0, -30.0, 4_950_000.0), "EPSG:32631")}
    with rasterio.open(dsm) as src:
        sources["reunion"] = (src.read(1).astype(np.float64), src.transform, "EPSG:32740")
    pairs = {}
    for seed, (name, (z, transform, crs)) in enumerate(sources.items()):
        ref, dem = tmp / f"{name}_ref.tif", tmp / f"{name}_dem.tif"
        write(ref, z, transform, crs)
        write(dem, moved(z, *SHIFTS[name], seed=seed), transform, crs)
        pairs[name] = (ref, dem)
    return pairs


def ours_in_process(ref: Path, dem: Path, repeat: int) -> dict[str, float]:
    from core.evaluation.coregister import nuth_kaab
    from tasks.evaluation.coregister import read_grid

    ref_grid, _ = read_grid(ref)
    dem_grid, _ = read_grid(dem)
    times, cpu = [], []
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        r = nuth_kaab(ref_grid, dem_grid)
        times.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return {"fit_s": statistics.median(times), "fit_cpu_s": statistics.median(cpu),
            "shift_col_px": r.shift_col_px,
            "shift_row_px": r.shift_row_px, "shift_up_m": r.shift_up_m}


def xdem_process(paths: list[Path], repeat: int) -> tuple[list[dict], float, float]:
    """xdem fitting every pair in one process: its answers, wall and CPU seconds."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    r = subprocess.run([str(XDEM_PY), str(XDEM_FIT), *map(str, paths), "--repeat", str(repeat)],
                       capture_output=True, text=True, check=False)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if r.returncode:
        raise SystemExit(f"xdem failed:\n{r.stderr[-3000:]}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return [json.loads(ln) for ln in r.stdout.splitlines() if ln.startswith("{")], wall, cpu


def gcpfree_process(ref: Path, dem: Path, out: Path) -> tuple[float, float]:
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    r = subprocess.run([sys.executable, "-m", "flows.cli", "coregister", "--reference", str(ref),
                        "--dem", str(dem), "--out", str(out)], cwd=REPO, capture_output=True,
                       text=True, check=False)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if r.returncode:
        raise SystemExit(f"gcpfree coregister failed:\n{r.stderr[-3000:]}")
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def errors(r: dict, truth: tuple[float, float, float]) -> str:
    col, row, dz = truth
    return (f"error col {r['shift_col_px'] - col:+.4f} px, row {r['shift_row_px'] - row:+.4f} px, "
            f"up {r['shift_up_m'] - dz:+.3f} m")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reunion-dsm", type=Path, default=None,
                    help="the Reunion DSM (else made with gcpfree dsm first)")
    ap.add_argument("--repeat", type=int, default=3, help="in-process fits per pair (default 3)")
    ap.add_argument("--rounds", type=int, default=2,
                    help="shell rounds (both sides each round, default 2)")
    ap.add_argument("--json", type=Path, default=None, help="write the comparisons there")
    args = ap.parse_args()
    comparisons = []
    if not XDEM_PY.exists():
        raise SystemExit(f"{XDEM_PY} is missing: run bash bench/peers/xdem/install.sh first")
    with tempfile.TemporaryDirectory(prefix="bench-coregister-") as tmp_name:
        tmp = Path(tmp_name)
        dsm = args.reunion_dsm or reunion_dsm(tmp)
        pairs = make_pairs(tmp, dsm)
        paths = [p for pair in pairs.values() for p in pair]
        print(f"{os.cpu_count()} cores; {load()}; noise "
              f"{NOISE_M} m; shifts (col px, row px, dz m) {SHIFTS}")
        for name, (ref, dem) in pairs.items():  # the two sides in turn, pair by pair
            before = load()
            (xd,), _, _ = xdem_process([ref, dem], args.repeat)
            ours = ours_in_process(ref, dem, args.repeat)
            x_fit, x_cpu = statistics.median(xd["fit_s"]), statistics.median(xd["fit_cpu_s"])
            with rasterio.open(ref) as src:
                shape = src.shape
            print(f"{name} ({shape[1]} x {shape[0]} cells):")
            print(f"  gcpfree {errors(ours, SHIFTS[name])}; fit {ours['fit_s']:.2f} s "
                  f"({ours['fit_cpu_s']:.2f} s CPU)")
            print(f"  xdem    {errors(xd, SHIFTS[name])}; fit {x_fit:.2f} s ({x_cpu:.2f} s CPU)")
            comparisons.append(Comparison(f"coregistration fit, {name} ({shape[1]} x "
                                          f"{shape[0]} cells)", "xdem", ours["fit_s"], x_fit))
            print(f"  fit time ratio gcpfree / xdem {ours['fit_s'] / x_fit:.2f} wall, "
                  f"{ours['fit_cpu_s'] / x_cpu:.2f} CPU (target <= 0.5; "
                  f"{before} before, {load()} after)")
        print(f"from the shell: {len(pairs)} gcpfree coregister processes vs one xdem process "
              "fitting all pairs")
        for i in range(args.rounds):
            before = load()
            ours_wall = ours_cpu = 0.0
            for name, (ref, dem) in pairs.items():
                w, c = gcpfree_process(ref, dem, tmp / f"{name}.json")
                ours_wall, ours_cpu = ours_wall + w, ours_cpu + c
            _, x_wall, x_cpu = xdem_process(paths, 1)
            print(f"  round {i + 1}: gcpfree {ours_wall:.2f} s ({ours_cpu:.2f} s CPU), xdem "
                  f"{x_wall:.2f} s ({x_cpu:.2f} s CPU): ratio {ours_wall / x_wall:.2f} wall, "
                  f"{ours_cpu / x_cpu:.2f} CPU ({before} before, {load()} after)")
        if args.rounds:
            comparisons.append(Comparison(
                f"coregister from the shell, {len(pairs)} pairs (last round)", "xdem",
                ours_wall, x_wall))
        write_comparisons(args.json, "bench_coregister", comparisons)


if __name__ == "__main__":
    main()
