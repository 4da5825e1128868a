"""The overlap of a pair in tie-point cells (core.matching.overlap) on synthetic pushbroom
models of known footprint and parallax."""

from __future__ import annotations

import math

import numpy as np
import pytest

from core.geodesy import geodetic_to_enu
from core.matching.overlap import overlap_cell_m, overlap_cells
from core.matching.tiepoints import HeightPrior, TiePointConfig
from core.sensors.pushbroom_synthetic import SyntheticSpec, synthetic_pushbroom

SIZE = (200, 200)
GSD_M = 2.0  # a 400 m crop, much smaller than the default 2 km cell


def _model(incidence_deg: float, centre_h_m: float):
    return synthetic_pushbroom(SyntheticSpec(5.25, 44.2, centre_h_m=centre_h_m, n_cols=SIZE[0],
                                             n_rows=SIZE[1], gsd_m=GSD_M,
                                             incidence_deg=incidence_deg))


def _origin(model, h_m: float) -> tuple[float, float, float]:
    lon, lat = model.localize(99.5, 99.5, h_m)
    return float(lon), float(lat), h_m


def test_a_crop_smaller_than_the_cell_gets_eight_by_eight_cells():
    """Both images see the same 400 m square: the cell becomes 400 / 8 = 50 m (the footprint
    measured on the ground, not by the code under test); the overlap then holds about 64 full
    cells, where the default 2 km cell holds none."""
    m = _model(0.0, 500.0)
    heights = HeightPrior.from_range(400.0, 600.0)
    lon, lat = m.localize([0.0, 199.0, 0.0], [0.0, 0.0, 199.0], np.full(3, 500.0))
    e, n, _ = geodetic_to_enu(lon, lat, np.full(3, 500.0), (lon[0], lat[0], 500.0))
    side_m = math.sqrt(math.hypot(e[1], n[1]) * math.hypot(e[2], n[2])) * 200.0 / 199.0
    default = TiePointConfig().cell_m
    assert overlap_cells(m, m, SIZE, SIZE, heights, _origin(m, 500.0), default).size == 0
    cell = overlap_cell_m(m, m, SIZE, SIZE, heights, default)
    assert cell == pytest.approx(side_m / 8.0, rel=0.03)
    ids = overlap_cells(m, m, SIZE, SIZE, heights, _origin(m, 500.0), cell)
    assert 49 <= ids.size <= 81
    # a cell already small enough is kept, and 0 cells per side keeps any cell
    assert overlap_cell_m(m, m, SIZE, SIZE, heights, 30.0) == 30.0
    assert overlap_cell_m(m, m, SIZE, SIZE, heights, default, 0) == default


def test_a_pair_seen_together_only_at_intermediate_heights_overlaps():
    """Incidences +25 / -20 deg (0.83 m of parallax per metre of height, 0.42 px/m), both
    images centred on the same point at 3000 m: over the range 0..4000 m they overlap within
    about 480 m of 3000 m only, not at the range's ends nor its middle (415 px away)."""
    left, right = _model(25.0, 3000.0), _model(-20.0, 3000.0)
    heights = HeightPrior.from_range(0.0, 4000.0)
    cc, rr = np.meshgrid(np.arange(0.0, 200.0, 5.0), np.arange(0.0, 200.0, 5.0))
    for h in (0.0, 2000.0, 4000.0):  # the setup: no left pixel inside the right image there
        pc, pr = right.project(*left.localize(cc.ravel(), rr.ravel(), h), h)
        assert not np.any((pc >= 0) & (pc <= 199) & (pr >= 0) & (pr <= 199)), h
    cell = overlap_cell_m(left, right, SIZE, SIZE, heights, 2000.0)
    assert cell < 60.0
    ids = overlap_cells(left, right, SIZE, SIZE, heights, _origin(left, 3000.0), cell)
    assert ids.size >= 36
    # images that never meet at any height of the range do not overlap
    far = synthetic_pushbroom(SyntheticSpec(5.30, 44.2, centre_h_m=3000.0, n_cols=SIZE[0],
                                            n_rows=SIZE[1], gsd_m=GSD_M, incidence_deg=-20.0))
    assert overlap_cells(left, far, SIZE, SIZE, heights, _origin(left, 3000.0), cell).size == 0
