"""The block simulator's geometry, without rendering: passes cut into consecutive scenes that
share their orbit and attitude, adjacent passes and dates overlapping as stated, stereo between
dates, errors drawn per pass, and the flattening of one scene's ground."""

from __future__ import annotations

import numpy as np
import pytest

from core.errors import InputError
from core.points import GeoPoint
from core.sensors.viewing import pair_geometry
from core.simulation.block import (
    BlockLayout,
    block_models,
    flatten_region,
    image_name,
    parse_image_name,
)
from core.simulation.scene import PRESETS, ErrorConfig

TINY = PRESETS["tiny"]
SIZE = (TINY.n_cols, TINY.n_rows)
H_M = 600.0


@pytest.fixture(scope="module")
def block():
    """A tiny 2 x 2 block over 3 dates, realistic errors, lens and jitter, on flat ground."""
    lay = BlockLayout(2, 2, 3)
    errors = ErrorConfig(lens=True, jitter=True, realistic=True)
    passes, images = block_models(TINY, lay, GeoPoint(5.5, 44.5, H_M), errors, 5,
                                  lambda lon, lat: H_M)
    return lay, passes, {(im.row, im.col, im.date): im for im in images}


def test_layout_from_the_options_and_its_names():
    lay = BlockLayout.parse("3x2", 2)
    assert (lay.rows, lay.cols, lay.dates) == (3, 2, 2)
    assert len(lay.names()) == 12 and len(set(lay.names())) == 12
    assert lay.step_rows(600) == 540 and lay.pass_rows(600) == 1680
    assert parse_image_name(image_name(2, 1, 0)) == (2, 1, 0)
    for bad, msg in (("2by2", "RxC"), ("0x2", "1 <= R, C"), ("1x1", "two images")):
        with pytest.raises(InputError, match=msg):
            BlockLayout.parse(bad, 1)
    with pytest.raises(InputError, match="--dates must be"):
        BlockLayout.parse("2x2", 9)
    with pytest.raises(InputError, match="not a block image name"):
        parse_image_name("left")


def test_scenes_along_track_are_segments_of_one_pass(block):
    lay, _, by = block
    step = lay.step_rows(TINY.n_rows)
    for c in range(lay.cols):
        for d in range(lay.dates):
            a, b = by[(0, c, d)], by[(1, c, d)]
            assert a.pass_name == b.pass_name and b.first_line_in_pass == step
            ta, tb = a.models.truth, b.models.truth
            np.testing.assert_array_equal(ta.orbit.positions_m, tb.orbit.positions_m)
            # the same lines in both: the same instants, attitude and lines of sight
            t0 = ta.line_time_s(np.arange(step, TINY.n_rows))
            t1 = tb.line_time_s(np.arange(0, TINY.n_rows - step))
            np.testing.assert_allclose(t0, t1, rtol=0, atol=1e-9)
            np.testing.assert_allclose(ta.attitude_angles(t0), tb.attitude_angles(t1),
                                       rtol=0, atol=1e-15)
            assert ta.attitude.jitter and len(ta.attitude.jitter) > 8  # jitter + profile
            assert ta.attitude == tb.attitude  # one series: continuous at the boundary
            # each scene's own product: its metadata agree on the common lines to a few mm
            col = np.linspace(0.0, TINY.n_cols - 1, 9)
            rows = np.full(9, float(TINY.n_rows - 1))
            pa = np.array(a.models.delivered.localize(col, rows, np.full(9, H_M)))
            pb = np.array(b.models.delivered.localize(col, rows - step, np.full(9, H_M)))
            assert np.max(np.abs(pa - pb)) * 111e3 < 0.02 * TINY.gsd_m


def test_overlaps_and_stereo_as_stated(block):
    lay, _, by = block
    along = pair_geometry(by[(0, 0, 0)].models.truth, SIZE, by[(1, 0, 0)].models.truth, SIZE,
                          H_M)
    assert 8.0 < along.overlap_pct < 12.0
    for d in range(lay.dates):
        across = pair_geometry(by[(0, 0, d)].models.truth, SIZE, by[(0, 1, d)].models.truth,
                               SIZE, H_M)
        assert 8.0 < across.overlap_pct < 20.0, d  # 10 % of the narrowest date's swath
    stereo = pair_geometry(by[(1, 1, 0)].models.truth, SIZE, by[(1, 1, 1)].models.truth, SIZE,
                           H_M)
    assert stereo.overlap_pct > 85.0 and 0.8 < stereo.b_over_h < 0.9  # +25.5 / -20 deg
    third = pair_geometry(by[(1, 1, 0)].models.truth, SIZE, by[(1, 1, 2)].models.truth, SIZE,
                          H_M)
    assert 0.25 < third.b_over_h < 0.4  # +25.5 / +10 deg


def test_passes_are_their_own_orbits_and_draws(block):
    lay, passes, by = block
    assert len(passes) == lay.cols * lay.dates
    centres = {p.name: p.truth.orbit.positions_m for p in passes}
    assert len({c.tobytes() for c in centres.values()}) == len(passes)
    dates = {(p.col, p.date): p.view.date for p in passes}
    assert dates[(1, 0)] > dates[(0, 0)] and dates[(0, 1)] > dates[(1, 0)]
    # one pass, one draw: its scenes carry the same errors (their centre errors aside)
    a, b = by[(0, 1, 2)].models.injected, by[(1, 1, 2)].models.injected
    assert a.roll_bias_rad == b.roll_bias_rad and a.realistic == b.realistic
    assert a.distortion == b.distortion and a.jitter == b.jitter
    assert by[(0, 0, 2)].models.injected.roll_bias_rad != a.roll_bias_rad
    for im in by.values():
        assert 50.0 < im.models.injected.centre_error_m < 400.0


def test_flatten_region_keeps_a_percent_of_the_relief_inside_and_the_world_outside():
    lon0, lat0, d = 5.0, 44.0, 1.0 / 1200
    rows, cols = np.mgrid[0:240, 0:360]
    H = 500.0 + 3.0 * cols + 200.0 * np.sin(rows / 9.0) * np.cos(cols / 13.0)
    tr = (d, 0.0, lon0, 0.0, -d, lat0 + 240 * d)
    box = (np.array([5.08, 5.16, 5.16, 5.08]), np.array([44.17, 44.17, 44.11, 44.11]))
    flat, h_loc = flatten_region(H, tr, [box], relief=0.02, taper_m=1000.0)
    lon, lat = lon0 + (cols + 0.5) * d, lat0 + 240 * d - (rows + 0.5) * d
    inside = (lon > 5.08) & (lon < 5.16) & (lat > 44.11) & (lat < 44.17)
    assert h_loc == pytest.approx(np.median(H[inside]))
    assert np.std(flat[inside]) == pytest.approx(0.02 * np.std(H[inside]), rel=1e-6)
    far = (lon < 5.05) | (lon > 5.20) | (lat < 44.08) | (lat > 44.19)  # beyond the taper
    np.testing.assert_array_equal(flat[far], H[far])
    with pytest.raises(InputError, match="outside the DEM"):
        flatten_region(H, tr, [(box[0] + 2.0, box[1])])

