"""Time, throughput and peak memory of ``gcpfree ortho`` on a simulated SPOT image, and the
speed ratio against GDAL's RPC warp on the same output grid.

Each run is a child process whose peak memory is the resident size of it and its threads,
sampled every 0.25 s. Two cases, each timed on our ortho and on GDAL's, one after the other:

- ``crop``: the middle ``--crop`` x ``--crop`` cells (4000 x 4000 by default) of the grid
  ``gcpfree ortho`` plans for the whole image;
- ``whole``: that whole grid.

In each case:

1. ``rpc``: the left image through its own RPC (the GeoTIFF's tags) on the scene's SRTM-like
   reference (lon/lat, ellipsoidal), bilinear, written as a COG with overviews (what
   ``gcpfree ortho`` writes);
2. ``gdal``: the same grid and resampling by GDAL (rasterio ``reproject`` of the image read
   whole, with ``rpcs=`` and ``RPC_DEM``, 2 warp threads), written as a tiled GeoTIFF; its
   values are compared with run 1. (Warping from the file, ``rasterio.band``, took as much
   CPU and more time here.)

Then, once, ``pushbroom``: the left image through its truth pushbroom model (with attitude
jitter when the scene has it) on the truth DSM (projected), bilinear, with the occlusion mask
(``--no-pushbroom`` skips it).

Both sides' times include planning the grid (which reads the DEM over the footprint) and
writing the output; not the start of the child process (imports) nor Numba's compilation
(the compiled kernels are loaded from Numba's on-disk cache, warmed by a first call before
the clock starts; the first-call time is printed). Throughput is in output cells per second
(Mpx/s). The load average is printed beside every figure: figures taken while other work
shares the cores are slower, and the ratio of two runs taken one after the other is what
to read. ``--repeat N`` times each pair N times (alternating ours and GDAL's).

    .venv/bin/python bench/perf/bench_ortho.py [--scene DIR] [--preset spot] [--crop 4000]
        [--repeat 1] [--no-pushbroom] [--json FILE]

``--scene`` is a simulated scene (``gcpfree simulate --preset spot --no-lidar --out DIR``, about
8 minutes); without it one is simulated into a temporary folder (``--preset`` picks another
preset). ``--json`` writes each case's medians, ours and GDAL's (what ``bench/perf/run.py``
prints). Prints figures, asserts nothing.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from bench.common import Comparison, given_or_simulated, load, workspace, write_comparisons
from bench.perf.meters import watch

CHILD = """
import dataclasses, json, sys, time
from pathlib import Path
from flows._env import configure_environment
configure_environment()
import numpy as np
from core.matching.grid import GridSpec
from core.ortho.ortho import OrthoConfig
from tasks.ortho.orthorectify import plan_ortho, orthorectify
from tasks.ortho.inputs import describe_dem
from tasks.io.sensors import load_model
scene, out, kind, crop = Path(sys.argv[1]), Path(sys.argv[2]), sys.argv[3], int(sys.argv[4])
image = scene / "left.tif"
if kind == "pushbroom":
    loaded = load_model(image, model=scene / "truth" / "left_truth.json")
    dem, occlusion = scene / "truth" / "dsm.tif", True
else:
    loaded = load_model(image, model=image)
    dem, occlusion = scene / "reference.tif", False
warm = 0.0
if kind != "gdal":  # load (or compile, the first time) the Numba kernels before the clock
    from core.ortho import kernels
    from core.ortho.ortho import SourceWindow, resample
    t = time.perf_counter()
    loaded.model.project(np.zeros(3) + 5.0, np.zeros(3) + 44.0, np.zeros(3))
    z = np.zeros((2, 2))
    kernels.bilinear(z, np.zeros(1), np.zeros(1))
    rows = np.zeros((1, 4), np.intp), np.ones((1, 4)) * 0.25
    kernels.upsample(np.zeros((1, 4, 4)), *rows, *rows)
    kernels.image_position(np.zeros((2, 2, 4, 4)), *rows, *rows, np.zeros((1, 1)), 0.0, 1.0)
    resample(np.zeros((4, 4), np.uint8), SourceWindow(0, 0, 4, 4), np.ones((1, 1)),
             np.ones((1, 1)), (4, 4), "bilinear", 0)
    for zt in (np.float32, np.float64):
        kernels.cell_heights(np.zeros((3, 4, 4)), *rows, *rows, np.zeros((2, 2), zt))
    kernels.footprint_bounds(np.ones((1, 1)), np.ones((1, 1)), (4, 4))
    kernels.to_integer(np.ones((1, 1)), np.dtype(np.uint8), 0.0)
    warm = time.perf_counter() - t
t0 = time.perf_counter()
plan = plan_ortho.fn(loaded, describe_dem(dem), 10.0, occlusion=occlusion)
g = plan.grid
if 0 < crop < min(g.n_rows, g.n_cols):
    c0, r0 = (g.n_cols - crop) // 2, (g.n_rows - crop) // 2
    g = GridSpec(g.x0_m + c0 * g.res_m, g.y0_m - r0 * g.res_m, g.res_m, crop, crop)
    plan = dataclasses.replace(plan, grid=g)
if kind == "gdal":
    import rasterio, rasterio.warp
    from affine import Affine
    from rasterio.enums import Resampling
    with rasterio.open(image) as src:
        pixels, rpcs = src.read(1), src.rpcs
    dst = np.zeros(g.shape, np.uint8)
    rasterio.warp.reproject(pixels, dst, rpcs=rpcs, src_crs="EPSG:4326",
                            dst_transform=Affine(*g.geotransform()), dst_crs=f"EPSG:{plan.epsg}",
                            resampling=Resampling.bilinear, dst_nodata=0, RPC_DEM=str(dem),
                            num_threads=2)
    with rasterio.open(out, "w", driver="GTiff", width=g.n_cols, height=g.n_rows, count=1,
                       dtype="uint8", crs=f"EPSG:{plan.epsg}", transform=Affine(*g.geotransform()),
                       nodata=0, tiled=True, compress="DEFLATE") as f:
        f.write(dst, 1)
    summary = {"width": g.n_cols, "height": g.n_rows, "max_error_px": None}
else:
    s = orthorectify.fn(plan, out, OrthoConfig(occlusion=occlusion))
    summary = s.to_dict()
dt = time.perf_counter() - t0
print("RESULT " + json.dumps({"seconds": dt, "warm_s": warm, "summary": summary}))
"""


def run_child(scene: Path, out: Path, kind: str, crop: int, home: Path) -> dict:
    """One ortho in a child process: its seconds (planning and writing included), summary
    and kernel warm-up time, the process's wall time and the peak memory of its tree."""
    env = dict(os.environ, PREFECT_HOME=str(home), DASK_TEMPORARY_DIRECTORY=str(home / "dask"))
    wall, peak, stdout, _ = watch([sys.executable, "-c", CHILD, str(scene), str(out), kind,
                                   str(crop)], env, kind, quiet=True)
    line = next(ln for ln in stdout.splitlines() if ln.startswith("RESULT "))
    return {**json.loads(line[len("RESULT "):]), "wall_s": wall, "peak_mb": peak}


def describe(kind: str, res: dict) -> str:
    s = res["summary"]
    mpx = s["width"] * s["height"] / 1e6
    err = s.get("max_error_px")
    warm = f", kernels loaded in {res['warm_s']:.2f} s" if kind != "gdal" else ""
    return (f"  {kind:9s} {s['width']} x {s['height']} cells ({mpx:.1f} Mpx): "
            f"{res['seconds']:6.1f} s ({mpx / res['seconds']:.2f} Mpx/s; process "
            f"{res['wall_s']:.1f} s{warm}), peak RSS {res['peak_mb']:.0f} MB"
            + (f", interpolation <= {err:.1e} px" if err is not None else "")
            + f"; {load()}")


def agreement(a: Path, b: Path) -> str:
    """Values and geometry of two orthos on one grid."""
    import numpy as np
    import rasterio

    from core.ortho.ortho_compare import CompareConfig
    from tasks.ortho.compare import compare_orthos, plan_compare

    with rasterio.open(a) as fa, rasterio.open(b) as fb:
        va, vb = fa.read(1).astype(float), fb.read(1).astype(float)
    both = (va > 0) & (vb > 0)
    diff = np.abs(va - vb)[both]
    plan = plan_compare.fn(a, b, CompareConfig(step_px=256))
    s = compare_orthos.fn(plan, a.with_suffix(".cmp.json")).stats
    return (f"  |ours - GDAL| mean {diff.mean():.3f} DN, 99th percentile "
            f"{np.percentile(diff, 99):.0f} DN; footprints differ on "
            f"{((va > 0) != (vb > 0)).mean() * 100:.3f} % of cells; ortho-compare median "
            f"{s.median_norm_px:.3f} px, RMS {s.rms_norm_px:.3f} px ({s.n_valid} windows)")


def main(argv: list[str] | None = None) -> None:
    from flows._env import configure_environment

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", type=Path, default=None, help="a simulated scene folder")
    ap.add_argument("--preset", default="spot", help="the preset simulated without --scene")
    ap.add_argument("--crop", type=int, default=4000,
                    help="cells per side of the crop case (0: whole grid only)")
    ap.add_argument("--repeat", type=int, default=1, help="timed pairs per case")
    ap.add_argument("--no-pushbroom", action="store_true", help="skip the pushbroom run")
    ap.add_argument("--json", type=Path, default=None, help="write the comparisons there")
    args = ap.parse_args(argv)
    if args.crop < 0 or args.repeat < 1:
        ap.error("--crop must be >= 0 and --repeat >= 1")
    with workspace() as (tmp_path, env):
        configure_environment(prefect_home=tmp_path / "prefect_main")
        scene = given_or_simulated(args.scene, tmp_path, env, args.preset, 1, "--no-lidar")
        print(f"scene {scene}, {os.cpu_count()} cores, {load()}")
        cases = ([("crop", args.crop)] if args.crop else []) + [("whole", 0)]
        summary, comparisons = [], []
        for case, crop in cases:
            print(f"{case}" + (f" ({crop} x {crop} cells)" if crop else ""))
            times: dict[str, list[float]] = {"rpc": [], "gdal": []}
            for k in range(args.repeat):
                res = {}
                for kind in ("rpc", "gdal"):
                    out = tmp_path / f"{case}_{kind}_{k}.tif"
                    res[kind] = run_child(scene, out, kind, crop, tmp_path / f"prefect_{kind}")
                    times[kind].append(res[kind]["seconds"])
                    print(describe(kind, res[kind]))
                print(f"  speed ratio GDAL time / ours (RPC, same grid): "
                      f"{res['gdal']['seconds'] / res['rpc']['seconds']:.2f}")
            print(agreement(tmp_path / f"{case}_rpc_0.tif", tmp_path / f"{case}_gdal_0.tif"))
            s = res["rpc"]["summary"]
            ours, gdal = statistics.median(times["rpc"]), statistics.median(times["gdal"])
            summary.append(f"{case}: ours / GDAL speed {gdal / ours:.2f}x (target >= 2)")
            comparisons.append(Comparison(
                f"ortho, {s['width']} x {s['height']} cells ({case})", "GDAL RPC warp", ours,
                gdal))
        if not args.no_pushbroom:
            res = run_child(scene, tmp_path / "pushbroom.tif", "pushbroom", 0,
                            tmp_path / "prefect_pushbroom")
            print("whole grid, truth pushbroom on the truth DSM, occlusion mask")
            print(describe("pushbroom", res))
        print("\n".join(summary) + f"; {load()}")
        write_comparisons(args.json, "bench_ortho", comparisons)


if __name__ == "__main__":
    main()
