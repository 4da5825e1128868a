"""``gcpfree orient --sar``: SAR-optical GCPs (Goncalves 2002) orient a pair SRTM surface
matching refuses (a nearly flat tiny scene, relief x 0.05), measured on its check points."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from core.errors import InputError, InsufficientDataError, InsufficientReliefError

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def flat_sar_scene(tmp_path_factory):
    """The tiny preset with its relief scaled by 0.05 (seed 3, no lens, no jitter, no lidar)
    and an ERS-like SAR product of the same world."""
    from tasks.simulate.sar import simulate_sar
    from tests.scenes import run_scene

    out = tmp_path_factory.mktemp("flat_sar")
    scene = run_scene(out, seed=3, lidar=False, lens=False, jitter=False, relief_factor=0.05)
    simulate_sar.fn(scene, out, "ers")
    return out


def _params(scene, out, **kw):
    from flows.orient import OrientParams
    from tasks.io.pair import PairInputs

    return OrientParams(pair=PairInputs(scene / "left.tif", scene / "right.tif",
                                        reference=scene / "reference.tif"), out=out,
                        checkpoints=scene / "truth" / "checkpoints.json", progress=False, **kw)


@pytest.fixture(scope="module")
def flat_oriented(flat_sar_scene, tmp_path_factory, prefect_harness):
    from flows.orient import orient_flow

    out = tmp_path_factory.mktemp("orient_sar")
    return out, orient_flow(_params(flat_sar_scene, out, sar=flat_sar_scene / "sar.tif"))


@pytest.fixture(scope="module")
def independent_flat(flat_sar_scene, tmp_path_factory):
    """The flat scene against a reference made from its truth without the simulator's
    reference code (tests.scenes.independent_reference: half the canopy seen, 8 m shift,
    4 m of noise correlated over 600 m, +1.5 m), issue 45's case."""
    from tests.scenes import independent_reference

    dest = tmp_path_factory.mktemp("independent_ref") / "reference.tif"
    independent_reference(flat_sar_scene, dest, shift_m=(0.0, 8.0), seed=45)
    return dest


def _against(scene, reference, out, **kw):
    from flows.orient import OrientParams
    from tasks.io.pair import PairInputs

    return OrientParams(pair=PairInputs(scene / "left.tif", scene / "right.tif",
                                        reference=reference), out=out,
                        checkpoints=scene / "truth" / "checkpoints.json", progress=False, **kw)


@pytest.fixture(scope="module")
def fusion(flat_sar_scene, independent_flat, tmp_path_factory, prefect_harness):
    """The flat pair oriented on the SAR GCPs alone (SRTM refused: 100000 windows asked) and on
    SAR and SRTM together (4 windows enough), against the independent reference."""
    from flows.orient import orient_flow

    sar = flat_sar_scene / "sar.tif"
    alone = orient_flow(_against(flat_sar_scene, independent_flat,
                                 tmp_path_factory.mktemp("sar_alone"), sar=sar,
                                 min_windows=100000))
    out = tmp_path_factory.mktemp("fused")
    fused = orient_flow(_against(flat_sar_scene, independent_flat, out, sar=sar,
                                 min_windows=4))
    return alone, fused, out


def test_sar_fused_with_weak_srtm_windows_is_no_worse_than_sar_alone(fusion):
    """Issue 45's first case: over a flat world a handful of weak SRTM windows share an error
    of tens of metres; fused with the SAR GCPs in one adjustment, each source in its own
    frame, the SAR frame wins: the check points are no worse than the SAR alone's by more
    than that orientation's stated sigma, under 0.7 px of 40 m, and the prediction is not
    beaten by more than 1.5 on any axis (before: 0.80 px measured, 0.14 predicted)."""
    alone, fused, out = fusion
    report = json.loads((out / "report.json").read_text())
    assert report["sar"]["role"] == "with SRTM" and report["gcps"]["given"] > 100
    assert {f["name"] for f in report["absolute"]["frames"]} == {"reference", "sar"}
    a, f = alone.report.check_points, fused.report.check_points
    for name in ("left", "right"):
        for ax in ("col", "row"):
            got = getattr(f[name], f"rms_{ax}_px")
            assert got <= (getattr(a[name], f"rms_{ax}_px")
                           + getattr(a[name], f"predicted_rms_{ax}_px")), (name, ax)
            assert got <= 0.7, (name, ax, got)
            assert got / getattr(f[name], f"predicted_rms_{ax}_px") <= 1.5, (name, ax)


def test_without_the_sar_scene_the_flat_pair_is_refused(flat_sar_scene, tmp_path,
                                                        prefect_harness):
    from flows.orient import orient_flow

    with pytest.raises((InsufficientReliefError, InsufficientDataError)):
        orient_flow(_params(flat_sar_scene, tmp_path / "o"))


def test_sar_gcps_orient_the_flat_pair(flat_sar_scene, flat_oriented):
    out, outcome = flat_oriented
    report = json.loads((out / "report.json").read_text())
    sar = report["sar"]
    assert sar["role"].startswith("alone") and sar["mission"].startswith("ERS")
    gcps = json.loads((out / "gcps.json").read_text())["points"]
    assert gcps and all(p["source"] == "sar" for p in gcps)
    assert {n for p in gcps for n in p["images"]} == {"left", "right"}
    points = json.loads((out / "sar_points.json").read_text())
    assert points["format"] == "gcpfree.sar_points"
    assert all(points["images"][n]["gcps"] >= 50 for n in ("left", "right"))
    # the truth: what the delivered SAR annotation is off by, in optical pixels (40 m)
    truth = json.loads((flat_sar_scene / "truth" / "sar.json").read_text())
    sar_px = truth["centre_error_m"] / 40.0
    before, after = outcome.report.check_points_before, outcome.report.check_points
    for name in ("left", "right"):
        # the delivered metadata were off by several pixels; the SAR scene's error passes
        # whole (0.4 px here); along track the matching is unbiased
        assert after[name].rms_row_px <= 0.5 + sar_px
        assert after[name].rms_row_px < 0.3 * before[name].rms_row_px
        # across track (the radar's range): matched against the SAR image predicted from
        # the pair's relative DEM, the forest edges no longer pull the matches towards the
        # radar (core.orientation.sar_prediction): measured 0.41 and 0.63 px here, where
        # matching on the reference's heights gave 1.9-2.1 px
        assert after[name].rms_col_px <= 0.5 + sar_px
        assert after[name].rms_col_px < 0.7 * before[name].rms_col_px
        # and the prediction says so: the SAR scene's error and one radar pixel along range
        # are what an orientation on SAR alone cannot see
        ratio = after[name].predicted_rms_col_px / after[name].rms_col_px
        assert 0.7 <= ratio <= 1.5, ratio


def test_residuals_of_the_sar_gcps_are_in_the_report(flat_oriented):
    _, outcome = flat_oriented
    images = outcome.report.sar["images"]
    for name in ("left", "right"):
        assert 0 < images[name]["residual_rms_col_px"] < 1.0
        assert np.isfinite(images[name]["residual_mean_row_px"])
    assert any(line.startswith("GCPs from SAR left") for line in outcome.lines())


def test_an_optical_image_given_as_sar_is_refused(flat_sar_scene, tmp_path, prefect_harness):
    from flows.orient import orient_flow

    with pytest.raises(InputError, match="not a SAR"):
        orient_flow(_params(flat_sar_scene, tmp_path / "o", sar=flat_sar_scene / "left.tif"))
    assert not (tmp_path / "o").exists()


def test_a_sar_scene_elsewhere_is_refused(flat_sar_scene, tmp_path, prefect_harness):
    from core.sensors.sar import SarModel
    from flows.orient import orient_flow

    far = tmp_path / "far"
    far.mkdir()
    shutil.copy(flat_sar_scene / "sar.tif", far / "sar.tif")
    model = SarModel.from_json((flat_sar_scene / "sar.json").read_text())
    # a range delay of 0.15 ms: the same image 22 km further in slant range, off the pair
    (far / "sar.json").write_text(model.with_params([0.0, 1.5e-4]).to_json())
    with pytest.raises(InputError, match="does not overlap"):
        orient_flow(_params(flat_sar_scene, tmp_path / "o", sar=far / "sar.tif"))
    assert not (tmp_path / "o").exists()  # refused before anything was written


@pytest.fixture(scope="module")
def relief_sar(tiny_scene, tmp_path_factory):
    """The tiny scene (relief: good SRTM windows) with an ERS-like SAR product whose delivered
    timing is off by 4.5 ms in azimuth and 0.1 microsecond in range (tens of metres on the
    ground, a product with predicted orbits would be so far off), stated as 40 m: a copy of
    the session's scene (links), the SAR rendered into it, its model moved. (scene dir, the
    ground displacement of the SAR's points the error makes: east, north, m)."""
    from core.geodesy import metres_per_degree
    from core.sensors.sar import SarModel
    from tasks.simulate.sar import simulate_sar

    src, scene = tiny_scene
    out = tmp_path_factory.mktemp("relief_sar")
    for path in src.rglob("*"):
        if path.is_file() and "work" not in path.relative_to(src).parts:
            dest = out / path.relative_to(src)
            dest.parent.mkdir(parents=True, exist_ok=True)
            dest.symlink_to(path.resolve())
    simulate_sar.fn(scene, out, "ers")
    good = SarModel.from_json((out / "sar.json").read_text())
    bad = good.with_params(good.params + [4.5e-3, 1.0e-7])
    (out / "sar_bad.json").write_text(bad.to_json())
    c, r = good.n_cols / 2.0, good.n_rows / 2.0
    h = np.array([scene.centre.h_m])
    lon0, lat0 = good.localize(np.array([c]), np.array([r]), h)
    lon1, lat1 = bad.localize(np.array([c]), np.array([r]), h)
    m_lon, m_lat = metres_per_degree(float(lat0[0]))
    return out, (float((lon1 - lon0)[0] * m_lon), float((lat1 - lat0)[0] * m_lat))


def test_a_good_srtm_frame_wins_over_a_misplaced_sar_and_measures_it(relief_sar, tiny_oriented,
                                                                      tmp_path,
                                                                      prefect_harness):
    """The opposite case: good SRTM windows (relief), a SAR product off by tens of metres that
    says so (--sar-sigma 40): the SRTM frame wins (the reference frame's shift within its
    sigma of none), the check points no worse than SRTM's alone by more than that
    orientation's stated sigma and never beyond 1.5 x their own prediction (issue 45's
    acceptance), and the SAR's misregistration is measured (its frame's shift, against the
    displacement its timing error makes on the ground, within 3 of its sigmas). Measured:
    0.69 / 0.32 and 0.60 / 0.21 px for SRTM alone's 0.37 / 0.32 and 0.28 / 0.17 (stated
    0.72 / 0.43 and 0.75 / 0.40): the SAR's 347 points, in one variance component with the
    39 windows, still bend the shape the windows alone give."""
    from flows.orient import orient_flow

    scene, (de, dn) = relief_sar
    assert np.hypot(de, dn) > 25.0  # the error: more than half a 40 m pixel
    out = tmp_path / "fused"
    fused = orient_flow(_params(scene, out, sar=scene / "sar.tif",
                                sar_model=scene / "sar_bad.json", sar_sigma_m=40.0,
                                self_calibrate=True))
    _, _, alone = tiny_oriented
    for name in ("left", "right"):
        f, a = fused.report.check_points[name], alone.report.check_points[name]
        for ax in ("col", "row"):
            got = getattr(f, f"rms_{ax}_px")
            assert got <= (getattr(a, f"rms_{ax}_px") + getattr(a, f"predicted_rms_{ax}_px"))
            assert got <= 1.5 * getattr(f, f"predicted_rms_{ax}_px"), (name, ax)
    frames = json.loads((out / "report.json").read_text())["absolute"]["frames"]
    reference = next(f for f in frames if f["name"] == "reference")
    assert all(abs(v) <= s for v, s in zip(reference["shift_m"][:2], reference["sigma_m"][:2],
                                           strict=True)), reference
    frame = next(f for f in frames if f["name"] == "sar")
    assert frame["observed"] and frame["prior_sigma_m"][0] >= 40.0
    # X_true = X_gcp + shift: the SAR's points sit moved by (de, dn), the shift brings them back
    for got, want, s in zip(frame["shift_m"][:2], (-de, -dn), frame["sigma_m"][:2],
                            strict=True):
        assert abs(got - want) <= 3.0 * s + 2.0, (frame, want)
