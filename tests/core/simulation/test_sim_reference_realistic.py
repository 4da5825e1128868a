"""The realistic SRTM-like reference: partial canopy per stand, noise growing with slope, radar
shadow and layover voids, a tilt; each measured back from the heights."""

from __future__ import annotations

import numpy as np
import pytest

from core.errors import InputError
from core.simulation.reference import (
    ReferenceErrors,
    canopy_fraction_seen,
    radar_voids,
    seen_surface,
    srtm_like,
)

QUIET = dict(noise_m=0.0, void_share=0.0)  # only the error under test


def _grid(n: int = 120, step: float = 30.0):
    x, y = np.meshgrid(500_000.0 + step * np.arange(n), 4_900_000.0 - step * np.arange(n))
    return x, y


def test_measured_penetration_over_forest_is_the_drawn_fraction():
    """Canopy 20 m over the forest: the reference sees dtm + f * 20 m with f drawn per stand in
    30-70 %, one f per stand; bare ground is untouched."""
    err = ReferenceErrors(canopy_seen=(0.3, 0.7), stand_m=400.0, **QUIET)
    x, y = _grid()
    dtm = 300.0 + 0.002 * (y - y.min())
    forest = (x - x.min()) > 900.0
    dsm = np.where(forest, dtm + 20.0, dtm)
    seen = seen_surface(dtm, dsm, x, y, 7, err)
    h = srtm_like(seen, x, y, np.zeros_like(x), 7, err)
    measured = (h - dtm)[forest] / 20.0
    drawn = canopy_fraction_seen(x, y, 7, err)[forest]
    assert np.allclose(measured, drawn, atol=1e-9)
    assert np.allclose(h[~forest], dtm[~forest])
    stand = (np.floor(x / 400.0) * 1e4 + np.floor(y / 400.0))[forest]
    per_stand = {s: np.ptp(measured[stand == s]) for s in np.unique(stand)}
    assert max(per_stand.values()) < 1e-9  # one fraction per stand
    means = np.array([measured[stand == s].mean() for s in np.unique(stand)])
    assert 0.3 <= means.min() < 0.4 and 0.6 < means.max() <= 0.7  # the range is used
    # today's reference (simple errors) sees no canopy at all
    assert np.array_equal(seen_surface(dtm, dsm, x, y, 7, ReferenceErrors()), dtm)


def test_noise_grows_with_slope():
    err = ReferenceErrors(slope_noise_m=10.0, **QUIET)
    x, y = _grid(60)
    t = np.full_like(x, 500.0)
    d = {s: srtm_like(t, x, y, np.full_like(x, s), 3, err) - t for s in (0.0, 15.0, 30.0)}
    assert np.all(d[0.0] == 0.0)
    ratio = d[30.0] / np.where(d[15.0] == 0, np.nan, d[15.0])
    expect = np.tan(np.radians(30.0)) / np.tan(np.radians(15.0))
    assert np.nanmax(np.abs(ratio - expect)) < 1e-9
    assert 2.0 < np.std(d[30.0]) < 12.0  # metres on 30 degree slopes, beyond the 4.5 m base


def test_tilt_is_a_plane_about_its_origin():
    err = ReferenceErrors(tilt_east_m_per_km=0.05, tilt_north_m_per_km=-0.02,
                          tilt_origin_m=(501_000.0, 4_899_000.0), **QUIET)
    x, y = _grid()
    t = np.full_like(x, 200.0)
    d = srtm_like(t, x, y, np.zeros_like(x), 1, err) - t
    assert np.allclose(d, 0.05e-3 * (x - 501_000.0) - 0.02e-3 * (y - 4_899_000.0), atol=1e-9)


@pytest.mark.parametrize(("rise_deg", "void"), [(40.0, True), (30.0, False),
                                                (-60.0, True), (-50.0, False)])
def test_radar_voids_fall_on_layover_and_shadow(rise_deg, void):
    """Looking east at 35 degrees incidence: a slope rising towards the east (facing the radar)
    steeper than 35 degrees is layover, one falling steeper than 55 degrees is shadow."""
    err = ReferenceErrors(radar_incidence_deg=35.0, radar_look_azimuth_deg=90.0)
    x, _ = _grid(20)
    h = np.tan(np.radians(rise_deg)) * (x - x.min())
    mask = radar_voids(h, 30.0, 30.0, err)
    assert mask.all() == void and mask.any() == void
    # looking west, the same slopes swap roles
    west = radar_voids(h, 30.0, 30.0, ReferenceErrors(radar_incidence_deg=35.0,
                                                        radar_look_azimuth_deg=270.0))
    assert west.all() == (rise_deg < -35.0)  # -50, -60: layover seen from the east
    assert not radar_voids(h, 30.0, 30.0, ReferenceErrors()).any()  # simple: none


def test_realistic_draws_stay_in_their_ranges():
    for seed in range(40):
        e = ReferenceErrors.drawn_realistic(seed, (0.0, 0.0), 30_000.0)
        assert np.hypot(e.shift_east_m, e.shift_north_m) <= 10.0
        assert np.hypot(e.tilt_east_m_per_km, e.tilt_north_m_per_km) * 30.0 <= 2.0
        assert 30.0 <= e.radar_incidence_deg <= 58.0 and e.canopy_seen == (0.3, 0.7)
        assert e == ReferenceErrors.drawn_realistic(seed, (0.0, 0.0), 30_000.0)
    shifts = [np.hypot(e.shift_east_m, e.shift_north_m) for e in
              (ReferenceErrors.drawn_realistic(s, (0.0, 0.0), 3e4) for s in range(40))]
    assert max(shifts) > 7.0  # the range up to 10 m is used
    with pytest.raises(InputError):
        ReferenceErrors(canopy_seen=(0.7, 0.3))
