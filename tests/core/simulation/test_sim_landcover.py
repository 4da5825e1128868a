"""Land cover, canopy, buildings, DTM/DSM: fractions, ranges, flatness, tile independence."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from core.errors import InputError
from core.simulation.landcover import (
    LAS_CLASS,
    LandCover,
    LandCoverConfig,
    building_height_m,
    canopy_height_m,
    classify,
    dsm_m,
    dtm_m,
    sample_buildings,
    water_level_for_fraction,
)

SEED = 2024


def _terrain(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """A gentle tilted plane (about 0.6 degrees), metres."""
    return 200.0 + 0.01 * (x - 512_000.0) - 0.002 * (y - 4_987_000.0)


def _large_area(step_m: float = 30.0, size_m: float = 30_000.0) -> tuple[np.ndarray, np.ndarray]:
    g = np.arange(0.0, size_m, step_m)
    return np.meshgrid(g + 350_000.0, g + 5_100_000.0)


@pytest.mark.parametrize("urban, forest", [(0.08, 0.30), (0.2, 0.45)])
def test_fractions_follow_config(urban: float, forest: float) -> None:
    cfg = LandCoverConfig(urban_fraction=urban, forest_fraction=forest,
                          urban_patch_wavelength_m=1500.0)
    x, y = _large_area()
    c = classify(x, y, 100.0, 0.0, SEED, cfg)
    assert c.dtype == np.uint8
    assert set(np.unique(c)) <= {int(k) for k in LandCover}
    assert np.mean(c == LandCover.URBAN) == pytest.approx(urban, abs=0.03)
    assert np.mean(c == LandCover.FOREST) == pytest.approx(forest, abs=0.05)
    assert np.mean(c == LandCover.WATER) == 0.0


def test_steep_slopes_are_not_urban() -> None:
    x, y = _large_area(60.0, 20_000.0)
    cfg = LandCoverConfig(urban_fraction=0.3)
    flat = classify(x, y, 0.0, 0.0, SEED, cfg)
    steep = classify(x, y, 0.0, 25.0, SEED, cfg)
    assert np.mean(flat == LandCover.URBAN) > 0.2
    assert not np.any(steep == LandCover.URBAN)


def test_water_below_level_is_flat_in_dtm_and_dsm() -> None:
    x, y = _large_area(20.0, 4000.0)
    h = 90.0 + 0.01 * (x - x.min()) + 3.0 * np.sin(y / 300.0)
    cfg = LandCoverConfig(water_level_m=100.0, forest_fraction=0.5, urban_fraction=0.2)
    c = classify(x, y, h, 0.0, SEED, cfg)
    water = c == LandCover.WATER
    np.testing.assert_array_equal(water, h < 100.0)
    dtm = dtm_m(h, c, cfg)
    canopy = canopy_height_m(x, y, c, SEED, cfg)
    bld = building_height_m(x, y, c, SEED, cfg)
    dsm = dsm_m(h, c, canopy, bld, cfg)
    assert np.all(dtm[water] == 100.0) and np.all(dsm[water] == 100.0)
    np.testing.assert_array_equal(dtm[~water], h[~water])
    assert np.all(canopy[water] == 0.0) and np.all(bld[water] == 0.0)


def test_water_rule_needs_a_level() -> None:
    c = np.array([LandCover.WATER], dtype=np.uint8)
    with pytest.raises(InputError, match="water_level_m"):
        dtm_m(np.array([1.0]), c, LandCoverConfig())


def test_canopy_in_range_and_varies_at_crown_scale() -> None:
    g = np.arange(0.0, 600.0, 1.0)
    x, y = np.meshgrid(g + 1e5, g + 2e6)
    forest = np.full(x.shape, LandCover.FOREST, dtype=np.uint8)
    h = canopy_height_m(x, y, forest, SEED)
    assert h.min() >= 10.0 and h.max() <= 25.0
    assert h.max() - h.min() > 8.0
    assert h.std() > 1.5
    # crowns: neighbouring metres differ more than a smooth stand-scale field would
    assert np.mean(np.abs(np.diff(h, axis=1))) > 0.1
    bare = np.full(x.shape, LandCover.BARE_SOIL, dtype=np.uint8)
    assert np.all(canopy_height_m(x, y, bare, SEED) == 0.0)


def test_buildings_are_flat_blocks_with_streets() -> None:
    cfg = LandCoverConfig()
    g = np.arange(0.0, 1000.0, 1.0) + 0.25
    x, y = np.meshgrid(g + 6e5, g + 4e6)
    urban = np.full(x.shape, LandCover.URBAN, dtype=np.uint8)
    h = building_height_m(x, y, urban, SEED, cfg)
    bs = sample_buildings(x, y, SEED, cfg)
    on = h > 0
    assert h[on].min() >= 4.0 and h[on].max() <= 15.0
    assert np.all(h[bs.street] == 0.0)
    # one height per block, constant over the footprint
    bid = np.floor(x / cfg.block_m) * 1e6 + np.floor(y / cfg.block_m)
    ids, inv = np.unique(bid[on], return_inverse=True)
    hmax = np.full(ids.size, -np.inf)
    hmin = np.full(ids.size, np.inf)
    np.maximum.at(hmax, inv, h[on])
    np.minimum.at(hmin, inv, h[on])
    np.testing.assert_array_equal(hmax, hmin)
    n_blocks = (1000 // 50) ** 2
    assert ids.size / n_blocks == pytest.approx(cfg.building_presence, abs=0.05)
    assert 0.25 < np.mean(on) < 0.7
    assert np.mean(np.unique(bid[bs.dark_roof]).size / ids.size) == pytest.approx(
        cfg.dark_roof_fraction, abs=0.06)
    assert np.all(building_height_m(x, y, np.uint8(LandCover.FOREST), SEED, cfg) == 0.0)


def test_roofs_exactly_flat_with_centre_terrain() -> None:
    g = np.arange(0.0, 300.0, 0.5)
    x, y = np.meshgrid(g + 6e5, g + 4e6)
    urban = np.full(x.shape, LandCover.URBAN, dtype=np.uint8)
    h = _terrain(x, y)
    bs = sample_buildings(x, y, SEED)
    bh = building_height_m(x, y, urban, SEED)
    dsm = dsm_m(h, urban, 0.0, bh, roof_base_h_m=_terrain(bs.centre_x_m, bs.centre_y_m))
    on = bh > 0
    b = np.floor(x[on] / 50.0) * 1e6 + np.floor(y[on] / 50.0)
    for block in np.unique(b)[:10]:
        roof = dsm[on][b == block]
        assert np.ptp(roof) < 1e-9
    np.testing.assert_array_equal(dsm[~on], h[~on])


def test_tiles_bit_identical(splits: tuple[int, int], ground_grid: Callable,
                             assemble_tiles: Callable) -> None:
    cfg = LandCoverConfig(water_level_m=204.5, urban_fraction=0.3,
                          urban_patch_wavelength_m=300.0, forest_patch_wavelength_m=200.0)

    def scene(x: np.ndarray, y: np.ndarray, *_: int) -> np.ndarray:
        h = _terrain(x, y)
        c = classify(x, y, h, 1.0, SEED, cfg)
        dsm = dsm_m(h, c, canopy_height_m(x, y, c, SEED, cfg),
                    building_height_m(x, y, c, SEED, cfg), cfg)
        return dsm + 1000.0 * c

    x, y = ground_grid(256, 256)
    whole = scene(x, y)
    c = classify(x, y, _terrain(x, y), 1.0, SEED, cfg)
    assert len(np.unique(c)) == 4  # the window shows every class
    assert whole.tobytes() == assemble_tiles(scene, splits=splits).tobytes()


def test_las_mapping() -> None:
    assert LAS_CLASS == {LandCover.BARE_SOIL: 2, LandCover.FOREST: 5, LandCover.URBAN: 6,
                         LandCover.WATER: 9}


def test_water_level_for_fraction() -> None:
    h = np.arange(1000.0)
    h[::10] = np.nan
    level = water_level_for_fraction(h, 0.25)
    finite = h[np.isfinite(h)]
    assert np.mean(finite < level) == pytest.approx(0.25, abs=0.01)
    with pytest.raises(InputError, match="finite"):
        water_level_for_fraction(np.full(3, np.nan), 0.5)


@pytest.mark.parametrize("kwargs, match", [
    ({"urban_fraction": 1.2}, "urban_fraction"),
    ({"urban_fraction": 0.6, "forest_fraction": 0.6}, "exceed 1"),
    ({"block_m": 12.0}, "block_m"),
    ({"building_height_range_m": (15.0, 4.0)}, "building_height_range_m"),
    ({"water_level_m": float("nan")}, "water_level_m"),
    ({"urban_max_slope_deg": 0.0}, "urban_max_slope_deg"),
])
def test_config_checks(kwargs: dict, match: str) -> None:
    with pytest.raises(InputError, match=match):
        LandCoverConfig(**kwargs)


def test_non_finite_coordinates_are_not_buildings() -> None:
    x = np.array([np.nan, 1e5 + 25.0])
    y = np.array([4e6 + 25.0, np.nan])
    bs = sample_buildings(x, y, SEED)
    assert not bs.in_footprint.any() and not bs.urban_block.any() and not bs.street.any()
