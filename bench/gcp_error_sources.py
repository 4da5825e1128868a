"""Where the GCPs' errors come from on a simulated scene, and whether the self-calibration test
sees them for a lens (issue 19).

For each SCENE_DIR ORIENT_DIR pair (``gcpfree simulate`` output and its ``gcpfree orient
--self-calibrate --checkpoints ...``), with GCPFREE_SOURCES_TRUTH_REF=1 also oriented again
against the scene's truth DSM averaged onto the reference's grid (no reference error at all;
into ``ORIENT_DIR_truthref``), it prints:

- the used GCPs' true errors (triangulated with the true models, mean taken out): their
  standard deviation east / north / up, the plane fitted to them (m per km), and their mean
  products in distance classes beside the exponential field fitted to them, as it is and less
  its mean (the products are of errors less their mean: far apart, an exponential is then
  negative too);
- the Wald statistic of each image's lens terms in the final adjustment with ``N^-1`` and with
  the sandwich covariance of the correlated field (``orient`` tests both on the adjustment
  with every term: ``N^-1`` at 3 sigma, the sandwich over 2 per term);
- each parameter's error from the GCPs' true errors over its standard deviation under their
  own statistics (:func:`parameter_z`), and over several orientations its RMS;
- with GCPFREE_SOURCES_PERFECT_DEM=1, every good window matched again with the relative DEM's
  cells and with a perfect relative DEM (the truth DSM carried into the relative frame at the
  same cells), their GCP errors against the true shift where each window says its shift holds
  (:func:`perfect_dem`).

Measured (2026-11-28): tiny seed 4 (33-41 GCPs, 40 m pixels) against its truth DSM still has
5.8 / 5.5 m of horizontal GCP error (7.3 / 4.9 against its SRTM-like reference) and check
points of 0.14 / 0.07 and 0.19 / 0.09 px. Over the eight tiny scenes against their SRTM-like
references the windows' GCPs are 6.1-14.8 m east and 5.4-13.6 m north off with the relative
DEM, 3.1-5.2 and 2.5-4.2 m with the perfect one: the relative DEM (11-16 m NMAD from the
perfect one) makes most of the GCPs' error on tiny, not the reference. The lens terms' z had
an RMS of 1.6-2.0 over those scenes: the GCPs' errors held a pattern across the swath. Its
cause: the relative DEM's outermost cells, half covered by matched points, were 31-40 m
outwards, and the windows the DEM's edge cuts put their GCPs 6 m inwards (a shrinking all
round); ``core.matching.grid.without_rim`` now leaves those cells out. The same place
simulated without a lens keeps the lens terms (Wald 82 / 66 against 16.3; the tie points' F
1.4 against 3.1), and its check-point columns are 0.107 / 0.104 px with them against 0.061 /
0.081 without self-calibration. With the sandwich the Wald is 22 / 19 there against 471 / 465
with a lens (both against their truth DSM; ``N^-1``: 82 / 66 and 602 / 534), but 16.4 / 17.2
against 144 / 120 against the SRTM-like references (``N^-1``: 18.5 / 22.1 and 472 / 389).

Measured (2026-11-29, GCPFREE_SOURCES_PERFECT_DEM=1 GCPFREE_SOURCES_PERFECT_REF=truth: neither
the DEM nor the reference has an error): tiny seeds 3, 4, 7 and 8 still have 0.9-3.2 m of GCP
error east, of which a cubic across the swath holds 0.19-0.69, and it follows the window's
slope-weighted average of the relative frame's deformation less its value where the GCP is
placed (correlation +0.76 to +0.86 east): a window's translation is the deformation's mean
over it, which the lens makes differ from its value at any one point.

Run: ``.venv/bin/python bench/gcp_error_sources.py SCENE_DIR ORIENT_DIR [...]``. Prints
figures, asserts nothing.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import rasterio
from pyproj import Transformer
from rasterio.warp import Resampling, reproject
from scipy.ndimage import map_coordinates

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import prediction_check as pc  # noqa: E402

from core.geodesy import BBox, metres_per_degree  # noqa: E402
from core.intersection import triangulate  # noqa: E402
from core.matching.surface import SurfaceMatchConfig, match_window  # noqa: E402
from core.orientation.ground_field import CorrelatedGroundError, _distances  # noqa: E402
from core.orientation.selfcal import TERMS, _wald  # noqa: E402
from core.robust import nmad  # noqa: E402
from core.sensors.pushbroom import PushbroomModel  # noqa: E402
from tasks.absolute.surface_match import TieGround, read_window_cells  # noqa: E402
from tasks.io.dem import read_reference  # noqa: E402
from tasks.io.sensors import load_model  # noqa: E402

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


def parameter_z(seen: dict, e0: np.ndarray, field: CorrelatedGroundError) -> dict[str, float]:
    """Each adjusted parameter's error made by the GCPs' true errors ``e0`` (n, 3; mean out),
    over its standard deviation under their own statistics: each GCP's own error (its outer
    product) plus ``field`` between GCPs. Over many scenes the z of a parameter has an RMS of
    1 when those statistics hold what the errors do in its direction."""
    m = pc.params_from_errors(seen)
    sd = np.sqrt(np.diag(m @ pc.error_statistics(seen, e0, field) @ m.T))
    names = [f"{im}.{p}" for im, pn in zip(pc.NAMES, seen["final"].param_names, strict=True)
             for p in pn]
    return dict(zip(names, (m @ e0.ravel()) / sd, strict=True))


def across_swath(err: np.ndarray, col: np.ndarray) -> np.ndarray:
    """The share of each component of ``err`` (n, 3; its mean out) a cubic in the image column
    ``col`` holds (a lens's shape across the swath; chance gives about 3 / (n - 1))."""
    u = (col - col.min()) / max(float(np.ptp(col)), 1e-9) * 2.0 - 1.0
    x = np.column_stack([np.ones_like(u), u, u**2, u**3])
    y = err - err.mean(axis=0)
    fit = x @ np.linalg.lstsq(x, y, rcond=None)[0]
    return 1.0 - np.sum((y - fit) ** 2, axis=0) / np.sum(y**2, axis=0)


def perfect_dem(scene: Path, out: Path, truths: list, reference: Path) -> None:
    """Each good window matched again against ``reference``, once with the relative DEM's cells
    (as ``orient`` matched them) and once with the truth DSM carried into the relative frame at
    the same cells (a relative DEM without errors), both against the true shift where the
    window says its shift holds; and the relative DEM's heights against the perfect ones.

    For both, the share of the GCP errors a cubic across the swath holds (:func:`across_swath`);
    for the perfect DEM, how its errors follow the window's average of the relative frame's
    true deformation, weighted by the squared slopes along each axis (the correlation's
    sensitivity), less the deformation where the GCP is placed: what a translation measures of
    a deformation that varies within the window. GCPFREE_SOURCES_PERFECT_REF=truth matches
    against the scene's truth DSM on the reference's grid instead (no reference error)."""
    cfg = SurfaceMatchConfig(**json.loads((out / "report.json").read_text())["settings"][
        "surface"])
    rel = json.loads((out / "relative" / "rel.json").read_text())
    models = [load_model(scene / "left.tif").model,
              PushbroomModel.from_dict(rel["right_model"])]
    ties = TieGround.from_tiepoints_json(out / "relative" / "rel.tiepoints.json")
    with rasterio.open(scene / "truth" / "dsm.tif") as src:
        truth = src.read(1).astype(np.float64)
        tr, to_xy = src.transform, Transformer.from_crs(4326, src.crs, always_xy=True)
    with rasterio.open(reference) as src:
        b = src.bounds
    ref = read_reference(reference, BBox(b.left + 0.01, b.bottom + 0.01, b.right - 0.01,
                                         b.top - 0.01), "ellipsoidal")

    def truth_h(lon: np.ndarray, lat: np.ndarray) -> np.ndarray:
        x, y = to_xy.transform(lon, lat)
        return map_coordinates(truth, [(y - tr.f) / tr.e - 0.5, (x - tr.c) / tr.a - 0.5],
                               order=1, mode="nearest")

    def true_shift(lon: np.ndarray, lat: np.ndarray, h: np.ndarray) -> np.ndarray:
        """Where the relative frame's (lon, lat, h) truly is, less it (m east, north, up)."""
        im = [mdl.project(lon, lat, h) for mdl in models]
        t = triangulate(truths, [im[0][0], im[1][0]], [im[0][1], im[1][1]],
                        (float(h.min()) - 800.0, float(h.max()) + 800.0))
        m_lon, m_lat = metres_per_degree(lat)
        return np.stack([(t.lon_deg - lon) * m_lon, (t.lat_deg - lat) * m_lat, t.h_m - h], 1)

    err: dict[str, list[np.ndarray]] = {"relative DEM": [], "perfect DEM": []}
    cols: dict[str, list[float]] = {"relative DEM": [], "perfect DEM": []}
    averaged = []
    spread = []
    for w in json.loads((out / "windows.json").read_text())["windows"]:
        if w["status"] != "OK":
            continue
        i = w["tie_point"]
        lon, lat, h = read_window_cells(str(out / "relative_dem.tif"), ties.lon_deg[i],
                                        ties.lat_deg[i], cfg.radius_m)
        ok = np.isfinite(h)
        perfect = np.full_like(h, np.nan)
        m_lon, m_lat = metres_per_degree(lat[ok])
        sh = true_shift(lon[ok], lat[ok], h[ok])
        for _ in range(2):  # the true shift at the perfect height, then the height again
            perfect[ok] = truth_h(lon[ok] + sh[:, 0] / m_lon, lat[ok] + sh[:, 1] / m_lat) - sh[:, 2]
            sh = true_shift(lon[ok], lat[ok], perfect[ok])
        for key, heights in (("relative DEM", h), ("perfect DEM", perfect)):
            mt = match_window(lon, lat, heights, (ties.lon_deg[i], ties.lat_deg[i]), ref, cfg)
            if mt.ok:  # against the true shift where the window says its shift holds
                at = [np.array([v]) for v in (mt.at_lon_deg, mt.at_lat_deg, mt.at_h_m)]
                at_shift = true_shift(*at)[0]
                err[key].append(np.array([mt.shift_east_m, mt.shift_north_m, mt.shift_h_m])
                                - at_shift)
                cols[key].append(float(models[0].project(*at)[0][0]))
                if key == "perfect DEM":  # the window's slope-weighted deformation, less at
                    gy, gx = np.gradient(heights.reshape(-1, int(np.argmax(np.diff(lon) < 0))
                                                         + 1))
                    weight = np.nan_to_num(np.stack([gx.ravel()[ok], gy.ravel()[ok]], 1) ** 2)
                    averaged.append(np.sum(weight * sh[:, :2], axis=0) / weight.sum(axis=0)
                                    - at_shift[:2])
        dh = (h - perfect)[ok]
        spread.append(nmad(dh))
    for key, v in err.items():
        x = np.array(v)
        print(f"  windows matched with the {key}: {len(x)}, GCP error sd E/N/U "
              f"{np.round(x.std(axis=0), 1)} m, mean {np.round(x.mean(axis=0), 1)}; a cubic "
              f"across the swath holds {np.round(across_swath(x, np.array(cols[key])), 2)} "
              f"(chance about {3 / max(len(x) - 1, 1):.2f})")
    x, a = np.array(err["perfect DEM"])[:, :2], np.array(averaged)
    x, a = x - x.mean(axis=0), a - a.mean(axis=0)
    print("  perfect DEM's errors against the window's slope-weighted deformation less at the "
          f"GCP (E / N): correlation {np.corrcoef(x[:, 0], a[:, 0])[0, 1]:+.2f} / "
          f"{np.corrcoef(x[:, 1], a[:, 1])[0, 1]:+.2f}, that average's sd "
          f"{np.round(a.std(axis=0), 1)} m")
    print(f"  relative DEM minus the perfect one: NMAD {np.median(spread):.1f} m (median over "
          "the windows)")


def errors(scene: Path, out: Path, pooled: dict[str, list[float]] | None = None) -> None:
    seen = pc.adjusted(scene, out)
    truths, e0, field = pc.true_error_field(scene, seen)
    x = np.column_stack([np.ones(len(e0)), seen["east"] / 1000.0, seen["north"] / 1000.0])
    plane = np.linalg.lstsq(x, e0, rcond=None)[0]
    print(f"{out.name}: {len(e0)} GCPs, true error sd E/N/U {np.round(e0.std(axis=0), 1)} m; "
          f"plane per km east {np.round(plane[1], 2)}, north {np.round(plane[2], 2)}; field "
          f"fitted to them {field.length_m / 1000:.1f} km {np.round(field.variance_m2, 1)} m2")
    d = _distances(seen["east"], seen["north"])
    n = len(e0)
    centred = np.eye(n) - 1.0 / n  # the products are of errors less their mean: J C J
    demeaned = centred @ field.correlation(d) @ centred
    iu = np.triu_indices(n, 1)
    b = np.searchsorted(np.array(CLASSES_KM) * 1000.0, d[iu], side="right") - 1
    prod = e0[iu[0]] * e0[iu[1]]
    for k in range(len(CLASSES_KM) - 1):
        sel = b == k
        if sel.any():
            model = np.array(field.variance_m2) * field.correlation(d[iu][sel].mean())
            less_mean = (np.array(field.variance_m2) * demeaned[iu][sel].mean()
                         - np.maximum(np.mean(e0**2, axis=0) - field.variance_m2, 0.0) / n)
            print(f"  {CLASSES_KM[k]:4.1f}-{min(CLASSES_KM[k + 1], 99):4.1f} km ({sel.sum():3d} "
                  f"pairs): products E/N/U {np.round(prod[sel].mean(axis=0), 1)}, the field "
                  f"{np.round(model, 1)}, less its mean {np.round(less_mean, 1)}")
    for name, names in zip(pc.NAMES, seen["final"].param_names, strict=True):
        terms = [t for t in TERMS.values() if t in names]
        if terms:  # the same parameters, before and after the sandwich replaced N^-1
            wald = [_wald(seen[k], name, terms) for k in ("adj", "final")]
            print(f"  {name}: lens terms' Wald {wald[0]:.1f} with N^-1, "
                  f"{wald[1]:.1f} with the sandwich")
    z = parameter_z(seen, e0, field)
    print("  parameters' z (error from the GCPs / sd from their statistics): "
          + ", ".join(f"{k} {v:+.1f}" for k, v in z.items()))
    if pooled is not None:
        for k, v in z.items():
            pooled.setdefault(k, []).append(v)
    if os.environ.get("GCPFREE_SOURCES_PERFECT_DEM") == "1":
        reference = Path(json.loads((out / "report.json").read_text())["settings"]["reference"])
        if os.environ.get("GCPFREE_SOURCES_PERFECT_REF") == "truth":
            reference = truth_reference(scene, out.with_name(out.name + "_truth_dsm.tif"))
        perfect_dem(scene, out, truths, reference)


def main() -> None:
    args = sys.argv[1:]
    if not args or len(args) % 2:
        sys.exit("usage: gcp_error_sources.py SCENE_DIR ORIENT_DIR [SCENE_DIR ORIENT_DIR ...]")
    pooled: dict[str, list[float]] = {}
    for scene, out in zip(map(Path, args[::2]), map(Path, args[1::2]), strict=True):
        errors(scene, out, pooled)
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
    if len(args) > 2:
        print("parameters' z, RMS over the orientations (1 where the errors' statistics hold): "
              + ", ".join(f"{k} {np.sqrt(np.mean(np.square(v))):.2f} ({len(v)})"
                          for k, v in pooled.items()))


if __name__ == "__main__":
    main()
