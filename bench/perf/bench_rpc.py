"""Benchmark RPC projection of 1,000,000 points: gcpfree vs rpcm vs GDAL's RPC transformer.

Run from the repository root::

    .venv/bin/python bench/perf/bench_rpc.py [--n 1000000] [--repeat 3] [--json FILE]

Prints best-of-``repeat`` wall times, ratios (with the load average: the machine's other work
slows every figure; read the ratios of one run) and the largest disagreement; asserts nothing.
``gcpfree`` is the compiled kernel (:func:`core.sensors.rpc_kernels.rpc_project`, split over the cores);
``gcpfree NumPy`` the same model evaluated with NumPy, the reference the kernel is tested
against. The first call's time (Numba's import, then loading the kernel from its on-disk
cache, or compiling it the first time) is printed apart.
rpcm is optional (``bench/peers/rpcm``: ``pip install --no-deps "rpcm>=1.4"``). Its package ``__init__`` imports ``srtm4``
(which does not build here) and ``geojson``, so only its ``rpc_model`` module is loaded, through
a bare package stub that skips that ``__init__``.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from rasterio.rpc import RPC
from rasterio.transform import RPCTransformer

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from bench.common import Comparison, write_comparisons
from core.sensors.rpc import RPCModel
from tests.peers import rpcm_model_module

GEOM = Path(__file__).resolve().parents[2] / "tests" / "data" / "pleiades_ventoux" / "left_image.geom"


def best_time(fn: Callable[[], object], repeat: int) -> tuple[float, object]:
    best, out = float("inf"), None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1_000_000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--json", type=Path, default=None, help="write the comparisons there")
    args = ap.parse_args()

    model = RPCModel.from_geom(GEOM.read_text())
    rng = np.random.default_rng(0)
    n = args.n
    lon = model.lon_off + model.lon_scale * rng.uniform(-1, 1, n)
    lat = model.lat_off + model.lat_scale * rng.uniform(-1, 1, n)
    h = model.alt_off + model.alt_scale * rng.uniform(-1, 1, n)
    print(f"RPC: {GEOM.name}; projecting {n:,} points, best of {args.repeat}; "
          f"{os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f}")

    t_first, _ = best_time(lambda: model.project(lon[:10], lat[:10], h[:10]), 1)
    print(f"  first call (Numba import + kernel load or compile): {t_first:.2f} s")
    t_ours, (c_ours, r_ours) = best_time(lambda: model.project(lon, lat, h), args.repeat)
    results = {"gcpfree": t_ours}
    t, (c, r) = best_time(lambda: model._project_numpy(lon, lat, h), args.repeat)
    results["gcpfree NumPy"] = t
    print(f"  max |gcpfree - gcpfree NumPy| = "
          f"{max(np.max(np.abs(c - c_ours)), np.max(np.abs(r - r_ours))):.2e} px")

    rpcm_mod = rpcm_model_module()
    if rpcm_mod is None:
        print("  rpcm not installed (or its rpc_model does not import): skipping rpcm")
    else:
        rpcm_model = rpcm_mod.RPCModel(model.to_gdal_tags())
        t, (c, r) = best_time(lambda: rpcm_model.projection(lon, lat, h), args.repeat)
        results["rpcm"] = t
        print(f"  max |gcpfree - rpcm|  = {max(np.max(np.abs(c - c_ours)), np.max(np.abs(r - r_ours))):.2e} px")

    with RPCTransformer(RPC.from_gdal(model.to_gdal_tags())) as tr:
        t, (r, c) = best_time(lambda: tr.rowcol(lon, lat, zs=h, op=np.positive), args.repeat)
    results["GDAL RPCTransformer"] = t
    err = max(np.max(np.abs(c - 0.5 - c_ours)), np.max(np.abs(r - 0.5 - r_ours)))
    print(f"  max |gcpfree - (GDAL - 0.5)| = {err:.2e} px")

    print(f"{'implementation':<22}{'time [s]':>10}{'M points/s':>12}{'time / gcpfree':>16}")
    for name, t in results.items():
        print(f"{name:<22}{t:>10.3f}{n / t / 1e6:>12.2f}{t / t_ours:>16.1f}")
    if "rpcm" in results:
        print(f"gcpfree is {results['rpcm'] / t_ours:.1f}x rpcm (target >= 10); load average "
              f"{os.getloadavg()[0]:.1f}")

    what = f"RPC projection, {n:,} points"
    write_comparisons(args.json, "bench_rpc", [
        Comparison(what, peer, t_ours, results[name])
        for name, peer in (("rpcm", "rpcm"), ("GDAL RPCTransformer", "GDAL RPC transformer"))
        if name in results])

    # localisation, for information (Newton on project, from the affine first guess)
    t_loc, _ = best_time(lambda: model.localize(c_ours, r_ours, h), args.repeat)
    print(f"gcpfree localize (no inverse polynomial, Newton to 1e-8 px) of {n:,} points: "
          f"{t_loc:.3f} s ({n / t_loc / 1e6:.2f} M points/s)")


if __name__ == "__main__":
    main()
