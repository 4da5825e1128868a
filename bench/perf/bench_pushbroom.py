"""Throughput of the rigorous pushbroom model: project and localize over 100k points.

A SPOT-like 6000x6000 scene at 10 m, 25 deg incidence, heights -400..4800 m. Prints figures,
asserts nothing.

    .venv/bin/python bench/perf/bench_pushbroom.py [--n 100000]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from core.sensors.pushbroom_synthetic import SyntheticSpec, synthetic_pushbroom


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=100_000, help="points (default 100000)")
    n = ap.parse_args(argv).n
    m = synthetic_pushbroom(SyntheticSpec(5.0, 44.0, incidence_deg=25.0))
    rng = np.random.default_rng(0)
    col, row, h = rng.uniform(0, 5999, n), rng.uniform(0, 5999, n), rng.uniform(-400, 4800, n)
    t0 = time.perf_counter()
    lon, lat = m.localize(col, row, h)
    t1 = time.perf_counter()
    c, r = m.project(lon, lat, h)
    t2 = time.perf_counter()
    err = float(np.max(np.hypot(c - col, r - row)))
    print(f"pushbroom localize {n} points: {t1 - t0:.2f} s ({n / (t1 - t0) / 1e3:.0f} k/s)")
    print(f"pushbroom project  {n} points: {t2 - t1:.2f} s ({n / (t2 - t1) / 1e3:.0f} k/s), "
          f"round trip max {err:.1e} px")


if __name__ == "__main__":
    main()
