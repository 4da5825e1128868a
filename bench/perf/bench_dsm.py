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

    .venv/bin/python bench/perf/bench_dsm.py [SCENE_DIR]

SCENE_DIR is a simulated scene (``gcpfree simulate --preset spot --no-lidar --out DIR``,
about 8 minutes); without it one is simulated into a temporary folder. GCPFREE_BENCH_PRESET
picks another preset for that. Prints figures, asserts nothing.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))

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


def _status_kb(pid: int, key: str = "VmRSS") -> float:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith(key):
                return float(line.split()[1])
    except OSError:
        pass
    return 0.0


def tree_pids(root: int) -> Iterator[int]:
    """A process and its descendants, Prefect's temporary API server (uvicorn) left out (its
    children still walked); a process gone meanwhile is skipped with its children."""
    todo, seen = [root], set()
    while todo:
        pid = todo.pop()
        if pid in seen:
            continue
        seen.add(pid)
        try:
            cmd = Path(f"/proc/{pid}/cmdline").read_bytes()
        except OSError:
            continue
        if b"uvicorn" not in cmd:
            yield pid
        for f in Path(f"/proc/{pid}/task").glob("*/children"):
            try:
                todo += [int(x) for x in f.read_text().split()]
            except OSError:
                pass


def tree_rss_mb(root: int) -> float:
    """Resident memory of a process and its descendants, Prefect's temporary API server
    (uvicorn) left out: what the DEM itself holds, its worker processes included."""
    return sum(_status_kb(pid) for pid in tree_pids(root)) / 1024.0


def run_child(scene: Path, out: Path, roi: list[int] | None, home: Path) -> dict:
    from tasks.io.geoid import BUNDLED_SRTM_DIR

    env = dict(os.environ, PREFECT_HOME=str(home), DASK_TEMPORARY_DIRECTORY=str(home / "dask"))
    extra = {"reference": str(BUNDLED_SRTM_DIR / "N44E005.hgt")}
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-c", CHILD, str(scene), str(out),
                             json.dumps(roi), json.dumps(extra)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env, cwd=REPO)
    peak = 0.0
    while proc.poll() is None:
        peak = max(peak, tree_rss_mb(proc.pid))
        time.sleep(0.25)
    stdout, stderr = proc.communicate()
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        print(stdout[-3000:], stderr[-3000:])
        raise SystemExit("dsm failed")
    line = next(ln for ln in stdout.splitlines() if ln.startswith("RESULT "))
    res = json.loads(line[len("RESULT "):])
    res["wall_s"] = wall
    res["peak_mb"] = peak
    return res


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


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        tmp_path = Path(tmp)
        if len(sys.argv) > 1:
            scene = Path(sys.argv[1])
        else:
            scene = tmp_path / "scene"
            preset = os.environ.get("GCPFREE_BENCH_PRESET", "spot")
            subprocess.run([sys.executable, "-m", "flows.cli", "simulate", "--preset", preset,
                            "--seed", "1", "--no-lidar", "--out", str(scene)], check=True,
                           cwd=REPO, capture_output=True,
                           env=dict(os.environ, PREFECT_HOME=str(tmp_path / "sim")))
        from core.simulation.scene import SceneDef

        sdef = SceneDef.from_json((scene / "truth" / "scene.json").read_text())
        spec = sdef.preset_spec
        gsd = spec.gsd_m
        runs = [("half", [0, 0, spec.n_cols, spec.n_rows // 2]), ("full", None)]
        print(f"scene {scene} (preset {sdef.preset}, {spec.n_cols} x {spec.n_rows} px, "
              f"{gsd:g} m), {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f}")
        for name, roi in runs:
            out = tmp_path / f"dem_{name}.tif"
            res = run_child(scene, out, roi, tmp_path / f"prefect_{name}")
            s = res["summary"]
            px = (roi[2] * roi[3]) if roi else spec.n_cols * spec.n_rows
            acc = accuracy(scene, out)
            print(f"{name:5s} {px / 1e6:5.1f} Mpx: flow {res['seconds']:6.1f} s "
                  f"({px / 1e6 / res['seconds']:.2f} Mpx/s; process {res['wall_s']:.1f} s with "
                  f"Prefect start), peak RSS {res['peak_mb']:.0f} MB; {s['n_tiles']} tiles; "
                  f"load average now {os.getloadavg()[0]:.1f}")
            print(f"      matched {s['match_rate_pct']:.1f} %, mismatched {s['mismatched_pct']:.1f} "
                  f"%, occluded {s['occluded_pct']:.1f} %; completeness "
                  f"{s['completeness_pct']:.1f} %; y residual <= {s['y_residual_max_px']:.3f} px")
            figures = ", ".join(f"{k} {v:.2f}" for k, v in acc.items())
            print(f"      DEM - truth after offset/tilt: {figures} (target bare soil NMAD <= "
                  f"{gsd:g} m)")


if __name__ == "__main__":
    main()
