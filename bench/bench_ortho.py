"""Time, throughput and peak memory of ``gcpfree ortho`` on a simulated SPOT image, and the
speed ratio against GDAL's RPC warp on the same output grid.

Three runs, each in a child process whose peak memory is the resident size of it and its
threads, sampled every 0.25 s:

1. ``rpc``: the left image through its own RPC (the GeoTIFF's tags) on the scene's SRTM-like
   reference (lon/lat, ellipsoidal), bilinear;
2. ``gdal``: the same grid and resampling by GDAL (rasterio ``reproject`` with ``rpcs=`` and
   ``RPC_DEM``, 2 warp threads), written as a tiled GeoTIFF; its values are compared with run 1;
3. ``pushbroom``: the left image through its truth pushbroom model (with attitude jitter when the
   scene has it) on the truth DSM (projected), bilinear, with the occlusion mask.

Throughput is in output cells per second (Mpx/s). The load average is printed: figures taken
while other work shares the cores are slower.

    .venv/bin/python bench/bench_ortho.py [SCENE_DIR]

SCENE_DIR is a simulated scene (``gcpfree simulate --preset spot --no-lidar --out DIR``, about
8 minutes); without it one is simulated into a temporary folder (GCPFREE_BENCH_PRESET picks
another preset). Prints figures, asserts nothing.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(Path(__file__).parent))

from bench_dsm import tree_rss_mb

CHILD = """
import json, sys, time
from pathlib import Path
from flows._env import configure_environment
configure_environment()
import numpy as np
from core.ortho import OrthoConfig
from tasks.ortho.orthorectify import plan_ortho, orthorectify
from tasks.ortho.inputs import describe_dem
from tasks.io.sensors import load_model
scene, out, kind = Path(sys.argv[1]), Path(sys.argv[2]), sys.argv[3]
image = scene / "left.tif"
if kind == "pushbroom":
    loaded = load_model(image, model=scene / "truth" / "left_truth.json")
    dem, occlusion = scene / "truth" / "dsm.tif", True
else:
    loaded = load_model(image, model=image)
    dem, occlusion = scene / "reference.tif", False
t0 = time.perf_counter()
plan = plan_ortho.fn(loaded, describe_dem(dem), 10.0, occlusion=occlusion)
if kind == "gdal":
    import rasterio, rasterio.warp
    from affine import Affine
    from rasterio.enums import Resampling
    g = plan.grid
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
print("RESULT " + json.dumps({"seconds": dt, "summary": summary}))
"""


def run_child(scene: Path, out: Path, kind: str, home: Path) -> dict:
    env = dict(os.environ, PREFECT_HOME=str(home), DASK_TEMPORARY_DIRECTORY=str(home / "dask"))
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-c", CHILD, str(scene), str(out), kind],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
                            cwd=REPO)
    peak = 0.0
    while proc.poll() is None:
        peak = max(peak, tree_rss_mb(proc.pid))
        time.sleep(0.25)
    stdout, stderr = proc.communicate()
    if proc.returncode != 0:
        print(stdout[-3000:], stderr[-3000:])
        raise SystemExit(f"{kind} failed")
    line = next(ln for ln in stdout.splitlines() if ln.startswith("RESULT "))
    res = json.loads(line[len("RESULT "):])
    res["wall_s"] = time.perf_counter() - t0
    res["peak_mb"] = peak
    return res


def agreement(a: Path, b: Path) -> str:
    """Values and geometry of two orthos on one grid."""
    import numpy as np
    import rasterio

    from core.ortho_compare import CompareConfig
    from tasks.ortho.compare import compare_orthos, plan_compare

    with rasterio.open(a) as fa, rasterio.open(b) as fb:
        va, vb = fa.read(1).astype(float), fb.read(1).astype(float)
    both = (va > 0) & (vb > 0)
    diff = np.abs(va - vb)[both]
    plan = plan_compare.fn(a, b, CompareConfig(step_px=256))
    s = compare_orthos.fn(plan, a.with_suffix(".cmp.json")).stats
    return (f"|ours - GDAL| mean {diff.mean():.3f} DN, 99th percentile "
            f"{np.percentile(diff, 99):.0f} DN; footprints differ on "
            f"{((va > 0) != (vb > 0)).mean() * 100:.3f} % of cells; ortho-compare median "
            f"{s.median_norm_px:.3f} px, RMS {s.rms_norm_px:.3f} px ({s.n_valid} windows)")


def main() -> None:
    from flows._env import configure_environment

    with tempfile.TemporaryDirectory() as tmp:
        tmp_path = Path(tmp)
        configure_environment(prefect_home=tmp_path / "prefect_main")
        if len(sys.argv) > 1:
            scene = Path(sys.argv[1])
        else:
            scene = tmp_path / "scene"
            preset = os.environ.get("GCPFREE_BENCH_PRESET", "spot")
            subprocess.run([sys.executable, "-m", "flows.cli", "simulate", "--preset", preset,
                            "--seed", "1", "--no-lidar", "--out", str(scene)], check=True,
                           cwd=REPO, capture_output=True,
                           env=dict(os.environ, PREFECT_HOME=str(tmp_path / "sim")))
        print(f"scene {scene}, {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f}")
        results = {}
        for kind in ("rpc", "gdal", "pushbroom"):
            out = tmp_path / f"{kind}.tif"
            res = run_child(scene, out, kind, tmp_path / f"prefect_{kind}")
            s = res["summary"]
            mpx = s["width"] * s["height"] / 1e6
            err = s.get("max_error_px")
            print(f"{kind:9s} {s['width']} x {s['height']} cells ({mpx:.1f} Mpx): "
                  f"{res['seconds']:6.1f} s ({mpx / res['seconds']:.2f} Mpx/s; process "
                  f"{res['wall_s']:.1f} s), peak RSS {res['peak_mb']:.0f} MB"
                  + (f", interpolation <= {err:.1e} px" if err is not None else "")
                  + f"; load average now {os.getloadavg()[0]:.1f}")
            results[kind] = res
        ratio = results["gdal"]["seconds"] / results["rpc"]["seconds"]
        print(f"speed ratio GDAL time / ours (RPC, same grid): {ratio:.2f} (target >= 1.0)")
        print(agreement(tmp_path / "rpc.tif", tmp_path / "gdal.tif"))


if __name__ == "__main__":
    main()
