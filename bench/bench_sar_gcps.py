"""SAR-optical matching on a simulated scene with a SAR product (issue 20, item 3): how many
conjugate points, how wrong they are against the truth, and what a GCP made from each
(Goncalves 2002: the point's height from the SAR-optical parallax calibrated on the
reference, its planimetry from the SAR model at that height) is worth.

    .venv/bin/gcpfree simulate --preset tiny --seed 3 --relief-factor 0.05 --sar ers \\
        --out /tmp/s20/flat
    .venv/bin/python bench/bench_sar_gcps.py /tmp/s20/flat [--image left] [--cell 80]

Both images are resampled onto one ground grid (the reference DEM's heights, the delivered
models), described by oriented gradients (core/matching/multimodal.py) and matched: a few
large templates first (the scene's offset), then a template every 8 cells. Truth: the
optical pixel's 3-D point on the truth DSM (true optical model), projected by the true SAR
model, against the matched SAR pixel (in SAR pixels; the optical side is the better
conditioned one: a SAR pixel at a height step has several 3-D points). Printed: counts,
the offsets' error (median = bias, NMAD), the share beyond one SAR pixel, and each GCP's
error in optical pixels with the parallax heights, with the reference's, and with the true
SAR model (the part that is the matching's, not the SAR product's).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import rasterio
from pyproj import Transformer
from rasterio.errors import NotGeoreferencedWarning
from scipy.ndimage import gaussian_filter

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from core.dem import sample_bilinear
from core.geodesy import BBox, metres_per_degree
from core.matching import multimodal as mm
from core.robust import nmad, robust_fit
from core.sensors.sar import SarModel
from tasks.io.dem import dem_datum, read_reference
from tasks.io.sensors import load_model, read_model_file


def _read(path: Path) -> np.ndarray:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NotGeoreferencedWarning)
        with rasterio.open(path) as f:
            return f.read(1).astype(np.float64)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scene", type=Path)
    ap.add_argument("--image", default="left")
    ap.add_argument("--cell", type=float, default=None,
                    help="ground grid cell (m); default the SAR's ground spacing")
    ap.add_argument("--ignore-steps", choices=("none", "truth"), default="none",
                    help="leave out of the scores the cells near height steps of a DSM "
                         "(truth: the truth DSM, to see what a perfect mask gives)")
    ap.add_argument("--step-m", type=float, default=3.0)
    a = ap.parse_args()
    d = a.scene
    rec = json.loads((d / "truth" / "sar.json").read_text())
    cell = a.cell or max(rec["figures"]["ground_spacing_m"])
    opt, sar = load_model(d / f"{a.image}.tif"), load_model(d / "sar.tif")
    t0 = time.perf_counter()
    c = np.array([0, opt.size[0] - 1, 0, opt.size[0] - 1], float)
    r = np.array([0, 0, opt.size[1] - 1, opt.size[1] - 1], float)
    datum = dem_datum(d / "reference.tif").datum
    lon, lat = opt.model.localize(c, r, np.full(4, 0.0))
    ref = read_reference(d / "reference.tif",
                         BBox(lon.min(), lat.min(), lon.max(), lat.max()).expanded(0.05), datum)
    h_mid = float(np.nanmedian(ref.h_m))
    lon, lat = opt.model.localize(c, r, np.full(4, h_mid))
    g = mm.GroundGrid.covering(lon, lat, cell)
    LON, LAT = g.nodes()
    H = ref.height_m(LON, LAT)

    def ortho(model, image: np.ndarray, log: bool):
        cc, rr = mm.image_positions(model.project, g, H)
        gsd = cell / max(float(np.nanmedian(np.hypot(np.diff(cc, axis=1),
                                                     np.diff(rr, axis=1)))), 1e-9)
        if log:
            image = np.log(np.maximum(image, 1.0) ** 2)
        if 0.5 * cell / gsd > 0.5:
            image = gaussian_filter(image, 0.5 * cell / gsd)
        return sample_bilinear(image, rr, cc), cc, rr

    ol, occ, orr = ortho(opt.model, _read(d / f"{a.image}.tif"), False)
    os_, scc, srr = ortho(sar.model, _read(d / "sar.tif"), True)
    da, db = mm.orientation_channels(ol), mm.orientation_channels(os_)
    va, vb, st = np.isfinite(ol), np.isfinite(os_), mm.gradient_energy(ol)
    coarse = mm.MultimodalConfig(half_cells=max(min(g.shape) // 6, 8),
                                 radius_cells=int(np.ceil(1500.0 / cell)), min_score=0.1,
                                 min_structure=0.0)
    ci, cj = mm.template_centres(va, coarse.half_cells, coarse.half_cells)
    mc = mm.match_points(da, db, va, vb, st, (ci, cj), (0.0, 0.0), coarse)
    if not mc.ok.any():
        raise SystemExit(f"no coarse match: {mc.counts()}")
    oi, oj = float(np.median(mc.di[mc.ok])), float(np.median(mc.dj[mc.ok]))
    ignore = None
    if a.ignore_steps == "truth":
        from scipy.ndimage import maximum_filter, minimum_filter
        with rasterio.open(d / "truth" / "dsm.tif") as f:
            z, tz, cz = f.read(1).astype(np.float64), f.transform, f.crs
        x, y = Transformer.from_crs(4326, cz, always_xy=True).transform(LON, LAT)
        D = sample_bilinear(z, (y - tz.f) / tz.e - 0.5, (x - tz.c) / tz.a - 0.5)
        D = np.where(np.isfinite(D), D, np.nanmedian(D))
        inc = np.radians(rec["figures"]["incidence_centre_deg"])
        step = maximum_filter(D, 3) - minimum_filter(D, 3)
        tall = step[step > a.step_m]
        reach = int(np.ceil(float(np.percentile(tall, 90)) / np.tan(inc) / cell)) + 1 \
            if tall.size else 1
        ignore = maximum_filter(step > a.step_m, 2 * reach + 1)
        print(f"ignored: {100 * ignore.mean():.0f} % of the cells ({reach} cells around "
              f"steps over {a.step_m:g} m)")
    ci, cj = mm.template_centres(va, mm.MultimodalConfig().half_cells, 8)
    m = mm.match_points(da, db, va, vb, st, (ci, cj), (oi, oj), ignore_a=ignore)
    t_match = time.perf_counter() - t0
    print(f"grid {g.shape} of {cell:g} m; scene offset ({oi:+.2f}, {oj:+.2f}) cells from "
          f"{int(mc.ok.sum())} large templates; {ci.size} templates: {m.counts()}; "
          f"{t_match:.1f} s")

    ok = m.ok
    i0, j0 = m.i[ok], m.j[ok]
    po = sample_bilinear(occ, i0, j0), sample_bilinear(orr, i0, j0)
    ps = (sample_bilinear(scc, i0 + m.di[ok], j0 + m.dj[ok]),
          sample_bilinear(srr, i0 + m.di[ok], j0 + m.dj[ok]))
    lon0, lat0 = g.lonlat(i0, j0)
    href = ref.height_m(lon0, lat0)

    # truth: the optical pixel's 3-D point on the truth DSM, seen by the true SAR model
    opt_t = read_model_file(d / "truth" / f"{a.image}_truth.json").model
    sar_t = SarModel.from_json((d / "truth" / "sar_truth.json").read_text())
    with rasterio.open(d / "truth" / "dsm.tif") as f:
        dsm, tr, crs = f.read(1).astype(np.float64), f.transform, f.crs
    to_xy = Transformer.from_crs(4326, crs, always_xy=True)

    def dsm_at(lo, la):
        x, y = to_xy.transform(lo, la)
        return sample_bilinear(dsm, (y - tr.f) / tr.e - 0.5, (x - tr.c) / tr.a - 0.5)

    ht = np.full(i0.size, h_mid)
    for _ in range(10):
        ht = dsm_at(*opt_t.localize(*po, ht))
    sc, sr = sar_t.project(*opt_t.localize(*po, ht), ht)
    ec, er = ps[0] - sc, ps[1] - sr
    far = np.hypot(ec - np.nanmedian(ec), er - np.nanmedian(er)) > 1.0
    print(f"SAR pixel error of the matches (true SAR model): median {np.nanmedian(ec):+.2f} "
          f"col {np.nanmedian(er):+.2f} row, NMAD {nmad(ec[np.isfinite(ec)]):.2f} / "
          f"{nmad(er[np.isfinite(er)]):.2f}; beyond 1 SAR pixel of the median: "
          f"{100 * np.mean(far):.1f} %")

    # Goncalves: parallax along its height direction, calibrated on the reference heights
    def parallax(h):
        ls, as_ = sar.model.localize(*ps, h)
        lo, ao = opt.model.localize(*po, h)
        mx, my = metres_per_degree(ao)
        return np.stack([(ls - lo) * mx, (as_ - ao) * my], 1)

    d0 = parallax(href)
    v = (parallax(href + 10.0) - d0) / 10.0
    mx, my = metres_per_degree(float(lat0.mean()))
    basis = np.stack([np.ones_like(lon0), (lon0 - lon0.mean()) * mx / 1e4,
                      (lat0 - lat0.mean()) * my / 1e4], 1)
    field = np.stack([basis @ robust_fit(d0[:, k], basis)[0] for k in range(2)], 1)
    h_par = href + np.einsum("ij,ij->i", field - d0, v) / np.einsum("ij,ij->i", v, v)
    e = h_par - ht
    print(f"heights: parallax - truth median {np.nanmedian(e):+.2f} m NMAD "
          f"{nmad(e[np.isfinite(e)]):.2f}; reference - truth median "
          f"{np.nanmedian(href - ht):+.2f} NMAD {nmad((href - ht)[np.isfinite(ht)]):.2f}; "
          f"{np.median(np.linalg.norm(v, axis=1)):.2f} m of parallax per m")
    for label, model, h in (("parallax heights", sar.model, h_par),
                            ("reference heights", sar.model, href),
                            ("true SAR model, true heights", sar_t, ht)):
        gc, gr = opt_t.project(*model.localize(*ps, h), h)
        ec, er = po[0] - gc, po[1] - gr
        fin = np.isfinite(ec) & np.isfinite(er)
        print(f"GCP error in {a.image} px, {label}: median {np.median(ec[fin]):+.2f} col "
              f"{np.median(er[fin]):+.2f} row, NMAD {nmad(ec[fin]):.2f} / {nmad(er[fin]):.2f}")
    print(f"SAR product's delivered geolocation error at the centre (truth/sar.json): "
          f"{rec['centre_error_m']:.1f} m")


if __name__ == "__main__":
    main()
