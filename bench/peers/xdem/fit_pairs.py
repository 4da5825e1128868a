"""xdem's Nuth & Kaab on DEM pairs, run by bench/peers/xdem/.venv/bin/python (xdem is not a
dependency of gcpfree): ``fit_pairs.py REF DEM [REF DEM ...] [--repeat N]``.

For each pair: the GeoTIFFs read with rasterio (NaN voids), ``xdem.coreg.NuthKaab()`` with its
defaults fitted ``N`` times on the arrays (the fit alone timed, wall and CPU seconds), its shift printed in the
reference's pixels, as gcpfree's ``shift_col_px``/``shift_row_px`` (the translation that,
added to the DEM's coordinates, aligns it with the reference) and metres up. One JSON line per
pair on stdout.
"""

from __future__ import annotations

import argparse
import json
import time
import warnings

import numpy as np
import rasterio
import xdem


def read(path: str) -> tuple[np.ndarray, rasterio.Affine, rasterio.crs.CRS]:
    with rasterio.open(path) as src:
        z = src.read(1, masked=True).astype(np.float32).filled(np.nan)
        return z, src.transform, src.crs


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("paths", nargs="+", help="REF DEM pairs")
    ap.add_argument("--repeat", type=int, default=1, help="fits per pair (default 1)")
    args = ap.parse_args()
    if len(args.paths) % 2:
        raise SystemExit("give REF DEM pairs")
    for ref_path, dem_path in zip(args.paths[::2], args.paths[1::2], strict=True):
        ref, transform, crs = read(ref_path)
        dem, _, _ = read(dem_path)
        times, cpu = [], []
        for _ in range(args.repeat):
            coreg = xdem.coreg.NuthKaab()
            t0, c0 = time.perf_counter(), time.process_time()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                coreg.fit(ref, dem, transform=transform, crs=crs, random_state=42)
            times.append(time.perf_counter() - t0)
            cpu.append(time.process_time() - c0)
        out = coreg.meta["outputs"]["affine"]
        print(json.dumps({
            "ref": ref_path, "dem": dem_path, "fit_s": times, "fit_cpu_s": cpu,
            "shift_col_px": float(out["shift_x"]) / transform.a,
            "shift_row_px": float(out["shift_y"]) / transform.e,
            "shift_up_m": float(out["shift_z"])}), flush=True)


if __name__ == "__main__":
    main()
