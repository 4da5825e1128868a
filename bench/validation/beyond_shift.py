"""Check points of a simulated scene beyond the reference's own misregistration (issue 19).

A GCP-free orientation inherits the reference DEM's registration error whole: every GCP sits
where the reference puts the terrain, a shift common to all that no residual shows. On a
simulated scene the shift drawn is known (``truth/reference_errors.json``), so it can be carried
through the scene's true models and taken out of every check point's residual: what is left is
what the method itself achieves. The same for the prediction: ``report.json``'s predicted
check-point RMS less its reference term (the reference's stated registration sigma through the
ground's partial derivatives at the check points), so measured and predicted are compared on
the part that is not one draw per scene.

Run: ``.venv/bin/python bench/validation/beyond_shift.py SCENE_DIR ORIENT_DIR`` (the simulator's output
and ``gcpfree orient --checkpoints SCENE_DIR/truth/checkpoints.json``'s). Prints per image the
check points' RMS (col / row, px) as measured and beyond the shift, and the predicted RMS in
total and without the reference's term. Asserts nothing.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from core.geodesy import metres_per_degree  # noqa: E402
from core.intersection import triangulate  # noqa: E402
from core.orientation.uncertainty import ground_jacobian, predicted_rms_px  # noqa: E402
from tasks.absolute.orientation import NAMES, read_checkpoints  # noqa: E402
from tasks.io.sensors import read_model_file  # noqa: E402


def _rms(v: np.ndarray) -> float:
    return float(np.sqrt(np.mean(v**2)))


def gcp_common_error(scene: Path, out: Path) -> tuple[float, float, float]:
    """The used GCPs' mean error (east, north, up; m) against the truth: each GCP's image
    points triangulated with the scene's true models give its true ground."""
    rep = json.loads((out / "report.json").read_text())
    rejected = {r["id"] for r in rep["gcps"]["rejected_ids"]}
    pts = [p for p in json.loads((out / "gcps.json").read_text())["points"]
           if p["id"] not in rejected]
    models = [read_model_file(scene / "truth" / f"{n}_truth.json").model for n in NAMES]
    cols = [np.array([p["images"][n]["col"] for p in pts]) for n in NAMES]
    rows = [np.array([p["images"][n]["row"] for p in pts]) for n in NAMES]
    lon, lat, h = (np.array([p[k] for p in pts]) for k in ("lon_deg", "lat_deg", "h_m"))
    t = triangulate(models, cols, rows, (float(h.min()) - 500.0, float(h.max()) + 500.0))
    m_lon, m_lat = metres_per_degree(lat)
    return (float(np.mean((lon - t.lon_deg) * m_lon)), float(np.mean((lat - t.lat_deg) * m_lat)),
            float(np.mean(h - t.h_m)))


def _carried(truth, lon, lat, h, e: tuple[float, float, float]) -> tuple[np.ndarray, ...]:
    """What a common ground error ``e`` (east, north, up; m) of the GCPs leaves in check points'
    residuals: the adjusted model takes X + e to the image of X, so a check point at X computes
    the image of X - e and its residual holds truth(X) - truth(X - e)."""
    m_lon, m_lat = metres_per_degree(lat)
    tc, tr = truth.project(lon, lat, h)
    sc, sr = truth.project(lon - e[0] / m_lon, lat - e[1] / m_lat, h - e[2])
    return tc - sc, tr - sr


def beyond_shift(scene: Path, out: Path) -> dict[str, dict[str, float]]:
    """Per image: ``rms_col_px``/``rms_row_px`` measured, ``beyond_col_px``/``beyond_row_px``
    once the reference's drawn shift (through the true models) is out of every residual,
    ``beyond_common_col_px``/``beyond_common_row_px`` once the used GCPs' mean error against
    the truth (``gcp_common_error_m``: the shift, the canopy share the reference sees, its
    tilt, all common to the GCPs) is,
    ``predicted_col_px``/``predicted_row_px`` as report.json states them and
    ``predicted_beyond_col_px``/``predicted_beyond_row_px`` without their reference term."""
    rep = json.loads((out / "report.json").read_text())
    err = json.loads((scene / "truth" / "reference_errors.json").read_text())
    sigma = np.asarray(rep["settings"]["absolute"]["reference_sigma_m"], dtype=float)
    points = read_checkpoints(scene / "truth" / "checkpoints.json")
    common = gcp_common_error(scene, out)
    res: dict[str, dict[str, float]] = {}
    for name in NAMES:
        pts = [p for p in points.points if name in p.image_points]
        lon, lat, h, col, row = (np.array(v, dtype=float) for v in zip(
            *[(p.lon_deg, p.lat_deg, p.h_m, p.image_points[name].col,
               p.image_points[name].row) for p in pts], strict=True))
        model = read_model_file(out / f"{name}.json").model
        truth = read_model_file(scene / "truth" / f"{name}_truth.json").model
        pc, pr = model.project(lon, lat, h)
        dc, dr = col - pc, row - pr
        # the GCPs sit where the reference shows the terrain, moved by its shift
        shc, shr = _carried(truth, lon, lat, h, (err["shift_east_m"], err["shift_north_m"], 0.0))
        bc, br = dc - shc, dr - shr
        cmc, cmr = _carried(truth, lon, lat, h, common)
        gc, gr = dc - cmc, dr - cmr
        cp = rep["check_points"][name]
        ref_c, ref_r = predicted_rms_px(ground_jacobian(model, lon, lat, h), np.diag(sigma**2))
        res[name] = {
            "rms_col_px": _rms(dc), "rms_row_px": _rms(dr),
            "shift_col_px": _rms(shc), "shift_row_px": _rms(shr),
            "beyond_col_px": _rms(bc), "beyond_row_px": _rms(br),
            "beyond_mean_col_px": float(np.mean(bc)), "beyond_mean_row_px": float(np.mean(br)),
            "gcp_common_error_m": list(common),
            "beyond_common_col_px": _rms(gc), "beyond_common_row_px": _rms(gr),
            "predicted_col_px": cp["predicted_rms_col_px"],
            "predicted_row_px": cp["predicted_rms_row_px"],
            "predicted_beyond_col_px": float(np.sqrt(max(
                cp["predicted_rms_col_px"] ** 2 - ref_c**2, 0.0))),
            "predicted_beyond_row_px": float(np.sqrt(max(
                cp["predicted_rms_row_px"] ** 2 - ref_r**2, 0.0)))}
    return res


def line(name: str, r: dict[str, Any]) -> str:
    """One image's figures of :func:`beyond_shift` (col / row, px), as printed."""
    return (f"{name:5s} measured {r['rms_col_px']:.2f} / {r['rms_row_px']:.2f}, the shift "
            f"{r['shift_col_px']:.2f} / {r['shift_row_px']:.2f}, beyond it "
            f"{r['beyond_col_px']:.2f} / {r['beyond_row_px']:.2f} (mean "
            f"{r['beyond_mean_col_px']:+.2f} / {r['beyond_mean_row_px']:+.2f}), beyond the "
            f"GCPs' common error ({', '.join(f'{x:+.1f}' for x in r['gcp_common_error_m'])} "
            f"m) {r['beyond_common_col_px']:.2f} / {r['beyond_common_row_px']:.2f}; predicted "
            f"{r['predicted_col_px']:.2f} / {r['predicted_row_px']:.2f}, without the "
            f"reference {r['predicted_beyond_col_px']:.2f} / "
            f"{r['predicted_beyond_row_px']:.2f}; ratio beyond the common error "
            f"{r['beyond_common_col_px'] / r['predicted_beyond_col_px']:.2f} / "
            f"{r['beyond_common_row_px'] / r['predicted_beyond_row_px']:.2f}")


def main() -> None:
    if len(sys.argv) != 3:
        sys.exit("usage: beyond_shift.py SCENE_DIR ORIENT_DIR")
    scene, out = Path(sys.argv[1]), Path(sys.argv[2])
    err = json.loads((scene / "truth" / "reference_errors.json").read_text())
    print(f"reference shift E {err['shift_east_m']:+.1f} N {err['shift_north_m']:+.1f} m")
    for name, r in beyond_shift(scene, out).items():
        print(line(name, r))


if __name__ == "__main__":
    main()
