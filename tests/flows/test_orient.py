"""``gcpfree orient`` end to end on the tiny simulated pair (lens, jitter, 10 % changed between
the dates, 100-300 m metadata errors) against an SRTM-like degraded reference: both sensor
families oriented to the check points with no GCP, the products readable, flat terrain and bad
input refused in one line."""

from __future__ import annotations

import argparse
import json
import math
import re
import shutil
from dataclasses import replace

import numpy as np
import pytest

from core.errors import InputError, InsufficientDataError, InsufficientReliefError
from core.geodesy import geodetic_to_enu
from core.intersection import triangulate
from core.jsonio import json_ready
from core.matching.relief import relief_sufficiency
from core.matching.surface import SurfaceMatchConfig, WindowMatch, WindowStatus
from flows.commands import orient as orient_command
from tasks.absolute.orientation import read_checkpoints
from tasks.absolute.report import REPORT
from tasks.io.pair import PairInputs
from tasks.io.products import GCPS
from tasks.io.sensors import load_model
from tests.scenes import dsm_against_truth


def parse(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="gcpfree")
    orient_command.add_parser(parser.add_subparsers(dest="command"))
    return parser.parse_args(["orient", *argv])


@pytest.fixture(scope="module")
def oriented(tiny_oriented):
    """The rigorous (pushbroom) family oriented with lens self-calibration (session run)."""
    return tiny_oriented


def test_pushbroom_pair_reaches_the_check_points_with_no_gcp(oriented):
    _, out, outcome = oriented
    report = json.loads((out / "report.json").read_text())
    # the typed report is the file, every key and value (read through its schema and back)
    assert report == json_ready(REPORT.dump(outcome.report)) == json_ready(
        REPORT.dump(REPORT.load(report)))
    before, after = report["check_points_before"], report["check_points"]
    for name in ("left", "right"):
        # the metadata are 100-300 m (2.5-7.5 px) off; SRTM alone brings them under a pixel
        # (jitter of 0.3 px and 40 m pixels in this scene)
        assert max(before[name]["rms_col_px"], before[name]["rms_row_px"]) > 2.0
        assert after[name]["n"] >= 50
        assert after[name]["rms_col_px"] < 0.7 and after[name]["rms_row_px"] < 0.7
        assert abs(after[name]["mean_row_px"]) < 0.4 and abs(after[name]["mean_col_px"]) < 0.4
    g = report["gcps"]
    assert g["used"] >= 8 and g["used"] + g["rejected"] == g["given"]
    assert report["relative"]["format"] == "gcpfree.relative"
    assert report["surface_matching"]["relief"]["enough"]
    # the lens is there (--lens): self-calibration keeps a term and lowers the column RMS
    lens = report["absolute"]["self_calibration"]
    assert lens["applied"]
    assert max(v["col_drop"] for v in lens["improvement"].values()) >= 0.3
    assert lens["decision"].startswith("kept in ")  # and says on what evidence


def test_products_are_what_the_report_says(oriented):
    scene, out, outcome = oriented
    cps = read_checkpoints(scene / "truth" / "checkpoints.json")
    for name in ("left", "right"):
        given = load_model(scene / f"{name}.tif")
        oriented_model = load_model(out / f"{name}.json")  # a gcpfree model file, reloadable
        # with the sun of the metadata it came from: a later `gcpfree dsm` on it chooses the
        # tie points' measure as the first run did
        assert given.sun is not None and oriented_model.sun == pytest.approx(given.sun)
        model = oriented_model.model
        pts = [p for p in cps.points if name in p.image_points]
        lon, lat, h = (np.array([getattr(p, k) for p in pts]) for k in ("lon_deg", "lat_deg",
                                                                        "h_m"))
        c, r = model.project(lon, lat, h)
        dc = np.array([p.image_points[name].col for p in pts]) - c
        dr = np.array([p.image_points[name].row for p in pts]) - r
        cp = outcome.report.check_points[name]
        assert np.sqrt(np.mean(dc**2)) == pytest.approx(cp.rms_col_px, rel=1e-9)
        assert np.sqrt(np.mean(dr**2)) == pytest.approx(cp.rms_row_px, rel=1e-9)
    gcps = GCPS.read(out / "gcps.json").points
    assert len(gcps) == outcome.report.gcps.given
    assert all(p.source == "srtm_surface_match" and p.sigma_xy_m > 0 for p in gcps)
    windows = json.loads((out / "windows.json").read_text())["windows"]
    assert sum(w["status"] == "OK" for w in windows) == len(gcps)
    assert (out / "relative_dem.tif").is_file() and (out / "relative" / "rel.json").is_file()


def test_simulated_gcps_sit_where_the_true_models_put_their_image_points(oriented):
    """The GCPs' ground against the intersection of their image points by the true models:
    the error of the local surface matching itself (40 m pixels, 3" reference)."""
    scene, out, _ = oriented
    gcps = GCPS.read(out / "gcps.json").points
    truth = [load_model(scene / "truth" / f"{n}_truth.json").model for n in ("left", "right")]
    cols = [np.array([g.image_points[n].col for g in gcps]) for n in ("left", "right")]
    rows = [np.array([g.image_points[n].row for g in gcps]) for n in ("left", "right")]
    t = triangulate(truth, cols, rows, (-500.0, 4000.0))
    lon, lat, h = (np.array([getattr(g, k) for g in gcps]) for k in ("lon_deg", "lat_deg", "h_m"))
    o = (float(np.mean(lon)), float(np.mean(lat)), float(np.mean(h)))
    e, n, u = (a - b for a, b in zip(geodetic_to_enu(lon, lat, h, o),
                                     geodetic_to_enu(t.lon_deg, t.lat_deg, t.h_m, o),
                                     strict=True))
    assert np.median(np.hypot(e, n)) < 25.0  # the metadata were 100-300 m off
    assert abs(np.median(u)) < 15.0


def assert_same_json(a, b, where: str = "") -> None:
    """Two JSON documents equal, their floats within 1e-9 (relative)."""
    if isinstance(a, dict) and isinstance(b, dict):
        assert a.keys() == b.keys(), where
        for k in a:
            assert_same_json(a[k], b[k], f"{where}/{k}")
    elif isinstance(a, list) and isinstance(b, list):
        assert len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            assert_same_json(x, y, f"{where}[{i}]")
    elif isinstance(a, float) or isinstance(b, float):
        assert math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-12), (where, a, b)
    else:
        assert a == b, (where, a, b)


def test_the_chain_never_needs_the_simulators_answers(tiny_oriented, tmp_path,
                                                       prefect_harness):
    """The scene folder as a user has it (images, their metadata, the reference; no truth/,
    no simulator work/), the check points copied elsewhere: the same GCPs and the same
    oriented models as the session's run beside truth/ (measured: byte-identical)."""
    from flows.orient import OrientParams, orient_flow

    scene, ref_out, ref_outcome = tiny_oriented
    bare = tmp_path / "scene"
    bare.mkdir()
    for p in scene.iterdir():
        if p.is_file():
            shutil.copy2(p, bare / p.name)
    assert not (bare / "truth").exists() and (bare / "left.tif").is_file()
    elsewhere = tmp_path / "control"
    elsewhere.mkdir()
    cps = shutil.copy2(scene / "truth" / "checkpoints.json", elsewhere / "checkpoints.json")
    out = tmp_path / "out"
    outcome = orient_flow(OrientParams(
        pair=PairInputs(bare / "left.tif", bare / "right.tif",
                        reference=bare / "reference.tif"),
        out=out, checkpoints=cps, self_calibrate=True, progress=False))
    for name in ("gcps.json", "left.json", "right.json", "windows.json"):
        assert_same_json(json.loads((out / name).read_text()),
                         json.loads((ref_out / name).read_text()), name)
    doc, ref_doc = REPORT.dump(outcome.report), REPORT.dump(ref_outcome.report)
    for key in ("gcps", "check_points", "check_points_before"):
        assert_same_json(doc[key], ref_doc[key], key)


def test_rpc_family_is_oriented_too(tiny_scene, tmp_path, prefect_harness):
    """The same pair through the RPCs inside the GeoTIFFs (affine bias per image): no lens
    terms for RPCs, so the lens stays in the residuals (the report says so)."""
    from flows.orient import OrientParams, orient_flow

    scene, _ = tiny_scene
    outcome = orient_flow(OrientParams(
        pair=PairInputs(scene / "left.tif", scene / "right.tif", scene / "left.tif",
                        scene / "right.tif", reference=scene / "reference.tif"),
        out=tmp_path, checkpoints=scene / "truth" / "checkpoints.json", self_calibrate=True,
        progress=False))
    r = outcome.report
    assert json.loads((tmp_path / "left.json").read_text())["type"] == "rpc"
    assert not r.absolute.self_calibration.applied
    assert r.absolute.self_calibration.decision.startswith("no pushbroom image")
    for name in ("left", "right"):
        assert r.check_points_before[name].rms_row_px > 2.0
        assert r.check_points[name].rms_row_px < 0.8
        assert r.check_points[name].rms_col_px < 1.0


def test_too_few_windows_with_relief_is_refused_with_the_figures(tiny_scene, tmp_path,
                                                                  prefect_harness):
    """Asking for more qualifying windows than the scene can hold: not 'too flat' (the windows
    it holds have the relief) but too few windows, with the counts and what to change, and no
    report (an orientation is never written on too little)."""
    from core.errors import InsufficientDataError
    from flows.orient import OrientParams, orient_flow

    scene, _ = tiny_scene
    with pytest.raises(InsufficientDataError) as err:
        orient_flow(OrientParams(pair=PairInputs(scene / "left.tif", scene / "right.tif",
                                                 reference=scene / "reference.tif"),
                                 out=tmp_path, min_windows=500, progress=False))
    m = re.search(r"too few surface-matching windows: (\d+) placed, (\d+) with enough relief"
                  r".*, 500 needed; .*--min-windows", str(err.value))
    assert m, str(err.value)
    placed, qualified = int(m[1]), int(m[2])
    assert 20 < qualified <= placed < 500 and "flat" not in str(err.value)
    assert not (tmp_path / "report.json").exists()


@pytest.mark.slow
def test_nearly_flat_terrain_is_refused_with_the_relief_figures(tmp_path_factory,
                                                               prefect_harness):
    """The tiny pair with its relief scaled by 0.05 (some 11 m of relief about the plane per
    4 km window, 40 m pixels, the simulator's simple errors): too flat for the relative DEM's
    noise. Refused in one line with the relief found, either by the relief verdict (too few
    windows promise the precision: the relief found and needed) or, when the windows' relief
    passes it, because none of them correlates (their fate and the relief); never an
    orientation. (With the realistic errors and reference the same relief orients to 0.44 px:
    ``bench/validation/relief_sweep.py``.)"""
    from flows.orient import OrientParams, orient_flow
    from tests.scenes import run_scene

    scene = tmp_path_factory.mktemp("flat")
    run_scene(scene, seed=21, jitter=False, lidar=False, relief_factor=0.05, date_change=0.1)
    out = tmp_path_factory.mktemp("flat_out")
    with pytest.raises((InsufficientReliefError, InsufficientDataError)) as err:
        orient_flow(OrientParams(pair=PairInputs(scene / "left.tif", scene / "right.tif",
                                                 reference=scene / "reference.tif"),
                                 out=out, progress=False))
    msg = str(err.value)
    assert "\n" not in msg
    if isinstance(err.value, InsufficientReliefError):
        m = re.search(r"too flat for GCP-free orientation: (\d+) of (\d+) windows judged.* "
                      r"\((\d+) needed\); relief found ([0-9.]+) m .*needed about ([0-9.]+) m",
                      msg)
        assert m, msg
        qualified, judged, needed = int(m[1]), int(m[2]), int(m[3])
        found_m, needed_m = float(m[4]), float(m[5])
        # the figures say why: fewer windows qualify than are needed, less relief than needed
        assert qualified < needed <= judged and found_m < needed_m, msg
    else:
        m = re.search(r"only (\d+) surface-matching windows gave a GCP \((\d+) needed\).*"
                      r"too flat for its noise \(median relief ([0-9.]+) m per window\)", msg)
        assert m and int(m[1]) < int(m[2]), msg
        found_m = float(m[3])
    assert 5.0 < found_m < 25.0, msg  # about their plane, spikes and blunders left out
    assert not (out / "report.json").exists() and not (out / "left.json").exists()


def test_relief_verdict_scales_the_needed_relief():
    cfg = SurfaceMatchConfig(max_precision_m=5.0)
    windows = [WindowMatch(WindowStatus.LOW_RELIEF, relief_m=4.0, predicted_precision_m=20.0,
                           n_cells=900, masked_share=0.0) for _ in range(9)]
    windows += [WindowMatch(WindowStatus.TOO_FEW_CELLS, relief_m=50.0, n_cells=3)]
    v = relief_sufficiency(windows, cfg, 3)
    assert not v.enough and v.n_qualified == 0 and v.n_windows == 10
    assert v.relief_found_m == pytest.approx(4.0)  # windows without cells do not count
    assert v.relief_needed_m == pytest.approx(16.0)  # 4 m x 20 m / 5 m
    good = [replace(w, predicted_precision_m=2.0, status=WindowStatus.OK) for w in windows[:9]]
    assert relief_sufficiency(good, cfg, 3).enough


def test_checkpoint_csv_and_bad_files(tmp_path):
    csv = tmp_path / "cp.csv"
    csv.write_text("id,lon_deg,lat_deg,h_m,left_col,left_row,right_col,right_row\n"
                   "7,5.2,44.1,812.5,10.5,20.25,11,21\n")
    s = read_checkpoints(csv)
    assert s.points[0].id == 7 and s.points[0].image_points["right"].row == 21.0
    csv.write_text("id,lon,lat\n1,2,3\n")
    with pytest.raises(InputError, match="must have the columns"):
        read_checkpoints(csv)
    csv.write_text("id,lon_deg,lat_deg,h_m,left_col,left_row,right_col,right_row\n"
                   "1,5.2,x,3,4,5,6,7\n")
    with pytest.raises(InputError, match="line 2"):
        read_checkpoints(csv)
    with pytest.raises(InputError, match="does not exist"):
        read_checkpoints(tmp_path / "missing.json")


def test_cli_refuses_bad_input_before_running(tiny_scene, tmp_path):
    scene, _ = tiny_scene
    args = parse("--left", str(scene / "left.tif"), "--right", str(scene / "right.tif"),
                 "--out", str(tmp_path / "o"))
    with pytest.raises(InputError, match="needs a reference DEM"):
        orient_command.run(args)
    args = parse("--left", str(scene / "left.tif"), "--right", str(scene / "right.tif"),
                 "--reference", str(scene / "reference.tif"), "--checkpoints",
                 str(tmp_path / "nope.csv"), "--out", str(tmp_path / "o"))
    with pytest.raises(InputError, match="check point file"):
        orient_command.run(args)
    assert not (tmp_path / "o").exists()


def test_final_dsm_is_the_relative_one_put_in_place(oriented):
    """The matches intersected again with the oriented models: the relative DEM sits where
    the metadata put it (100-300 m off: tens of metres of height error on slopes), the final
    DSM on the truth; the EGM96 twin is the same surface minus the geoid. Its median sits a
    few metres low: the simple reference is bare earth, the DSM it is matched to has 10-25 m
    of canopy, so the surface matching lowers the orientation by the canopy's mean share
    (measured on this scene's check points, bare soil: -7.1 m before the tie points were in
    the adjustment, -7.9 m after; the DSM's median -6.0 m): a limit of the reference, not of
    the chain, within a fifth of the 40 m pixel."""
    import rasterio

    from tasks.io.geoid import load_geoid

    scene, out, _outcome = oriented
    truth = scene / "truth" / "dsm.tif"
    _rel_med, rel_nmad, _ = dsm_against_truth(out / "relative_dem.tif", truth)
    fin_med, fin_nmad, _ = dsm_against_truth(out / "dsm.tif", truth)
    assert abs(fin_med) < 8.0 and fin_nmad < 0.6 * rel_nmad and fin_nmad < 40.0  # 1 GSD
    with rasterio.open(out / "dsm.tif") as a, rasterio.open(out / "dsm_egm96.tif") as b:
        assert "ellipsoid" in a.tags()["vertical_datum"].lower()
        assert "egm96" in b.tags()["vertical_datum"].lower()
        za, zb, t, epsg = a.read(1), b.read(1), a.transform, a.crs.to_epsg()
    from tasks.io.crs import Projection

    rows, cols = np.nonzero(np.isfinite(za) & np.isfinite(zb))
    pick = slice(None, None, max(1, rows.size // 500))
    lon, lat = Projection(epsg).to_lonlat(t.c + (cols[pick] + 0.5) * t.a,
                                          t.f + (rows[pick] + 0.5) * t.e)
    n = load_geoid().undulation_m(lon, lat)
    assert np.allclose(za[rows[pick], cols[pick]] - zb[rows[pick], cols[pick]], n, atol=0.05)
    assert not any(p.name.endswith(".work") for p in out.iterdir())
