"""Simulated lidar: spacing, tile union, noise, dropouts, classes."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from core.errors import InputError
from core.simulation.landcover import (
    LandCover,
    LandCoverConfig,
    building_height_m,
    canopy_height_m,
    classify,
    dsm_m,
    dtm_m,
    sample_buildings,
)
from core.simulation.lidar import LidarConfig, LidarPoints, lidar_points, lidar_returns

SEED = 5
BOX = (600_010.0, 4_000_020.0, 601_210.0, 4_001_220.0)  # 1.2 km square


def test_mean_nearest_neighbour_distance_matches_spacing() -> None:
    p = lidar_points(*BOX, SEED, spacing_m=3.0)
    assert len(p) == pytest.approx((1200 / 3) ** 2, rel=0.01)
    d, _ = cKDTree(np.c_[p.x_m, p.y_m]).query(np.c_[p.x_m, p.y_m], k=2)
    assert d[:, 1].mean() == pytest.approx(3.0, rel=0.2)
    assert d[:, 1].min() > 3.0 * (1 - 0.3) - 1e-9  # jitter 0.3 keeps points apart


def test_tiles_partition_the_points() -> None:
    x0, y0 = BOX[:2]
    whole = lidar_points(x0, y0, x0 + 256.0, y0 + 256.0, SEED)
    xm, ym = x0 + 128.7, y0 + 101.3  # cuts that do not fall on the lattice
    parts = [lidar_points(a, b, c, d, SEED) for a, b, c, d in (
        (x0, y0, xm, ym), (xm, y0, x0 + 256.0, ym),
        (x0, ym, xm, y0 + 256.0), (xm, ym, x0 + 256.0, y0 + 256.0))]
    joined = np.concatenate([np.c_[q.x_m, q.y_m, q.cell_i, q.cell_j] for q in parts])
    ref = np.c_[whole.x_m, whole.y_m, whole.cell_i, whole.cell_j]
    order = np.lexsort((joined[:, 1], joined[:, 0]))
    ref_order = np.lexsort((ref[:, 1], ref[:, 0]))
    assert joined[order].tobytes() == ref[ref_order].tobytes()
    other = lidar_points(x0, y0, x0 + 256.0, y0 + 256.0, SEED + 1)
    assert not np.array_equal(other.x_m, whole.x_m)


def _survey(seed: int = SEED, cfg: LidarConfig | None = None
            ) -> tuple[LidarPoints, dict[str, np.ndarray], object]:
    lc = LandCoverConfig(water_level_m=100.0, urban_fraction=0.3, forest_fraction=0.4,
                         urban_patch_wavelength_m=400.0, forest_patch_wavelength_m=300.0,
                         dark_roof_fraction=0.3)
    pts = lidar_points(*BOX, seed)
    x, y = pts.x_m, pts.y_m
    terrain = 95.0 + 0.02 * (x - BOX[0])  # water in the western 250 m
    cls = classify(x, y, terrain, 0.0, SEED, lc)
    bh = building_height_m(x, y, cls, SEED, lc)
    dsm = dsm_m(terrain, cls, canopy_height_m(x, y, cls, SEED, lc), bh, lc)
    info = {"cls": cls, "dtm": dtm_m(terrain, cls, lc), "dsm": dsm, "bh": bh,
            "dark": sample_buildings(x, y, SEED, lc).dark_roof}
    ret = lidar_returns(pts, info["dtm"], dsm, cls, bh > 0, info["dark"], seed,
                        cfg or LidarConfig())
    return pts, info, ret


def test_returns_noise_classes_and_dropouts() -> None:
    pts, info, ret = _survey()
    cls, dark = info["cls"], info["dark"]
    assert {int(k) for k in np.unique(cls)} == {int(k) for k in LandCover}
    # no return on water, none on dark roofs, everything else kept
    kept = np.zeros(len(pts), dtype=bool)
    lookup = {(i, j): n for n, (i, j) in enumerate(zip(pts.cell_i, pts.cell_j, strict=True))}
    kept[[lookup[(i, j)] for i, j in zip(ret.cell_i, ret.cell_j, strict=True)]] = True
    dropped = (cls == LandCover.WATER) | (dark & (info["bh"] > 0))
    assert np.sum(dark & (info["bh"] > 0)) > 100
    np.testing.assert_array_equal(kept, ~dropped)
    assert not np.any(ret.las_class == 9)
    # vertical noise 0.15 m, unbiased
    err = ret.z_m - ret.z_true_m
    assert err.std() == pytest.approx(0.15, abs=0.02)
    assert abs(err.mean()) < 0.005
    # classes follow the land cover
    kc = cls[kept]
    on_bld = (info["bh"] > 0)[kept]
    assert set(np.unique(ret.las_class)) == {2, 5, 6}
    assert np.all(ret.las_class[on_bld] == 6)
    assert np.all(ret.las_class[(kc == LandCover.BARE_SOIL)] == 2)
    assert np.all(ret.las_class[(kc == LandCover.URBAN) & ~on_bld] == 2)
    forest = kc == LandCover.FOREST
    assert set(np.unique(ret.las_class[forest])) == {2, 5}
    ground_share = np.mean(ret.las_class[forest] == 2)
    assert ground_share == pytest.approx(0.15, abs=0.02)
    # ground hits under the canopy are at the ground, canopy hits at the canopy top
    gh = forest & (ret.las_class == 2)
    np.testing.assert_array_equal(ret.z_true_m[gh], info["dtm"][kept][gh])
    assert np.all(ret.z_true_m[forest & (ret.las_class == 5)]
                  >= info["dtm"][kept][forest & (ret.las_class == 5)] + 10.0)


def test_water_returns_when_configured() -> None:
    _, info, ret = _survey(cfg=LidarConfig(water_return_fraction=0.5, noise_sigma_m=0.0))
    water = ret.las_class == 9
    share = water.sum() / np.sum(info["cls"] == LandCover.WATER)
    assert share == pytest.approx(0.5, abs=0.05)
    assert np.all(ret.z_m[water] == 100.0)


def test_same_seed_same_returns() -> None:
    a = _survey()[2]
    b = _survey()[2]
    assert a.z_m.tobytes() == b.z_m.tobytes() and a.las_class.tobytes() == b.las_class.tobytes()


def test_input_checks() -> None:
    with pytest.raises(InputError, match="spacing_m"):
        lidar_points(0.0, 0.0, 10.0, 10.0, SEED, spacing_m=0.0)
    with pytest.raises(InputError, match="empty box"):
        lidar_points(10.0, 0.0, 10.0, 10.0, SEED)
    with pytest.raises(InputError, match="noise_sigma_m"):
        LidarConfig(noise_sigma_m=-1.0)
    pts = lidar_points(0.0, 0.0, 30.0, 30.0, SEED)
    with pytest.raises(InputError, match="surface_h_m"):
        lidar_returns(pts, np.zeros(len(pts)), np.zeros(3), np.zeros(len(pts)),
                      np.zeros(len(pts)), np.zeros(len(pts)), SEED)
