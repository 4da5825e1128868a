"""The simulator's golden hashes and its time (issue 49 item 3).

Same seed, same bytes: each case is simulated in a child process and every file it writes
(images, models, DIMAP metadata, truth rasters, check points, reference, lidar, radiance) is
hashed, SHA-256 of the file and, for a GeoTIFF, of its pixels alone (so a change of tags shows
apart from a change of values); the hashes are compared with ``bench/results/sim_golden.json``.
A change that moves bytes must say why and show the scene's figures unchanged (the figures the
simulator writes are printed beside the hashes: check points, DSM range, metadata errors).

    python bench/perf/bench_simulate.py [--case tiny|spot-crop ...] [--record] [--keep DIR]

Cases: ``tiny`` (the tiny preset, seed 11, lens, jitter, 10 % date change, an ERS-like SAR
product), ``spot-crop`` (the spot preset's sensor and realistic errors, lens, jitter and date
change, on a 1500 x 1500 px crop: 15 km instead of 60 km, registered in the child as the preset
``spot-crop``), ``block`` (``gcpfree simulate --block 2x2 --dates 2``, tiny, seed 5, realistic
errors, lens, jitter, 10 % date change; not run unless named). ``--record`` writes the hashes as the new golden ones. Prints per stage the
wall and CPU seconds (process CPU: every thread) and the load; exit status 1 when a hash differs.
Tasks run through ``.fn`` (no Prefect server: its start would dwarf the tiny case).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
GOLDEN = REPO / "bench" / "results" / "sim_golden.json"

CASES: dict[str, dict] = {
    "tiny": {"preset": "tiny", "seed": 11, "lens": True, "jitter": True, "date_change": 0.1,
             "errors": "simple", "sar": "ers"},
    "spot-crop": {"preset": "spot-crop", "seed": 1, "lens": True, "jitter": True,
                  "date_change": 0.1, "errors": "realistic", "sar": None},
    "block": {"preset": "tiny", "seed": 5, "lens": True, "jitter": True, "date_change": 0.1,
              "errors": "realistic", "sar": None, "block": (2, 2, 2)},
}
CROP_PX = 1500


def load() -> str:
    try:
        return " ".join(Path("/proc/loadavg").read_text().split()[:3])
    except OSError:
        return "?"


# ---------------------------------------------------------------------------- the child


def _stage(times: list, name: str, fn: Callable, *args: object) -> object:
    w, c = time.perf_counter(), time.process_time()
    out = fn(*args)
    times.append((name, time.perf_counter() - w, time.process_time() - c))
    return out


def child(case: str, out: Path) -> None:
    """Simulate one case into ``out`` as ``gcpfree simulate`` does (its flow's tasks, in its
    order, through ``.fn``); print the stage times as JSON on the last line."""
    from dataclasses import replace

    from core.simulation.scene import PRESETS, error_config

    PRESETS["spot-crop"] = replace(PRESETS["spot"], name="spot-crop", n_cols=CROP_PX,
                                   n_rows=CROP_PX)
    cfg = CASES[case]
    times: list = []
    errors = error_config(cfg["preset"], cfg["errors"], lens=cfg["lens"], jitter=cfg["jitter"])
    if "block" in cfg:
        _block(times, cfg, errors, out)
        print(json.dumps(times))
        return
    from flows.simulate_scene import BUNDLED_DEM
    from tasks.simulate import scene as S
    from tasks.simulate.sar import simulate_sar

    scene = _stage(times, "define", S.define_scene.fn, BUNDLED_DEM, out, cfg["preset"],
                   cfg["seed"], errors, 1.0, 8, cfg["date_change"])
    _stage(times, "dimap", S.write_spot_metadata.fn, scene, out)
    scene = _stage(times, "truth", S.build_truth_surface.fn, scene, out)
    for i in range(len(scene.image_names)):
        _stage(times, f"radiance{i}", S.build_radiance.fn, scene, out, i)
        _stage(times, f"render{i}", S.render_image.fn, scene, out, i)
    _stage(times, "checkpoints", S.make_checkpoints.fn, scene, out)
    _stage(times, "reference", S.make_reference.fn, scene, out)
    _stage(times, "lidar", S.make_lidar.fn, scene, out)
    if cfg["sar"]:
        _stage(times, "sar", simulate_sar.fn, scene, out, cfg["sar"])
    print(json.dumps(times))


def _block(times: list, cfg: dict, errors: object, out: Path) -> None:
    """A block as ``gcpfree simulate --block`` makes it (its flow's tasks, in its order)."""
    from core.simulation.block import BlockLayout
    from flows.simulate_scene import BUNDLED_DEM
    from tasks.simulate import block as B
    from tasks.simulate.scene import build_truth_surface
    from tasks.simulate.survey import make_reference

    opts = B.BlockOptions(BlockLayout(*cfg["block"]), cfg["preset"], cfg["seed"], errors,
                          date_change=cfg["date_change"])
    scene = _stage(times, "define", B.define_block.fn, BUNDLED_DEM, out, opts)
    _stage(times, "dimap", B.write_block_metadata.fn, scene, out)
    scene = _stage(times, "truth", build_truth_surface.fn, scene, out)
    for d in range(opts.layout.dates):
        _stage(times, f"radiance{d}", B.build_block_radiance.fn, scene, out, d)
        _stage(times, f"render{d}", B.render_block_images.fn, scene, out, d)
    _stage(times, "checkpoints", B.make_block_checkpoints.fn, scene, out)
    _stage(times, "reference", make_reference.fn, scene, out)


# ---------------------------------------------------------------------------- the parent


def file_hashes(root: Path) -> dict[str, dict[str, str]]:
    """SHA-256 of every file under ``root`` (relative POSIX path -> {"file", and for a GeoTIFF
    "pixels"}), the simulator's own temporary files left out."""
    import warnings

    import numpy as np
    import rasterio
    from rasterio.errors import NotGeoreferencedWarning

    out = {}
    for p in sorted(root.rglob("*")):
        if not p.is_file() or p.name.startswith("."):
            continue
        h = {"file": hashlib.sha256(p.read_bytes()).hexdigest()}
        if p.suffix == ".tif":
            with warnings.catch_warnings():  # the images have RPCs, no geotransform
                warnings.simplefilter("ignore", NotGeoreferencedWarning)
                src = rasterio.open(p)
            with src:
                h["pixels"] = hashlib.sha256(np.ascontiguousarray(src.read()).tobytes()
                                             ).hexdigest()
        out[p.relative_to(root).as_posix()] = h
    return out


def figures(root: Path) -> dict:
    """The figures the simulator writes about its scene(s): check points, DSM range, centre
    errors of the metadata; for a block, its overlaps (%) and B/H between dates."""
    figs = {}
    for sj in sorted(root.rglob("scene.json")):
        s = json.loads(sj.read_text())
        cp = sj.parent / "checkpoints.json"
        figs[sj.relative_to(root).as_posix()] = {
            "dsm_range_m": s.get("dsm_range_m"),
            "centre_error_m": {k: round(v["centre_error_m"], 3)
                               for k, v in s.get("injected", {}).items()},
            "checkpoints": (len(json.loads(cp.read_text())["points"]) if cp.exists() else None),
        }
        if (sj.parent / "block.json").exists():
            fig = json.loads((sj.parent / "block.json").read_text())["figures"]
            figs[sj.relative_to(root).as_posix()]["block"] = {
                k: [g["overlap_pct"] if k != "stereo" else g["b_over_h"] for g in fig[k]]
                for k in ("along_track", "across_track", "stereo")}
    return figs


def run_case(case: str, keep: Path | None) -> dict:
    with tempfile.TemporaryDirectory(prefix="bench_simulate_") as tmp:
        out = (keep / case) if keep else Path(tmp) / case
        env = dict(os.environ, PREFECT_HOME=str(Path(tmp) / "prefect"),
                   PREFECT_SERVER_ANALYTICS_ENABLED="false", PYTHONPATH=str(REPO))
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        w0, l0 = time.perf_counter(), load()
        proc = subprocess.run([sys.executable, __file__, "--child", case, str(out)], env=env,
                              cwd=REPO, capture_output=True, text=True, check=False)
        wall = time.perf_counter() - w0
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        if proc.returncode != 0:
            sys.exit(f"{case}: the simulation failed:\n{proc.stderr[-4000:]}")
        cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
        stages = json.loads(proc.stdout.strip().splitlines()[-1])
        return {"wall_s": wall, "cpu_s": cpu, "peak_rss_mb": after.ru_maxrss / 1024,
                "load": f"{l0} -> {load()}", "stages": stages,
                "hashes": file_hashes(out), "figures": figures(out)}


def compare(case: str, got: dict, golden: dict) -> list[str]:
    want = golden.get(case, {}).get("hashes")
    if want is None:
        return [f"{case}: no golden hashes recorded (run with --record)"]
    bad = []
    for name in sorted(set(want) | set(got["hashes"])):
        a, b = want.get(name), got["hashes"].get(name)
        if a is None or b is None:
            bad.append(f"{case}: {name} {'new' if a is None else 'missing'}")
        elif a != b:
            what = ("pixels" if a.get("pixels") != b.get("pixels") else "tags only") \
                if "pixels" in a else "bytes"
            bad.append(f"{case}: {name} differs ({what})")
    return bad


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--case", nargs="+", choices=sorted(CASES), default=["tiny", "spot-crop"])
    ap.add_argument("--record", action="store_true", help="write the hashes as the golden ones")
    ap.add_argument("--keep", type=Path, default=None, help="simulate into DIR/<case> and keep")
    ap.add_argument("--child", nargs=2, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child(args.child[0], Path(args.child[1]))
        return
    golden = json.loads(GOLDEN.read_text()) if GOLDEN.exists() else {}
    problems = []
    for case in args.case:
        got = run_case(case, args.keep)
        print(f"{case}: wall {got['wall_s']:.1f} s, CPU {got['cpu_s']:.1f} s, peak RSS "
              f"{got['peak_rss_mb']:.0f} MB, load {got['load']}")
        for name, w, c in got["stages"]:
            print(f"  {name:<14} wall {w:7.1f} s  CPU {c:7.1f} s")
        for scene, f in got["figures"].items():
            print(f"  {scene}: {json.dumps(f)}")
        if args.record:
            commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO,
                                    capture_output=True, text=True, check=False).stdout.strip()
            golden[case] = {"case": CASES[case], "hashes": got["hashes"],
                            "figures": got["figures"], "recorded_at": commit}
        else:
            bad = compare(case, got, golden)
            print(f"  {len(got['hashes'])} files, "
                  f"{'all as golden' if not bad else f'{len(bad)} DIFFERENT'}")
            problems += bad
    if args.record:
        GOLDEN.parent.mkdir(parents=True, exist_ok=True)
        GOLDEN.write_text(json.dumps(golden, indent=1, sort_keys=True) + "\n")
        print(f"recorded {GOLDEN.relative_to(REPO)}")
    for p in problems:
        print(p)
    sys.exit(1 if problems else 0)


if __name__ == "__main__":
    main()
