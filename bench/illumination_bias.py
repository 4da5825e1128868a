"""The tie points' y-parallax bias from the two dates' illumination (issue 19).

An across-track pair from two dates is lit by two suns (the spot and tiny presets: 140 / 63
deg and 158 / 50 deg azimuth / elevation). Matching shaded relief under two suns moves the
matches off the true epipolar geometry by a common y-parallax, which the adjustment, weighting
hundreds of tie points, puts into the images' rows. This simulates the tiny pair twice, as the
preset has it and with the right image lit by the left's sun, finds the tie points of each
(``gcpfree relative``, with each ``--tie-measure``) and prints their mean y-parallax under the
true models (``prediction_check.mean_y_parallax``). Then, at true correspondences (left pixels
on a grid,
their ground on the truth DSM, the right position through the true models), it compares
normalised cross-correlation of 15 px templates with orientation correlation (the correlation
of unit gradient directions, Fitch et al. 2002, which Heid & Kaab 2012 found robust to
illumination; ``--tie-measure auto`` takes it for pairs whose suns differ): the mean right-row
error (the bias) and its spread. About 3 minutes on 2 cores; asserts nothing.
"""

from __future__ import annotations

import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import rasterio
from pyproj import Transformer
from scipy.interpolate import RegularGridInterpolator

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE.parent)]

import core.simulation.scene as scenes  # noqa: E402
from core.matching.peaks import (  # noqa: E402
    correlation_surface,
    integer_peak,
    quadratic_peak,
)
from core.matching.tiepoints import predict_search  # noqa: E402
from core.orientation.ties import TieObservations  # noqa: E402
from flows.cli import main as cli  # noqa: E402
from prediction_check import mean_y_parallax  # noqa: E402
from tasks.absolute.surface_match import TieGround  # noqa: E402
from tasks.io.sensors import read_model_file  # noqa: E402

ARGS = ["--preset", "tiny", "--seed", "1", "--center", "5.75", "44.75", "--lens", "--errors",
        "realistic", "--no-lidar"]


def bias(scene: Path, out: Path) -> tuple[int, float]:
    """The tie points of ``out`` (rel.json): their number and mean y-parallax (px)."""
    t = TieGround.from_tiepoints_json(out.with_suffix(".tiepoints.json"))
    ties = TieObservations(np.stack([t.left_col, t.right_col], 1),
                           np.stack([t.left_row, t.right_row], 1), t.lon_deg, t.lat_deg, t.h_m)
    truths = [read_model_file(scene / "truth" / f"{n}_truth.json").model
              for n in ("left", "right")]
    return ties.n, mean_y_parallax(truths, ties)


HALF, SEARCH, GRID = 7, 4, 40  # template half size, search half extent (px), points per side


def measures(scene: Path) -> dict[str, np.ndarray]:
    """Right-row errors (px) of each measure at true correspondences."""
    models = [read_model_file(scene / "truth" / f"{n}_truth.json").model
              for n in ("left", "right")]
    with rasterio.open(scene / "truth" / "dsm.tif") as src:
        z, t, crs = src.read(1).astype(np.float64), src.transform, src.crs
    x = t.c + (np.arange(z.shape[1]) + 0.5) * t.a
    y = t.f + (np.arange(z.shape[0]) + 0.5) * t.e
    surface = RegularGridInterpolator((y[::-1], x), z[::-1], bounds_error=False)
    to_xy = Transformer.from_crs("EPSG:4326", crs, always_xy=True)
    images = []
    for name in ("left", "right"):
        with rasterio.open(scene / f"{name}.tif") as src:
            images.append(src.read(1).astype(np.float32))
    left, right = images
    m = HALF + SEARCH + 2
    g = np.linspace(m, left.shape[0] - m - 1, GRID).round()
    col, row = (a.ravel() for a in np.meshgrid(g, g))
    h = np.full(col.size, float(np.nanmedian(z)))
    for _ in range(20):  # the left rays onto the truth DSM
        e, n = to_xy.transform(*models[0].localize(col, row, h))
        hit = surface(np.stack([n, e], -1))
        h = np.where(np.isfinite(hit), 0.5 * (h + hit), h)
    prior = predict_search(models[0], models[1], col, row, h, h - 3.0, h + 3.0, 10.0)
    u = np.arange(-(HALF + SEARCH + 1), HALF + SEARCH + 2, dtype=np.float32)
    out: dict[str, list[float]] = {"cross-correlation": [], "orientation correlation": []}
    for i in np.flatnonzero(prior.valid):
        j = prior.jacobian[i]
        mx = (np.float32(prior.right_col[i]) + np.float32(j[0, 0]) * u[None, :]
              + np.float32(j[0, 1]) * u[:, None])
        my = (np.float32(prior.right_row[i]) + np.float32(j[1, 0]) * u[None, :]
              + np.float32(j[1, 1]) * u[:, None])
        search = cv2.remap(right, mx, my, cv2.INTER_LINEAR, borderValue=0)
        c, r = int(col[i]), int(row[i])
        tpl = left[r - HALF - 1:r + HALF + 2, c - HALF - 1:c + HALF + 2]
        if search.min() <= 0 or tpl.min() <= 0:
            continue
        # the matcher's own measures (orientation correlation's inputs keep their border)
        ncc = correlation_surface("ncc", search[1:-1, 1:-1], tpl[1:-1, 1:-1])
        oc = correlation_surface("orientation", search, tpl)
        for name, surf in (("cross-correlation", ncc), ("orientation correlation", oc)):
            ix, iy, _, nb = integer_peak(surf)  # the matcher's own peak
            if nb is not None:
                dx, dy = quadratic_peak(nb)
                pc, pr = ix - SEARCH + dx[0], iy - SEARCH + dy[0]
                out[name].append(j[1, 0] * pc + j[1, 1] * pr)  # right rows
    return {k: np.asarray(v) for k, v in out.items()}


def main() -> None:
    preset = scenes.PRESETS["tiny"]
    left, right = preset.images
    one_sun = replace(preset, images=(left, replace(
        right, sun_azimuth_deg=left.sun_azimuth_deg, sun_elevation_deg=left.sun_elevation_deg)))
    with tempfile.TemporaryDirectory() as tmp:
        for label, p in (("two suns (the preset)", preset), ("one sun", one_sun)):
            scenes.PRESETS["tiny"] = p
            scene = Path(tmp) / label.split()[0]
            try:
                rc = cli(["simulate", *ARGS, "--out", str(scene)])
                for measure in ("ncc", "orientation"):
                    out = Path(tmp) / f"{label.split()[0]}_{measure}.json"
                    rc = rc or cli([
                        "relative", "--left", str(scene / "left.tif"), "--right",
                        str(scene / "right.tif"), "--reference", str(scene / "reference.tif"),
                        "--tie-measure", measure, "--out", str(out)])
                    if rc:
                        raise SystemExit(f"{label}: gcpfree failed ({rc})")
                    n, y = bias(scene, out)
                    print(f"tiny, {label}, --tie-measure {measure}: {n} tie points, mean "
                          f"y-parallax against the true models {y:+.3f} px")
            finally:
                scenes.PRESETS["tiny"] = preset
            for name, e in measures(scene).items():
                e = e[np.abs(e) < 2.0]  # wrong peaks out
                print(f"  {name}, {2 * HALF + 1} px templates at {e.size} true "
                      f"correspondences: right rows {e.mean():+.3f} +- "
                      f"{e.std() / np.sqrt(e.size):.3f} px, spread {e.std():.3f} px")


if __name__ == "__main__":
    main()
