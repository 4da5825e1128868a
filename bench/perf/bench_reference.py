"""Peak memory of prepare-reference over a 3x3 block of 1" tiles (3601x3601 each).

The tiles are synthetic copies (a smooth surface with a few voids) written as
.hgt; the CLI runs in a child process and its peak RSS is read from
``getrusage(RUSAGE_CHILDREN)``. Target: below 1 GB. Prints figures, asserts nothing.

    .venv/bin/python bench/perf/bench_reference.py
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


def write_tiles(folder: Path, lon0: int, lat0: int, n: int = 3) -> None:
    size = 3601
    j = np.arange(size) / 3600.0
    for lo in range(lon0, lon0 + n):
        for la in range(lat0, lat0 + n):
            lon = lo + j
            lat = la + 1 - j
            H = (800 + 400 * np.sin(4 * lon)[None, :] * np.cos(3 * lat)[:, None]).astype(">i2")
            H[1000:1010, 2000:2050] = -32768
            H.tofile(folder / f"N{la:02d}E{lo:03d}.hgt")


def main(argv: list[str] | None = None) -> None:
    argparse.ArgumentParser(description=__doc__.splitlines()[0]).parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        (tmp / "srtm").mkdir()
        write_tiles(tmp / "srtm", 5, 44)
        cmd = [sys.executable, "-m", "flows.cli", "prepare-reference", "--bbox", "5", "44", "8",
               "47", "--srtm-dir", str(tmp / "srtm"), "--out", str(tmp / "ref.tif")]
        env = dict(os.environ, PREFECT_HOME=str(tmp / "prefect"))
        t0 = time.perf_counter()
        r = subprocess.run(cmd, capture_output=True, text=True, env=env, check=False)
        dt = time.perf_counter() - t0
        if r.returncode != 0:
            print(r.stdout, r.stderr)
            raise SystemExit("prepare-reference failed")
        peak_mb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
        size_mb = (tmp / "ref.tif").stat().st_size / 1e6
        print(f"prepare-reference 3x3 1\" tiles (10801x10801 px): {dt:.1f} s, "
              f"peak RSS {peak_mb:.0f} MB (target < 1024 MB), COG {size_mb:.0f} MB")


if __name__ == "__main__":
    main()
