"""Shared helpers for the simulation tests: a ground grid and its four tiles."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest
from numpy.typing import NDArray

X0_M = 512_345.0  # UTM-like easting, metres
Y0_M = 4_987_650.0
GSD_M = 2.5


def _ground_grid(n_rows: int, n_cols: int, row0: int = 0, col0: int = 0,
                gsd_m: float = GSD_M) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Pixel-centre coordinates of a north-up window, computed from global indices."""
    cols = np.arange(col0, col0 + n_cols, dtype=np.float64)
    rows = np.arange(row0, row0 + n_rows, dtype=np.float64)
    x = X0_M + (cols[None, :] + 0.5) * gsd_m
    y = Y0_M - (rows[:, None] + 0.5) * gsd_m
    return np.broadcast_arrays(x, y)


def _assemble_tiles(fn: Callable[[NDArray, NDArray, int, int], NDArray], n: int = 256,
                   splits: tuple[int, int] = (128, 128)) -> NDArray:
    """Compute ``fn(x, y, row0, col0)`` on four tiles cut at ``splits`` and join them."""
    r, c = splits
    out = None
    for r0, nr in ((0, r), (r, n - r)):
        for c0, nc in ((0, c), (c, n - c)):
            x, y = _ground_grid(nr, nc, r0, c0)
            block = fn(x, y, r0, c0)
            if out is None:
                out = np.empty((n, n), dtype=block.dtype)
            out[r0:r0 + nr, c0:c0 + nc] = block
    assert out is not None
    return out


@pytest.fixture(params=[(128, 128), (77, 131)], ids=["even", "odd"])
def splits(request: pytest.FixtureRequest) -> tuple[int, int]:
    """Tile cut positions: the 2x2 split asked for, and an uneven one (SIMD tails)."""
    return request.param


@pytest.fixture
def ground_grid() -> Callable[..., tuple[NDArray[np.float64], NDArray[np.float64]]]:
    """``ground_grid(n_rows, n_cols, row0=0, col0=0)``: pixel-centre x, y of a window."""
    return _ground_grid


@pytest.fixture
def assemble_tiles() -> Callable[..., NDArray]:
    """``assemble_tiles(fn, n=256, splits=(128, 128))``: four tiles of ``fn`` joined."""
    return _assemble_tiles
