"""SAR-optical matching on a simulated scene with a SAR product (issue 20, item 3): how many
conjugate points, how wrong they are against the truth, and what a GCP made from each
(Goncalves 2002: the point's height from the SAR-optical parallax calibrated on the
reference, its planimetry from the SAR model at that height) is worth.

    .venv/bin/gcpfree simulate --preset tiny --seed 3 --relief-factor 0.05 --sar ers \\
        --out /tmp/s20/flat
    .venv/bin/python bench/validation/sar_gcps.py /tmp/s20/flat [--image left] [--cell 80] \\
        [--orient /tmp/s20/o_flat]

The matches and heights are the product's own (core/orientation/sar_gcps.py: both images
on one ground grid at the reference's heights through the delivered models, oriented
gradients, the scene's offset then a template every 8 or more cells; the parallax heights
calibrated on the reliable reference). With ``--orient`` (a ``gcpfree orient`` output of
the same scene) they are those ``gcpfree orient --sar`` makes: the SAR image matched
against the SAR image predicted from the pair's relative DEM (``relative_dem.tif``; the
right image through its relatively oriented model, ``relative/rel.json``), the parallax
calibrated on that surface's heights (its datum from the reference).

Truth: the optical pixel's 3-D point on the truth DSM (true optical model), projected by
the true SAR model, against the matched SAR pixel (in SAR pixels; the optical side is the
better conditioned one: a SAR pixel at a height step has several 3-D points). Printed:
counts, the offsets' error (median = bias, NMAD), the share beyond one SAR pixel, and each
GCP's error in optical pixels with the parallax heights, with the control heights (the
reference's, or the surface's with ``--orient``), and with the true SAR model (the part
that is the matching's, not the SAR product's).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import rasterio
from pyproj import Transformer
from rasterio.errors import NotGeoreferencedWarning

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from core.dem import sample_bilinear
from core.geodesy import BBox
from core.orientation import sar_gcps as sg
from core.orientation import sar_matching as sgm
from core.orientation import sar_prediction as sgp
from core.robust import nmad
from core.sensors.sar import SarModel
from core.sensors.troposphere import with_standard_troposphere
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
    ap.add_argument("--looks", type=int, default=1,
                    help="match the SAR image multilooked KxK (what orient does where the grid "
                         "of the product's own pixels would not fit: a Sentinel-1 GRD over a "
                         "spot scene); errors still in the product's pixels")
    ap.add_argument("--orient", type=Path, default=None,
                    help="a gcpfree orient output of the scene: match against the SAR image "
                         "predicted from its relative DEM")
    a = ap.parse_args()
    d = a.scene
    rec = json.loads((d / "truth" / "sar.json").read_text())
    cell = a.cell or max(rec["figures"]["ground_spacing_m"])
    opt, sar = load_model(d / f"{a.image}.tif"), load_model(d / "sar.tif")
    sar_image = _read(d / "sar.tif")
    if a.looks > 1:  # the product's pixels averaged in intensity, as orient does
        sar_image = sgm.multilooked(sar_image, (a.looks, a.looks))
        cell = a.cell or a.looks * max(rec["figures"]["ground_spacing_m"])
    if a.orient is not None and a.image == "right":  # the relative DEM's frame
        from core.sensors.pushbroom import PushbroomModel

        rel = json.loads((a.orient / "relative" / "rel.json").read_text())
        opt = replace(opt, model=PushbroomModel.from_dict(rel["right_model"]))
    t0 = time.perf_counter()
    c = np.array([0, opt.size[0] - 1, 0, opt.size[0] - 1], float)
    r = np.array([0, 0, opt.size[1] - 1, opt.size[1] - 1], float)
    datum = dem_datum(d / "reference.tif").datum
    lon, lat = opt.model.localize(c, r, np.full(4, 0.0))
    ref = read_reference(d / "reference.tif",
                         BBox(lon.min(), lat.min(), lon.max(), lat.max()).expanded(0.05), datum)
    h_mid = float(np.nanmedian(ref.h_m))
    lon, lat = opt.model.localize(c, r, np.full(4, h_mid))
    # as orient does: the standard atmosphere's hydrostatic delay out of the range timing
    base, delay_m = with_standard_troposphere(sar.model, float(np.mean(lon)),
                                              float(np.mean(lat)), h_mid)
    sar = replace(sar, model=base if a.looks == 1 else sgm.LookedModel(base, (a.looks,) * 2))
    print(f"troposphere {delay_m:.2f} m taken out of the range; looks {a.looks}x{a.looks}")
    cfg = sgm.SarGcpConfig(cell_m=a.cell)  # None: the grid may coarsen (speckle)
    g = sgm.ground_images(opt.model, _read(d / f"{a.image}.tif"), sar.model,
                         sar_image, ref, (lon, lat), cell)
    ignore = None
    if a.ignore_steps == "truth":
        from scipy.ndimage import maximum_filter, minimum_filter
        with rasterio.open(d / "truth" / "dsm.tif") as f:
            z, tz, cz = f.read(1).astype(np.float64), f.transform, f.crs
        x, y = Transformer.from_crs(4326, cz, always_xy=True).transform(*g.grid.nodes())
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
    sm = sgm.match_sar_optical(g, cfg, ignore)
    m = sm.matches
    t_match = time.perf_counter() - t0
    oi, oj = sm.offset_cells
    print(f"optical image on the reference's heights: grid {g.grid.shape} of {cell:g} m; "
          f"scene offset ({oi:+.2f}, {oj:+.2f}) cells; {m.status.size} templates: "
          f"{m.counts()}; {t_match:.1f} s")

    # truth: the optical pixel's 3-D point on the truth DSM, seen by the true SAR model
    opt_t = read_model_file(d / "truth" / f"{a.image}_truth.json").model
    sar_t = SarModel.from_json((d / "truth" / "sar_truth.json").read_text())
    with rasterio.open(d / "truth" / "dsm.tif") as f:
        dsm, tr, crs = f.read(1).astype(np.float64), f.transform, f.crs
    to_xy = Transformer.from_crs(4326, crs, always_xy=True)

    def dsm_at(lo, la):
        x, y = to_xy.transform(lo, la)
        return sample_bilinear(dsm, (y - tr.f) / tr.e - 0.5, (x - tr.c) / tr.a - 0.5)

    def truth_of(sm):
        """The matched optical and SAR pixels, the true heights and the SAR pixel error."""
        ok = sm.matches.ok
        if isinstance(sar.model, sgm.LookedModel):  # in the product's own pixels
            sm = replace(sm, **dict(zip(("sar_col", "sar_row"),
                                        sar.model.to_full(sm.sar_col, sm.sar_row), strict=True)))
        if ok.sum() < sgm.MIN_POINTS:
            raise SystemExit(f"{int(ok.sum())} matches ({sgm.MIN_POINTS} needed): nothing to "
                             "measure")
        po = sm.optical_col[ok], sm.optical_row[ok]
        ps = sm.sar_col[ok], sm.sar_row[ok]
        ht = np.full(po[0].size, h_mid)
        for _ in range(10):
            ht = dsm_at(*opt_t.localize(*po, ht))
        sc, sr = sar_t.project(*opt_t.localize(*po, ht), ht)
        ec, er = ps[0] - sc, ps[1] - sr
        far = np.hypot(ec - np.nanmedian(ec), er - np.nanmedian(er)) > 1.0
        print(f"SAR pixel error of the matches (true SAR model): median "
              f"{np.nanmedian(ec):+.2f} col {np.nanmedian(er):+.2f} row, NMAD "
              f"{nmad(ec[np.isfinite(ec)]):.2f} / {nmad(er[np.isfinite(er)]):.2f}; beyond 1 "
              f"SAR pixel of the median: {100 * np.mean(far):.1f} %")
        return po, ps, ht

    po, ps, ht = truth_of(sm)
    if a.orient is not None:
        from tasks.absolute.sar_control import read_surface

        t0 = time.perf_counter()
        surface = read_surface(a.orient / "relative_dem.tif")
        sm, pred = sgp.predicted_sar_matches(opt.model, _read(d / f"{a.image}.tif"), sar.model,
                                            sar_image, ref, surface, (lon, lat), cfg)
        e = pred.elevated
        print(f"SAR image predicted from the relative DEM (render cells {pred.cell_m:.1f} m): "
              f"vertical datum {pred.vertical_plane_m[0]:+.2f} m; elevated class "
              f"{'dark' if e.dark else 'bright'} {e.percentile:g} %, {e.height_m:.1f} m, blur "
              f"{e.blur_m:.0f} m, R2 {e.r2:.3f}; passes "
              + "; ".join(f"{p['cell_m']:.0f} m {p['counts']} moved E {p['moved_east_m']:+.1f}"
                          f" N {p['moved_north_m']:+.1f} m" for p in pred.passes)
              + f"; {time.perf_counter() - t0:.1f} s")
        po, ps, ht = truth_of(sm)
    ok = sm.matches.ok
    href = sm.h_ref_m[ok]

    # Goncalves: the product's heights (parallax calibrated on the reliable reference)
    reliable = sgm.reliable_reference(ref, sm.lon_deg[ok], sm.lat_deg[ok], cfg.max_slope)
    product = sar.model.base if isinstance(sar.model, sgm.LookedModel) else sar.model
    hts = sg.parallax_heights(opt.model, product, po, ps, href, reliable, cfg)
    h_par = hts.h_parallax_m
    e = h_par - ht
    print(f"heights: parallax - truth median {np.nanmedian(e):+.2f} m NMAD "
          f"{nmad(e[np.isfinite(e)]):.2f}; control - truth median "
          f"{np.nanmedian(href - ht):+.2f} NMAD {nmad((href - ht)[np.isfinite(ht)]):.2f}; "
          f"{np.median(hts.m_per_m):.2f} m of parallax per m")
    for label, model, h in (("parallax heights", product, h_par),
                            ("control heights", product, href),
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
