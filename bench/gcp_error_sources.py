"""Where the GCPs' errors come from on a simulated scene, and whether the self-calibration test
sees them for a lens (issue 19).

For each SCENE_DIR ORIENT_DIR pair (``gcpfree simulate`` output and its ``gcpfree orient
--self-calibrate --checkpoints ...``), with GCPFREE_SOURCES_TRUTH_REF=1 also oriented again
against the scene's truth DSM averaged onto the reference's grid (no reference error at all;
into ``ORIENT_DIR_truthref``), it prints:

- the used GCPs' true errors (triangulated with the true models, mean taken out): their
  standard deviation east / north / up, the plane fitted to them (m per km), and their mean
  products in distance classes beside the exponential field fitted to them (a stationary field
  is never negative; a scene-wide pattern is);
- the self-calibration's Wald statistic of each image's lens terms with ``N^-1`` (what
  ``orient`` tests) and with the sandwich covariance of the correlated field.

Measured (2026-11-28): tiny seed 4 (33-41 GCPs, 40 m pixels) against its truth DSM still has
5.8 / 5.5 m of horizontal GCP error (7.3 / 4.9 against its SRTM-like reference) and check
points of 0.14 / 0.07 and 0.19 / 0.09 px; the reference is not the main source there. The same
place simulated without a lens keeps the lens terms (Wald 82 / 66 against 16.3; the tie points'
F 1.4 against 3.1), and its check-point columns are 0.107 / 0.104 px with them against 0.061 /
0.081 without self-calibration. With the sandwich the Wald is 22 / 19 there against 471 / 465
with a lens (both against their truth DSM; ``N^-1``: 82 / 66 and 602 / 534), but 16.4 / 17.2
against 144 / 120 against the SRTM-like references (``N^-1``: 18.5 / 22.1 and 472 / 389).

Run: ``.venv/bin/python bench/gcp_error_sources.py SCENE_DIR ORIENT_DIR [...]``. Prints
figures, asserts nothing.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import rasterio
from rasterio.warp import Resampling, reproject

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import prediction_check as pc  # noqa: E402

from core.orientation.ground_field import _distances, correlated_ground_error  # noqa: E402
from core.orientation.selfcal import TERMS, _wald  # noqa: E402
from tasks.io.sensors import read_model_file  # noqa: E402

CLASSES_KM = (0.0, 1.5, 3.0, 5.0, 8.0, 12.0, 18.0, 1e9)


def truth_reference(scene: Path, dest: Path) -> Path:
    """The scene's truth DSM averaged onto its reference's grid, tags and all."""
    if not dest.is_file():
        with rasterio.open(scene / "truth" / "dsm.tif") as src, \
                rasterio.open(scene / "reference.tif") as ref:
            out = np.full((ref.height, ref.width), np.nan, dtype=np.float32)
            reproject(src.read(1), out, src_transform=src.transform, src_crs=src.crs,
                      dst_transform=ref.transform, dst_crs=ref.crs, src_nodata=src.nodata,
                      dst_nodata=np.nan, resampling=Resampling.average)
            profile = {**ref.profile, "dtype": "float32", "nodata": np.nan}
            tmp = dest.with_suffix(".part.tif")
            with rasterio.open(tmp, "w", **profile) as dst:
                dst.write(out, 1)
                dst.update_tags(**ref.tags())
            tmp.replace(dest)
    return dest


def errors(scene: Path, out: Path) -> None:
    seen = pc.adjusted(scene, out)
    truths = [read_model_file(scene / "truth" / f"{n}_truth.json").model for n in pc.NAMES]
    e = pc.true_errors(truths, seen)
    e0 = e - e.mean(axis=0)
    x = np.column_stack([np.ones(len(e0)), seen["east"] / 1000.0, seen["north"] / 1000.0])
    plane = np.linalg.lstsq(x, e0, rcond=None)[0]
    vtrue = np.einsum("nmak,nk->nma", seen["g"], e0)
    field = correlated_ground_error(seen["g"], vtrue, seen["east"], seen["north"])
    print(f"{out.name}: {len(e0)} GCPs, true error sd E/N/U {np.round(e0.std(axis=0), 1)} m; "
          f"plane per km east {np.round(plane[1], 2)}, north {np.round(plane[2], 2)}; field "
          f"fitted to them {field.length_m / 1000:.1f} km {np.round(field.variance_m2, 1)} m2")
    d = _distances(seen["east"], seen["north"])
    iu = np.triu_indices(len(e0), 1)
    b = np.searchsorted(np.array(CLASSES_KM) * 1000.0, d[iu], side="right") - 1
    prod = e0[iu[0]] * e0[iu[1]]
    for k in range(len(CLASSES_KM) - 1):
        sel = b == k
        if sel.any():
            model = np.array(field.variance_m2) * np.exp(-d[iu][sel].mean() / field.length_m)
            print(f"  {CLASSES_KM[k]:4.1f}-{min(CLASSES_KM[k + 1], 99):4.1f} km ({sel.sum():3d} "
                  f"pairs): products E/N/U {np.round(prod[sel].mean(axis=0), 1)}, the field "
                  f"{np.round(model, 1)}")
    for name, names in zip(pc.NAMES, seen["final"].param_names, strict=True):
        terms = [t for t in TERMS.values() if t in names]
        if terms:  # the same parameters, before and after the sandwich replaced N^-1
            wald = [_wald(seen[k], name, terms) for k in ("adj", "final")]
            print(f"  {name}: lens terms' Wald {wald[0]:.1f} with N^-1, "
                  f"{wald[1]:.1f} with the sandwich")


def main() -> None:
    args = sys.argv[1:]
    if not args or len(args) % 2:
        sys.exit("usage: gcp_error_sources.py SCENE_DIR ORIENT_DIR [SCENE_DIR ORIENT_DIR ...]")
    for scene, out in zip(map(Path, args[::2]), map(Path, args[1::2]), strict=True):
        errors(scene, out)
        if os.environ.get("GCPFREE_SOURCES_TRUTH_REF") == "1":
            again = out.with_name(out.name + "_truthref")
            if not (again / "report.json").is_file():
                ref = truth_reference(scene, out.with_name(out.name + "_truth_dsm.tif"))
                subprocess.run([sys.executable, "-m", "flows.cli", "orient", "--left",
                                str(scene / "left.tif"), "--right", str(scene / "right.tif"),
                                "--reference", str(ref), "--checkpoints",
                                str(scene / "truth" / "checkpoints.json"), "--self-calibrate",
                                "--no-progress", "--out", str(again)], check=True,
                               capture_output=True)
            errors(scene, again)


if __name__ == "__main__":
    main()
