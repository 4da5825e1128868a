"""The block's adjustment at scale (issue 49 item 2): :func:`core.orientation.adjust.adjust` on
synthetic blocks of 4, 8, 12, 16 and 20 images, its time and peak memory per size.

Each block is ``N / 2`` stereo pairs side by side (tiny-like pushbroom images: 600 x 600 px of
40 m, +25.5 / -20 degrees, each pair 19 km east of the last, a fifth of the swath
overlapping), as ``tests/core/orientation/test_block.py`` builds two: true models off the
delivered ones by attitude biases and rates, tie points between every overlapping image (the
same density over the whole block: 750 per pair, 0.1 px of noise), 40 SRTM-like GCPs per pair
(3 m of ground noise, 0.2 px), one reference frame. Every size is adjusted in a child process
of its own (``adjust`` with ``AdjustConfig()`` but ``along_track=False``: the images are
synthetic, their attitude smooth), whose CPU seconds and peak resident memory beyond what the
inputs held (Linux's VmHWM, reset just before the call through ``/proc/self/clear_refs``) are
printed with the wall time, the number of tie-point equations and the check points' worst RMS
(2000 error-free check points; the figure that must not move). The load average is printed
beside: the machine is shared, compare CPU seconds. Prints figures, asserts nothing.

    .venv/bin/python bench/perf/bench_block.py [--sizes 4 8 12 16 20] [--repeat 1]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

N_PX, GSD_M = 600, 40.0
EAST_DEG = 0.25  # the next pair 19.9 km east: a fifth of the 24 km swath overlaps
LAT0, HALF_LAT = 44.2, 0.1
TIES_PER_PAIR, GCPS_PER_PAIR = 750, 40


def _status_mb(key: str) -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(key):
            return float(line.split()[1]) / 1024.0
    return float("nan")


def block_inputs(n_images: int):
    """The delivered models, the truth, tie points, GCPs and check points of a block of
    ``n_images`` (an even number) images."""
    import numpy as np

    from core.orientation.frames import shifted_ground
    from core.orientation.ties import TieObservations
    from core.points import CheckPoint, CheckPointSet, ControlPoint, ImagePoint
    from core.sensors.pushbroom_synthetic import SyntheticSpec, seen_in, synthetic_pushbroom

    pairs = n_images // 2
    names = tuple(f"p{p:02d}{s}" for p in range(pairs) for s in "ab")
    lons = [5.25 + p * EAST_DEG for p in range(pairs)]
    delivered = tuple(synthetic_pushbroom(SyntheticSpec(
        lon, LAT0, 800.0, n_cols=N_PX, n_rows=N_PX, gsd_m=GSD_M, incidence_deg=inc,
        epoch_utc="2023-07-12T10:00:00Z")) for lon in lons for inc in (25.5, -20.0))
    rng = np.random.default_rng(47)
    truth = tuple(m.with_params(np.concatenate([rng.normal(0, 1e-4, 3), rng.normal(0, 2e-6, 2),
                                                [0.0]])) for m in delivered)

    def ground(lon0, lon1, n):
        return (rng.uniform(lon0, lon1, n), rng.uniform(LAT0 - HALF_LAT, LAT0 + HALF_LAT, n),
                500.0 + 800.0 * rng.uniform(size=n))

    def seen(lon, lat, h, noise_px):
        return seen_in(truth, lon, lat, h, N_PX, noise_px, rng)

    lon, lat, h = ground(lons[0] - 0.15, lons[-1] + 0.15, TIES_PER_PAIR * pairs)
    col, row = seen(lon, lat, h, 0.1)
    ok = np.isfinite(col).sum(axis=1) >= 2
    ties = TieObservations(col[ok], row[ok], lon[ok] + rng.normal(0, 20, ok.sum()) / 79_870,
                           lat[ok] + rng.normal(0, 20, ok.sum()) / 111_130,
                           h[ok] + rng.normal(0, 20, ok.sum()))
    gcps = []
    for p, lon0 in enumerate(lons):
        glon, glat, gh = ground(lon0 - 0.08, lon0 + 0.08, GCPS_PER_PAIR)
        c, r = seen(glon, glat, gh, 0.2)
        glon, glat, gh = shifted_ground(glon, glat, gh, rng.normal(0, 3.0, (glon.size, 3)))
        for i in range(glon.size):
            ips = {names[k]: ImagePoint(float(c[i, k]), float(r[i, k])) for k in (2 * p, 2 * p + 1)
                   if np.isfinite(c[i, k])}
            if len(ips) == 2:
                gcps.append(ControlPoint(len(gcps) + 1, float(glon[i]), float(glat[i]),
                                         float(gh[i]), ips, 3.0, 3.0, "srtm"))
    clon, clat, ch = ground(lons[0] - 0.1, lons[-1] + 0.1, 2000)
    cc, cr = seen(clon, clat, ch, 0.0)
    checks = CheckPointSet("EPSG:4326", names, tuple(
        CheckPoint(i, float(clon[i]), float(clat[i]), float(ch[i]), float("nan"), float("nan"),
                   float("nan"), "", {names[k]: ImagePoint(float(cc[i, k]), float(cr[i, k]))
                                      for k in range(n_images) if np.isfinite(cc[i, k])})
        for i in range(clon.size) if np.isfinite(cc[i]).any()))
    return names, delivered, ties, tuple(gcps), checks


def child(n_images: int) -> dict:
    """One size adjusted in this process: its figures."""
    from core.orientation.adjust import AdjustConfig, ControlSet, ImageToAdjust, adjust
    from core.orientation.frames import REFERENCE, FramePrior

    names, delivered, ties, gcps, checks = block_inputs(n_images)
    images = [ImageToAdjust(n, m, (N_PX, N_PX)) for n, m in zip(names, delivered, strict=True)]
    control = [ControlSet("surface", gcps, FramePrior(REFERENCE, (5.0, 5.0, 5.0)))]
    Path("/proc/self/clear_refs").write_text("5")  # VmHWM from here on
    base = _status_mb("VmRSS")
    t0, c0 = time.perf_counter(), time.process_time()
    solution = adjust(images, control, ties, AdjustConfig(along_track=False))
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    peak = _status_mb("VmHWM") - base
    got = solution.check_points(checks)
    worst = max(max(s.rms_col_px, s.rms_row_px) for s in got.values())
    pred = max(max(s.predicted_rms_col_px, s.predicted_rms_row_px) for s in got.values())
    return {"images": n_images, "ties": ties.n, "tie_equations": ties.n_equations,
            "gcps": len(gcps), "wall_s": wall, "cpu_s": cpu, "peak_mb": peak,
            "check_worst_px": worst, "predicted_worst_px": pred,
            "sigma0": solution.adjustment.sigma0}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[4, 8, 12, 16, 20],
                    help="images per block (even numbers)")
    ap.add_argument("--repeat", type=int, default=1, help="runs per size (the best kept)")
    ap.add_argument("--child", type=int, default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child is not None:
        print(json.dumps(child(args.child)))
        return
    if any(n < 2 or n % 2 for n in args.sizes):
        ap.error("--sizes are even numbers of images, at least 2")
    from bench.common import load

    print(f"{'images':>6s} {'ties':>6s} {'tie eq':>7s} {'gcps':>5s} {'wall s':>7s} "
          f"{'CPU s':>7s} {'CPU/img':>7s} {'peak MB':>8s} {'MB/img':>7s} {'check px':>9s} "
          f"{'pred px':>8s}  load", flush=True)
    for n in args.sizes:
        runs = []
        for _ in range(args.repeat):
            out = subprocess.run([sys.executable, __file__, "--child", str(n)], check=True,
                                 capture_output=True, text=True, cwd=REPO)
            runs.append(json.loads(out.stdout.strip().splitlines()[-1]))
        r = min(runs, key=lambda x: x["cpu_s"])
        print(f"{n:6d} {r['ties']:6d} {r['tie_equations']:7d} {r['gcps']:5d} "
              f"{r['wall_s']:7.2f} {r['cpu_s']:7.2f} {r['cpu_s'] / n:7.3f} "
              f"{r['peak_mb']:8.1f} {r['peak_mb'] / n:7.2f} {r['check_worst_px']:9.4f} "
              f"{r['predicted_worst_px']:8.4f}  {load()}", flush=True)


if __name__ == "__main__":
    main()
