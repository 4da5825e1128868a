"""Ortho-versus-ortho correlation kernel: known sub-pixel shifts of an analytic texture are
recovered (the texture is evaluated exactly at the shifted positions, no resampling), windows
without value, texture or match are flagged, and the statistics agree with numpy."""

from __future__ import annotations

import numpy as np
import pytest

from core.errors import InputError
from core.ortho.ortho_compare import (
    CompareConfig,
    ShiftStatus,
    WindowShifts,
    discrepancy_stats,
    match_windows,
    window_origins,
)

N = 300


def texture(x: np.ndarray, y: np.ndarray, seed: int = 3) -> np.ndarray:
    """A sum of random plane waves (wavelengths 5..40 cells), exact at any position."""
    rng = np.random.default_rng(seed)
    out = np.zeros(np.broadcast(x, y).shape)
    for _ in range(40):
        k = 2 * np.pi / rng.uniform(5.0, 40.0)
        a = rng.uniform(0, 2 * np.pi)
        out += rng.uniform(5, 20) * np.sin(k * (np.cos(a) * x + np.sin(a) * y)
                                           + rng.uniform(0, 2 * np.pi))
    return out


def pair(d_col: float, d_row: float) -> tuple[np.ndarray, np.ndarray]:
    """Left and right arrays where the right's content is moved by (d_col, d_row) cells."""
    i, j = np.mgrid[0:N, 0:N].astype(np.float64)
    return texture(j, i), texture(j - d_col, i - d_row)


@pytest.mark.parametrize("d_col, d_row", [(0.0, 0.0), (0.3, -0.45), (2.0, 0.0), (-1.73, 3.26)])
def test_known_shifts_are_recovered_to_a_hundredth_of_a_cell(d_col, d_row):
    left, right = pair(d_col, d_row)
    cfg = CompareConfig(window_px=48, step_px=60, search_px=6)
    rows = cols = window_origins(0, N, cfg)
    s = match_windows(left, right, rows, cols, cfg)
    assert (s.status == ShiftStatus.OK).all()
    np.testing.assert_allclose(s.dx_px, d_col, atol=0.01)
    np.testing.assert_allclose(s.dy_px, -d_row, atol=0.01)  # dy is north: rows go south
    assert np.all(s.ncc > 0.99)


def test_nodata_flat_and_mismatched_windows_are_flagged():
    cfg = CompareConfig(window_px=32, step_px=40, search_px=4, min_ncc=0.5)
    left, right = pair(0.0, 0.0)
    rows = cols = window_origins(0, N, cfg)
    r0, c0 = rows[0], cols[0]
    left[r0 + 3, c0 + 3] = np.nan  # window (0, 0): no value
    left[rows[1]:rows[1] + 32, cols[0]:cols[0] + 32] = 7.0  # window (1, 0): flat
    rng = np.random.default_rng(0)  # window (2, 0): noise against texture
    right[rows[2] - 6:rows[2] + 38, cols[0] - 6:cols[0] + 38] = rng.normal(size=(44, 44))
    s = match_windows(left, right, rows, cols, cfg)
    assert s.status[0, 0] == ShiftStatus.NODATA
    assert s.status[1, 0] == ShiftStatus.FLAT
    assert s.status[2, 0] == ShiftStatus.LOW_NCC
    assert (s.status[:, 1:] == ShiftStatus.OK).all()
    assert np.isnan(s.dx_px[0, 0]) and np.isnan(s.dy_px[1, 0])


def test_a_shift_beyond_the_search_is_not_reported():
    left, right = pair(9.0, 0.0)
    cfg = CompareConfig(window_px=48, step_px=60, search_px=4, min_ncc=-1.0)
    rows = cols = window_origins(0, N, cfg)
    s = match_windows(left, right, rows, cols, cfg)
    assert not (s.status == ShiftStatus.OK).any()


def test_window_origins_keep_the_search_inside():
    cfg = CompareConfig(window_px=64, step_px=128, search_px=8)
    o = window_origins(5, 500, cfg)
    assert o[0] - cfg.margin_px >= 5 and o[-1] + 64 + cfg.margin_px <= 500
    assert np.all(np.diff(o) == 128)
    assert window_origins(0, 60, cfg).size == 0


def test_statistics_agree_with_numpy():
    rng = np.random.default_rng(1)
    dx, dy = rng.normal(0.3, 1, (7, 9)), rng.normal(-0.2, 1, (7, 9))
    status = np.zeros((7, 9), np.uint8)
    status[0] = ShiftStatus.NODATA
    st = discrepancy_stats(WindowShifts(dx, dy, np.ones((7, 9)), status), cell_m=2.5)
    norm = np.hypot(dx[1:], dy[1:])
    assert st.n_windows == 63 and st.n_valid == 54
    assert st.median_dx_px == pytest.approx(np.median(dx[1:]))
    assert st.median_dy_px == pytest.approx(np.median(dy[1:]))
    assert st.median_norm_px == pytest.approx(np.median(norm))
    assert st.p95_norm_px == pytest.approx(np.percentile(norm, 95))
    assert st.rms_norm_px == pytest.approx(np.sqrt(np.mean(norm ** 2)))
    assert st.to_dict()["m"]["p95_norm"] == pytest.approx(2.5 * np.percentile(norm, 95))


def test_bad_settings_are_one_line():
    with pytest.raises(InputError, match="window"):
        CompareConfig(window_px=4)
    with pytest.raises(InputError, match="search"):
        CompareConfig(search_px=1)
