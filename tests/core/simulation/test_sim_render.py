"""Rendering: analytic hillshade, map_overlap tiling, texture, date changes, digital numbers."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest

from core.errors import InputError
from core.simulation.landcover import LandCover, LandCoverConfig, classify
from core.simulation.render import (
    ChangeKind,
    apply_date_change,
    date_change_kind,
    date_change_mask,
    date_change_weight,
    hillshade,
    illuminate,
    radiance_to_dn,
    texture,
)

SEED = 77


def _lambert(slope_deg: float, aspect_deg: float, sun_az: float, sun_el: float) -> float:
    """Textbook Lambert: cos(zenith)cos(slope) + sin(zenith)sin(slope)cos(az - aspect)."""
    z, s = np.deg2rad(90.0 - sun_el), np.deg2rad(slope_deg)
    return max(0.0, np.cos(z) * np.cos(s)
               + np.sin(z) * np.sin(s) * np.cos(np.deg2rad(sun_az - aspect_deg)))


@pytest.mark.parametrize("slope_deg, aspect_deg", [(0.0, 0.0), (20.0, 135.0), (35.0, 300.0),
                                                   (10.0, 180.0), (60.0, 10.0)])
@pytest.mark.parametrize("dy_sign", [-1.0, 1.0])
def test_hillshade_of_a_plane_is_exact_lambert(slope_deg: float, aspect_deg: float,
                                               dy_sign: float) -> None:
    # a plane that faces (descends towards) azimuth aspect_deg with the given slope
    g = np.tan(np.deg2rad(slope_deg))
    a = np.deg2rad(aspect_deg)
    dzde, dzdn = -g * np.sin(a), -g * np.cos(a)  # metres per metre east, north
    dx, dy = 2.0, 3.0 * dy_sign
    rows, cols = np.mgrid[0:7, 0:9].astype(np.float64)
    dem = 500.0 + dzde * cols * dx + dzdn * rows * dy
    shade = hillshade(dem, dx, dy, 150.0, 40.0)
    assert shade.shape == dem.shape
    np.testing.assert_allclose(shade, _lambert(slope_deg, aspect_deg, 150.0, 40.0), atol=1e-12)


def test_hillshade_north_up_slope_facing_sun_is_brighter() -> None:
    # north-up raster (dy < 0): heights rise with row index = terrain descends to the north
    rows = np.arange(10.0)[:, None] * np.ones((1, 10))
    north_facing = hillshade(rows * 5.0, 10.0, -10.0, 0.0, 30.0)  # sun in the north
    south_facing = hillshade(-rows * 5.0, 10.0, -10.0, 0.0, 30.0)
    assert np.all(north_facing > south_facing)
    assert np.all(hillshade(rows * 100.0, 1.0, -1.0, 180.0, 10.0) == 0.0)  # in shadow


def test_hillshade_tiles_with_one_pixel_halo_join_exactly(ground_grid: Callable) -> None:
    x, y = ground_grid(100, 90)
    dem = 300.0 + 20.0 * np.sin(x / 37.0) * np.cos(y / 23.0)
    whole = hillshade(dem, 2.5, -2.5, 135.0, 45.0)
    out = np.empty_like(whole)
    for r0, r1 in ((0, 41), (41, 100)):
        for c0, c1 in ((0, 57), (57, 90)):
            lo_r, lo_c = max(r0 - 1, 0), max(c0 - 1, 0)
            block = hillshade(dem[lo_r:r1 + 1, lo_c:c1 + 1], 2.5, -2.5, 135.0, 45.0)
            out[r0:r1, c0:c1] = block[r0 - lo_r:r0 - lo_r + r1 - r0, c0 - lo_c:c0 - lo_c + c1 - c0]
    assert out.tobytes() == whole.tobytes()


def test_hillshade_input_errors() -> None:
    with pytest.raises(InputError, match="2-D"):
        hillshade(np.zeros(5), 1.0, 1.0, 0.0, 45.0)
    with pytest.raises(InputError, match="non-zero"):
        hillshade(np.zeros((3, 3)), 0.0, 1.0, 0.0, 45.0)


def _classes(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    cfg = LandCoverConfig(water_level_m=0.0, urban_fraction=0.3, urban_patch_wavelength_m=300.0,
                          forest_patch_wavelength_m=150.0)
    h = np.where(x < x.min() + 60.0, -1.0, 10.0)
    return classify(x, y, h, 0.0, SEED, cfg)


def test_texture_per_class_and_tiles(splits: tuple[int, int], ground_grid: Callable,
                                     assemble_tiles: Callable) -> None:
    x, y = ground_grid(256, 256)
    cls = _classes(x, y)
    cfg = LandCoverConfig(water_level_m=0.0, urban_fraction=0.3)
    t = texture(x, y, cls, SEED, cfg)
    assert t.min() >= 0.0 and t.max() <= 1.0
    means = {k: t[cls == k].mean() for k in LandCover if np.any(cls == k)}
    assert len(means) == 4
    assert means[LandCover.WATER] < 0.06 < means[LandCover.FOREST] < 0.15 < means[
        LandCover.BARE_SOIL]
    assert t[cls == LandCover.WATER].std() < 0.02
    assert t[cls == LandCover.URBAN].std() > 0.08  # roofs vs streets
    tiled = assemble_tiles(lambda tx, ty, r, c: texture(tx, ty, cls[r:r + tx.shape[0],
                                                                    c:c + tx.shape[1]],
                                                        SEED, cfg), splits=splits)
    assert tiled.tobytes() == t.tobytes()


def test_date_change_fraction_blobs_and_kinds() -> None:
    g = np.arange(0.0, 20_000.0, 20.0)
    x, y = np.meshgrid(g + 4e5, g + 5e6)
    m = date_change_mask(x, y, SEED, 0.2, blob_wavelength_m=800.0)
    assert np.mean(m) == pytest.approx(0.2, abs=0.04)
    # blobs, not salt and pepper: most neighbours agree
    assert np.mean(m[:, 1:] != m[:, :-1]) < 0.05
    w = date_change_weight(x, y, SEED, 0.2, blob_wavelength_m=800.0)
    assert np.array_equal(w > 0, m) and w.max() == 1.0
    assert 0.0 < np.mean((w > 0) & (w < 1)) < 0.1  # soft rims
    k = date_change_kind(x, y, SEED, region_wavelength_m=2000.0)
    shares = [np.mean(k == kind) for kind in (ChangeKind.VEGETATION, ChangeKind.SNOW,
                                              ChangeKind.CLOUD)]
    assert np.allclose(shares, 1 / 3, atol=0.08)


def test_apply_date_change() -> None:
    r = np.array([0.1, 0.1, 0.1, 0.1, 0.3])
    w = np.array([0.0, 0.5, 0.5, 0.5, 1.0])
    kinds = np.array([ChangeKind.CLOUD, ChangeKind.CLOUD, ChangeKind.SNOW,
                      ChangeKind.VEGETATION, ChangeKind.NONE])
    out = apply_date_change(r, w, kinds)
    np.testing.assert_allclose(out, [0.1, 0.5, 0.815, 0.4, 0.3])
    assert np.all(apply_date_change(r, 1.0, ChangeKind.SNOW) > 0.8)


@pytest.mark.parametrize("bits, dtype", [(8, np.uint8), (12, np.uint16)])
def test_dn_range_dtype_and_noise(bits: int, dtype: type) -> None:
    rows, cols = np.mgrid[0:300, 0:300]
    r = np.full(rows.shape, 0.4)
    dn = radiance_to_dn(illuminate(r, 1.0), 2.0, bits, SEED, rows, cols)
    assert dn.dtype == dtype
    gain = 0.8 * (2**bits - 1)
    assert dn.astype(float).mean() == pytest.approx(0.4 * gain, abs=0.05)
    assert dn.astype(float).std() == pytest.approx(np.sqrt(4.0 + 1 / 12), rel=0.05)
    sat = radiance_to_dn(np.array([0.0, 1.0, 5.0, np.nan]), 50.0, bits, SEED,
                         0, np.arange(4))
    assert sat.max() <= 2**bits - 1 and sat[2] == 2**bits - 1 and sat[3] == 0


def test_dn_noise_is_per_pixel(splits: tuple[int, int]) -> None:
    rows, cols = np.mgrid[0:256, 0:256]
    r = np.linspace(0, 1, 256)[None, :] * np.ones((256, 1))
    shade = np.full(r.shape, 0.7)
    whole = radiance_to_dn(illuminate(r, shade), 3.0, 12, SEED, rows, cols)
    a, b = splits
    tile = radiance_to_dn(illuminate(r[a:, b:], shade[a:, b:]), 3.0, 12, SEED, rows[a:, b:],
                          cols[a:, b:])
    assert tile.tobytes() == whole[a:, b:].tobytes()
    other = radiance_to_dn(illuminate(r, shade), 3.0, 12, SEED + 1, rows, cols)
    assert np.mean(other == whole) < 0.5
    shaded = radiance_to_dn(illuminate(r, 0.0), 0.0, 12, SEED, rows, cols)
    assert shaded.max() <= np.rint(0.2 * 0.8 * 4095)


def test_dn_input_errors() -> None:
    with pytest.raises(InputError, match="bits"):
        radiance_to_dn(0.5, 1.0, 16, SEED, 0, 0)
    with pytest.raises(InputError, match="noise_sigma_dn"):
        radiance_to_dn(0.5, -1.0, 8, SEED, 0, 0)
    with pytest.raises(InputError, match="ambient"):
        illuminate(0.5, 1.0, ambient=1.5)
