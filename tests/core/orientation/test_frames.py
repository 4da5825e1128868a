"""The control's frames as unknowns of the one estimator (:mod:`core.orientation.frames`,
:func:`core.orientation.adjust.adjust`) on the synthetic pushbroom pair with known truth: one
frame's registration carried into the prediction as the reference term always was, a precise
second frame measuring the reference's misregistration, the better-known frame winning, and a
frame of weak surface-matching windows not trusted beyond their own precision."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from core.orientation.absolute import AbsoluteConfig
from core.orientation.adjust import AdjustConfig, ControlSet, ImageToAdjust, adjust
from core.orientation.frames import REFERENCE, FrameLayout, FramePrior, shifted_ground
from core.orientation.uncertainty import ground_jacobian, predicted_rms_px
from core.points import CheckPoint, CheckPointSet, ControlPoint, ImagePoint
from tests.core.orientation.test_absolute import measured

NAMES = ("left", "right")


def _points(truth, n, seed, shift_m=(0.0, 0.0, 0.0), sxy=2.0, sh=2.0, images=NAMES,
            first_id=1, source="srtm", field=None):
    """GCPs of ``n`` true ground points measured (0.2 px) in ``images`` of ``truth``, their
    ground moved by ``shift_m`` (east, north, up: the source shows the world moved by it),
    ``field(east_m, north_m) -> (n, 3)`` more, and noise of ``sxy``/``sh``."""
    rng = np.random.default_rng(seed)
    lon, lat, h, cols, rows = measured(truth, n, rng)
    move = np.broadcast_to(np.asarray(shift_m, dtype=float), (n, 3)).copy()
    if field is not None:
        move += field(lon, lat)
    move += rng.normal(0.0, 1.0, (n, 3)) * [sxy, sxy, sh]
    glon, glat, gh = shifted_ground(lon, lat, h, move)
    out = []
    for i in range(n):
        ip = {name: ImagePoint(float(cols[k][i]), float(rows[k][i]))
              for k, name in enumerate(NAMES) if name in images}
        out.append(ControlPoint(first_id + i, float(glon[i]), float(glat[i]), float(gh[i]), ip,
                                sxy, sh, source))
    return tuple(out)


def _check_points(truth, n=200, seed=5):
    rng = np.random.default_rng(seed)
    lon, lat, h, cols, rows = measured(truth, n, rng, noise_px=0.0)
    return CheckPointSet("EPSG:4326", NAMES, tuple(
        CheckPoint(i, float(lon[i]), float(lat[i]), float(h[i]), float("nan"), float("nan"),
                   float("nan"), "", {name: ImagePoint(float(cols[k][i]), float(rows[k][i]))
                                      for k, name in enumerate(NAMES)})
        for i in range(n)))


def _images(delivered):
    return [ImageToAdjust(n, m, (m.n_cols, m.n_rows)) for n, m in zip(NAMES, delivered,
                                                                         strict=True)]


def _worst(stats) -> float:
    return max(max(s.rms_col_px, s.rms_row_px) for s in stats.values())


def test_frame_layout_shares_the_vertical_and_fixes_exact_components():
    layout = FrameLayout.of((FramePrior(REFERENCE, (5.0, 5.0, 4.0)),
                             FramePrior("sar", (10.0, 0.0, 7.0), up_of=REFERENCE)))
    # reference east, north, up; sar east (its north known exactly, its up the reference's)
    assert layout.index.tolist() == [[0, 1, 2], [3, -1, 2]]
    assert layout.sigma_m.tolist() == [5.0, 5.0, 4.0, 10.0]
    assert layout.shifts_m([1.0, 2.0, 3.0, 4.0]).tolist() == [[1, 2, 3], [4, 0, 3]]


def test_one_frame_carries_the_references_registration_into_the_prediction(pair):
    """Alone, the reference's frame and the images' biases trade exactly: its prior decides it
    and what it puts into the prediction is the registration carried through the ground's
    partial derivatives at the check points, ``G S G'`` (computed here independently of the
    adjustment's covariance), and the relative part is what a reference known exactly gives."""
    delivered, truth = pair
    sigma = (4.0, 6.0, 3.0)
    gcps = _points(truth, 60, seed=2)
    cps = _check_points(truth)
    free = adjust(_images(delivered), [ControlSet("surface", gcps, FramePrior(REFERENCE,
                                                                              sigma))])
    exact = adjust(_images(delivered), [ControlSet("surface", gcps, FramePrior(
        REFERENCE, (0.0, 0.0, 0.0)))])
    got, known = free.check_points(cps), exact.check_points(cps)
    for k, name in enumerate(NAMES):
        lon = np.array([p.lon_deg for p in cps.points])
        lat = np.array([p.lat_deg for p in cps.points])
        h = np.array([p.h_m for p in cps.points])
        g = ground_jacobian(free.models[k], lon, lat, h)
        ref_c, ref_r = predicted_rms_px(g, np.diag(np.square(sigma)))
        assert got[name].predicted_reference_rms_col_px == pytest.approx(ref_c, rel=0.05)
        assert got[name].predicted_reference_rms_row_px == pytest.approx(ref_r, rel=0.05)
        # the relative part: as if the frame were known (it is its conditional covariance)
        assert got[name].predicted_relative_rms_col_px == pytest.approx(
            known[name].predicted_rms_col_px, rel=0.02)
        assert got[name].predicted_relative_rms_row_px == pytest.approx(
            known[name].predicted_rms_row_px, rel=0.02)
        # and the models the same: a frame alone moves nothing the biases cannot follow
        assert got[name].rms_col_px == pytest.approx(known[name].rms_col_px, abs=0.01)
    assert not free.frame(REFERENCE).observed


def test_a_precise_second_frame_measures_the_references_misregistration(pair):
    """A reference shifted by (12, -9, 0) m (beyond its stated 5 m, as a real SRTM can be) and
    a precise SAR-like source (3 m, measured in one image per point, its vertical the
    reference's): the reference's shift is estimated within 2 sigma of the truth, its sigma
    under 5 m, and removed from the orientation (the check points as good as with the precise
    source alone)."""
    delivered, truth = pair
    srtm = _points(truth, 60, seed=3, shift_m=(12.0, -9.0, 0.0))
    sar = (_points(truth, 80, seed=4, sxy=3.0, images=("left",), first_id=100, source="sar")
           + _points(truth, 80, seed=5, sxy=3.0, images=("right",), first_id=200,
                     source="sar"))
    cps = _check_points(truth)
    both = adjust(_images(delivered), [
        ControlSet("surface", srtm, FramePrior(REFERENCE, (5.0, 5.0, 5.0))),
        ControlSet("sar", sar, FramePrior("sar", (3.0, 3.0, 5.0), up_of=REFERENCE))])
    ref = both.frame(REFERENCE)
    assert ref.observed and max(ref.sigma_m[:2]) < 5.0
    # X_true = X_gcp + s: the reference's GCPs moved by (12, -9) come back by (-12, 9)
    for got, want, s in zip(ref.shift_m[:2], (-12.0, 9.0), ref.sigma_m[:2], strict=True):
        assert abs(got - want) < 2.0 * s, (ref, want)
    srtm_only = adjust(_images(delivered), [ControlSet("surface", srtm, FramePrior(
        REFERENCE, (5.0, 5.0, 5.0)))]).check_points(cps)
    fused = both.check_points(cps)
    assert _worst(fused) < 0.6 * _worst(srtm_only)
    for s in fused.values():  # the prediction holds what stays unknown of the frames
        assert max(s.rms_col_px / s.predicted_rms_col_px,
                   s.rms_row_px / s.predicted_rms_row_px) <= 1.5


def test_the_better_known_frame_wins(pair):
    """A good reference (5 m, exact here) and a SAR source off by 40 m that says so (50 m):
    the fused orientation stays within a tenth of a pixel of the reference alone's."""
    delivered, truth = pair
    srtm = _points(truth, 60, seed=6)
    sar = _points(truth, 120, seed=7, shift_m=(40.0, 25.0, 0.0), sxy=3.0, first_id=100,
                  source="sar")
    cps = _check_points(truth)
    alone = adjust(_images(delivered), [ControlSet("surface", srtm, FramePrior(
        REFERENCE, (5.0, 5.0, 5.0)))]).check_points(cps)
    fused = adjust(_images(delivered), [
        ControlSet("surface", srtm, FramePrior(REFERENCE, (5.0, 5.0, 5.0))),
        ControlSet("sar", sar, FramePrior("sar", (50.0, 50.0, 5.0), up_of=REFERENCE))
    ]).check_points(cps)
    for name in NAMES:
        assert fused[name].rms_col_px < alone[name].rms_col_px + 0.1
        assert fused[name].rms_row_px < alone[name].rms_row_px + 0.1


def test_weak_windows_do_not_pull_a_precise_frame(pair):
    """Eight weak windows (20 m each) off by 30 m east in common and +-30 m more across the
    swath (a low-relief scene's surface-matching GCPs: they share the relative DEM's
    deformation), with a precise source beside them: their frame's prior takes their
    precision (overlapping windows share their errors), so the precise frame wins, and the
    prediction is not beaten by more than 1.5."""
    delivered, truth = pair
    lon0 = np.mean([p.lon_deg for p in _points(truth, 8, seed=8)])

    def bend(lon, lat):
        x = (lon - lon0) * 79_870.0 / 15_000.0  # about -1..1 across the swath
        return np.stack([30.0 * (2.0 * x**2 - 0.6), np.zeros_like(x), np.zeros_like(x)], 1)

    srtm = _points(truth, 8, seed=8, shift_m=(30.0, 0.0, 0.0), sxy=20.0, sh=10.0, field=bend)
    sar = _points(truth, 200, seed=9, sxy=10.0, first_id=100, source="sar")
    cps = _check_points(truth)
    alone = adjust(_images(delivered), [ControlSet("sar", sar, FramePrior(
        "sar", (10.0, 10.0, 5.0)))]).check_points(cps)
    fused = adjust(_images(delivered), [
        ControlSet("surface", srtm, FramePrior(REFERENCE, (5.0, 5.0, 5.0))),
        ControlSet("sar", sar, FramePrior("sar", (10.0, 10.0, 5.0), up_of=REFERENCE))])
    got = fused.check_points(cps)
    widened = fused.frames_used[0]
    assert widened.sigma_m[0] > 15.0, widened  # its windows' precision
    for name in NAMES:
        s = got[name]
        # no worse than the better source alone by more than that source's stated sigma
        assert s.rms_col_px <= alone[name].rms_col_px + alone[name].predicted_rms_col_px
        assert s.rms_col_px / s.predicted_rms_col_px <= 1.5
        assert s.rms_row_px / s.predicted_rms_row_px <= 1.5


def test_without_its_scatter_the_weak_frame_would_pull(pair):
    """The same case with the frames' priors as stated alone (``frames_from_scatter`` off):
    the weak windows' common error pulls the precise frame and the check points (what the
    widening above prevents: this test fails if the widening does nothing)."""
    delivered, truth = pair
    lon0 = np.mean([p.lon_deg for p in _points(truth, 8, seed=8)])

    def bend(lon, lat):
        x = (lon - lon0) * 79_870.0 / 15_000.0
        return np.stack([30.0 * (2.0 * x**2 - 0.6), np.zeros_like(x), np.zeros_like(x)], 1)

    srtm = _points(truth, 8, seed=8, shift_m=(30.0, 0.0, 0.0), sxy=20.0, sh=10.0, field=bend)
    sar = _points(truth, 200, seed=9, sxy=10.0, first_id=100, source="sar")
    cps = _check_points(truth)
    sets = [ControlSet("surface", srtm, FramePrior(REFERENCE, (5.0, 5.0, 5.0))),
            ControlSet("sar", sar, FramePrior("sar", (10.0, 10.0, 5.0), up_of=REFERENCE))]
    widened = adjust(_images(delivered), sets).check_points(cps)
    stated = adjust(_images(delivered), sets,
                    config=AdjustConfig(frames_from_scatter=False)).check_points(cps)
    assert _worst(stated) > _worst(widened) + 0.2


def test_a_gcp_measured_in_an_image_not_adjusted_is_refused(pair):
    from core.errors import InputError

    delivered, truth = pair
    gcps = _points(truth, 10, seed=1)
    with pytest.raises(InputError, match="not adjusted"):
        adjust(_images(delivered)[:1], [ControlSet("surface", gcps, FramePrior(
            REFERENCE, (5.0, 5.0, 5.0)))], config=AdjustConfig(absolute=AbsoluteConfig()))


def test_each_frames_gcps_get_their_own_variance_components(pair):
    """60 windows that state their 2 m truly, and 200 SAR points that state 3 m but scatter by
    15 m (a SAR product's speckle and layover beyond its stated precision): calibrated apart,
    the SAR's factor is found far above the windows' (its true scatter over its stated, with
    the 0.2 px of matching beside), so the SAR points weigh as they deserve and the check
    points are no worse than with one factor for both, which lets the 200 SAR points pull."""
    delivered, truth = pair
    srtm = _points(truth, 60, seed=10)
    sar = _points(truth, 200, seed=11, sxy=15.0, sh=15.0, first_id=100, source="sar")
    sar = tuple(replace(p, sigma_xy_m=3.0, sigma_h_m=3.0) for p in sar)  # understated
    sets = [ControlSet("surface", srtm, FramePrior(REFERENCE, (5.0, 5.0, 5.0))),
            ControlSet("sar", sar, FramePrior("sar", (10.0, 10.0, 5.0), up_of=REFERENCE))]
    cps = _check_points(truth)
    apart = adjust(_images(delivered), sets, config=AdjustConfig(
        absolute=AbsoluteConfig(components_by_frame=True)))
    shared = adjust(_images(delivered), sets)  # the default: one set for every frame
    comps = apart.adjustment.components
    assert comps is not None
    names = comps.names
    assert any(n.endswith(":sar") for n in names) and any(n.endswith(":reference")
                                                           for n in names), names
    sar_factor = max(comps.factors[i] for i, n in enumerate(names) if n.endswith(":sar"))
    ref_factor = max(comps.factors[i] for i, n in enumerate(names) if n.endswith(":reference"))
    assert sar_factor > 5.0 * ref_factor, comps.to_dict()
    assert not any(":" in n for n in shared.adjustment.components.names)
    got, one = apart.check_points(cps), shared.check_points(cps)
    assert _worst(got) < _worst(one), (got, one)  # 0.10 against 0.16 px here
    for name in NAMES:
        assert got[name].rms_col_px / got[name].predicted_rms_col_px <= 1.5
        assert got[name].rms_row_px / got[name].predicted_rms_row_px <= 1.5
