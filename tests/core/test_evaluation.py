"""Accuracy statistics of dz: against NumPy (exact path) and within the bin width (histogram
path), streaming in chunks, the bootstrap interval against brute-force resampling, heights,
grids and the report's JSON round trip."""

import json
import math

import numpy as np
import pytest
from affine import Affine

from core.dem import sample_bilinear
from core.errors import InputError
from core.evaluation import (
    ClassedDz,
    CrsInfo,
    DemInfo,
    DzAccumulator,
    DzStats,
    EvaluationReport,
    GcpCheck,
    HeightFrame,
    LandcoverInfo,
    LidarInfo,
    MaskSummary,
    PointCounts,
    StatsConfig,
    affine_nodes,
    code_counts,
    height_difference_m,
    inside_grid,
    sample_nearest,
    select_points,
    window_groups,
)
from core.geoid import GeoidGrid


def _numpy_stats(x: np.ndarray) -> dict[str, float]:
    """The expected figures, written with NumPy only."""
    med = np.median(x)
    return {
        "count": x.size, "mean": np.mean(x), "std": np.std(x, ddof=1),
        "rmse": np.sqrt(np.mean(x ** 2)), "median": med,
        "nmad": 1.4826 * np.median(np.abs(x - med)),
        "le68": np.percentile(np.abs(x), 68), "le90": np.percentile(np.abs(x), 90),
        "le95": np.percentile(np.abs(x), 95), "min": np.min(x), "max": np.max(x),
    }


def _samples(seed: int) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    return {
        "normal_biased": rng.normal(0.35, 1.2, 4001),
        "heavy_tails": 0.8 * rng.standard_t(2.5, 2500) - 0.1,
        "skewed": rng.exponential(2.0, 999) - 0.5,
        "outliers": np.concatenate([rng.normal(0, 0.2, 1000), rng.uniform(-80, 80, 37)]),
        "tiny": np.array([0.4, -1.3, 2.0]),
        "two": np.array([0.25, -0.75]),
        "ties": np.round(rng.normal(0, 1, 600), 1),
    }


@pytest.mark.parametrize("name", sorted(_samples(0)))
def test_exact_statistics_agree_with_numpy(name):
    x = _samples(0)[name]
    acc = DzAccumulator()
    acc.add(x)
    s = acc.stats()
    want = _numpy_stats(x)
    assert s.method == "exact" and s.resolution_m == 0.0 and s.count == want["count"]
    for key in DzStats.KEYS:
        assert getattr(s, f"{key}_m") == pytest.approx(want[key], rel=1e-12, abs=1e-12), key


@pytest.mark.parametrize("bin_m", [0.001, 0.01])
@pytest.mark.parametrize("name", ["normal_biased", "heavy_tails", "outliers", "ties"])
def test_histogram_statistics_are_within_the_bin_width(name, bin_m):
    x = _samples(1)[name]
    acc = DzAccumulator(StatsConfig(bin_m=bin_m, exact_max_count=0))
    acc.add(x)
    s = acc.stats()
    want = _numpy_stats(x)
    assert s.method == "histogram" and s.resolution_m == bin_m / 2
    for key in ("mean", "std", "rmse", "min", "max"):  # exact from the running sums
        assert getattr(s, f"{key}_m") == pytest.approx(want[key], rel=1e-11, abs=1e-12), key
    for key in ("median", "le68", "le90", "le95"):
        assert abs(getattr(s, f"{key}_m") - want[key]) <= bin_m / 2 + 1e-12, key
    assert abs(s.nmad_m - want["nmad"]) <= 1.4826 * bin_m + 1e-12


def test_values_beyond_the_histogram_range_keep_the_percentiles_below_them():
    rng = np.random.default_rng(2)
    x = np.concatenate([rng.normal(0, 1, 5000), [900.0, -1200.0, 5e6]])
    acc = DzAccumulator(StatsConfig(exact_max_count=10))
    for part in np.array_split(x, 4):
        acc.add(part)
    s = acc.stats()
    assert s.min_m == -1200.0 and s.max_m == 5e6 and s.count == x.size
    assert abs(s.le90_m - np.percentile(np.abs(x), 90)) <= 0.0005 + 1e-12


def test_empty_and_single_value():
    s = DzAccumulator().stats()
    assert s.count == 0 and math.isnan(s.mean_m) and math.isnan(s.le68_ci_m[0])
    acc = DzAccumulator()
    acc.add([0.5])
    s = acc.stats()
    assert s.mean_m == 0.5 and s.le68_m == 0.5 and math.isnan(s.std_m)
    assert math.isnan(s.le68_ci_m[0])
    with pytest.raises(InputError, match="finite"):
        acc.add([1.0, np.nan])


@pytest.mark.parametrize("exact_max_count", [10**6, 0, 3000])
def test_chunks_and_merges_give_the_one_pass_result(exact_max_count):
    """exact throughout, histogram throughout, and a switch from exact to histogram midway"""
    cfg = StatsConfig(exact_max_count=exact_max_count)
    x = np.random.default_rng(3).normal(-0.2, 0.9, 10_000)
    one = DzAccumulator(cfg)
    one.add(x)
    chunked = DzAccumulator(cfg)
    for part in np.array_split(x, 17):
        chunked.add(part)
    merged = DzAccumulator(cfg)  # chunks accumulated apart, then merged
    for part in np.array_split(x, 5):
        a = DzAccumulator(cfg)
        a.add(part)
        merged.merge(a)
    ref = one.stats()
    for s in (chunked.stats(), merged.stats()):
        assert s.method == ref.method and s.count == ref.count
        for key in ("mean", "std", "rmse"):
            assert getattr(s, f"{key}_m") == pytest.approx(getattr(ref, f"{key}_m"), rel=1e-12)
        for key in ("median", "nmad", "le68", "le90", "le95", "min", "max"):
            assert getattr(s, f"{key}_m") == getattr(ref, f"{key}_m"), key
        assert s.le68_ci_m == ref.le68_ci_m


def test_bootstrap_interval_matches_brute_force_resampling():
    x = np.random.default_rng(4).normal(0.1, 1.0, 400)
    acc = DzAccumulator(StatsConfig(n_bootstrap=4000, seed=7))
    acc.add(x)
    lo, hi = acc.stats().le68_ci_m
    rng = np.random.default_rng(11)  # the textbook bootstrap, written with NumPy
    reps = [np.percentile(np.abs(rng.choice(x, x.size)), 68) for _ in range(4000)]
    want_lo, want_hi = np.quantile(reps, [0.025, 0.975])
    width = want_hi - want_lo
    assert abs(lo - want_lo) < 0.1 * width and abs(hi - want_hi) < 0.1 * width
    assert lo < np.percentile(np.abs(x), 68) < hi


def test_bootstrap_interval_is_seeded_and_follows_the_level():
    x = np.random.default_rng(5).normal(0.0, 1.0, 2000)

    def ci(**kw):
        acc = DzAccumulator(StatsConfig(**kw))
        acc.add(x)
        return acc.stats().le68_ci_m

    assert ci(seed=1) == ci(seed=1) != ci(seed=2)
    narrow, wide = ci(ci_level=0.5), ci(ci_level=0.99)
    assert wide[0] < narrow[0] < narrow[1] < wide[1]
    assert all(math.isnan(v) for v in ci(n_bootstrap=0))


def test_classes_match_numpy_on_each_subset_and_all():
    rng = np.random.default_rng(6)
    codes = rng.choice([2, 5, 6, 9], 5000)
    dz = rng.normal(0, 1, 5000) + codes * 0.1
    acc = ClassedDz()
    for part in np.array_split(np.arange(5000), 7):
        acc.add(dz[part], codes[part])
    per = acc.class_stats()
    assert sorted(per) == [2, 5, 6, 9] and acc.count == 5000
    for code, s in per.items():
        want = _numpy_stats(dz[codes == code])
        assert s.count == want["count"]
        assert s.le68_m == pytest.approx(want["le68"], rel=1e-12)
        assert s.mean_m == pytest.approx(want["mean"], rel=1e-12)
    assert acc.overall().nmad_m == pytest.approx(_numpy_stats(dz)["nmad"], rel=1e-12)
    with pytest.raises(InputError, match="class codes"):
        acc.add(dz[:3], codes[:2])


def test_height_difference_units_and_datums():
    geoid = GeoidGrid(np.full((3, 3), 48.0), 43.0, 4.0, 1.0, 1.0)  # N = 48 m everywhere
    dem_h = np.array([150.0, 260.0])
    lidar_h_ft = np.array([100.0, 200.0]) / 0.3048  # 100 m, 200 m ellipsoidal, in feet
    same = height_difference_m(dem_h, HeightFrame("ellipsoidal"), lidar_h_ft,
                               HeightFrame("ellipsoidal", 0.3048))
    np.testing.assert_allclose(same, [50.0, 60.0], atol=1e-9)
    lidar_H = np.array([52.0, 152.0])  # EGM96: h = H + 48
    dz = height_difference_m(dem_h, HeightFrame("ellipsoidal"), lidar_H, HeightFrame("egm96"),
                             [5.0, 5.0], [44.0, 44.0], geoid)
    np.testing.assert_allclose(dz, [50.0, 60.0], atol=1e-9)
    dz = height_difference_m(dem_h - 48.0, HeightFrame("egm96"), [100.0, 200.0],
                             HeightFrame("ellipsoidal"), [5.0, 5.0], [44.0, 44.0], geoid)
    np.testing.assert_allclose(dz, [50.0, 60.0], atol=1e-9)
    with pytest.raises(InputError, match="geoid"):
        height_difference_m(dem_h, HeightFrame("egm96"), dem_h, HeightFrame("ellipsoidal"))
    with pytest.raises(InputError, match="datum"):
        HeightFrame("navd88")


@pytest.mark.parametrize("transform", [
    (2.0, 0.0, 500_000.0, 0.0, -2.0, 4_900_000.0),
    (0.5, 0.1, 10.0, 0.2, -0.4, 46.0),  # rotated
])
def test_affine_nodes_agree_with_the_affine_library(transform):
    x = np.array([500_003.0, 500_101.0, 10.3, 11.0])
    y = np.array([4_899_995.0, 4_899_900.0, 45.7, 45.1])
    fi, fj = affine_nodes(transform, x, y)
    col, row = ~Affine(*transform) * (x, y)
    np.testing.assert_allclose(fj, np.asarray(col) - 0.5, atol=1e-9)
    np.testing.assert_allclose(fi, np.asarray(row) - 0.5, atol=1e-9)


def test_window_groups_cover_the_points_and_sample_as_the_whole_grid():
    rng = np.random.default_rng(8)
    z = rng.normal(size=(300, 410))
    z[100:103, 50:60] = np.nan
    fi = rng.uniform(-5, 305, 3000)
    fj = rng.uniform(-5, 415, 3000)
    whole = sample_bilinear(z, fi, fj)
    groups = window_groups(fi, fj, z.shape, tile_cells=64)
    assert len(groups) > 10
    got = np.full(fi.size, np.nan)
    seen = np.zeros(fi.size, int)
    for g in groups:
        assert g.row1 - g.row0 <= 66 and g.col1 - g.col0 <= 66
        got[g.index] = sample_bilinear(z[g.row0:g.row1, g.col0:g.col1], fi[g.index] - g.row0,
                                       fj[g.index] - g.col0)
        seen[g.index] += 1
    inside = inside_grid(fi, fj, z.shape)
    assert (seen == inside).all()
    np.testing.assert_array_equal(got, whole)  # NaN off the grid and next to the void


def test_nearest_cells_and_their_windows():
    grid = np.arange(12).reshape(3, 4)
    fi = np.array([0.0, -0.49, 2.49, 1.51, -0.51, 1.0])
    fj = np.array([0.0, 3.49, -0.5, 2.2, 0.0, 3.6])
    np.testing.assert_array_equal(sample_nearest(grid, fi, fj, -1), [0, 3, 8, 10, -1, -1])
    got = np.full(fi.size, -1)
    for g in window_groups(fi, fj, grid.shape, nearest=True):
        got[g.index] = sample_nearest(grid[g.row0:g.row1, g.col0:g.col1], fi[g.index] - g.row0,
                                      fj[g.index] - g.col0, -1)
    np.testing.assert_array_equal(got, [0, 3, 8, 10, -1, -1])


def test_point_selection_and_code_counts():
    codes = np.array([1, 2, 7, 18, 5, 2])
    withheld = np.array([0, 0, 0, 0, 1, 0], bool)
    np.testing.assert_array_equal(select_points(codes, withheld), [1, 1, 0, 0, 0, 1])
    np.testing.assert_array_equal(select_points(codes, None, keep=(2, 7)), [0, 1, 1, 0, 0, 1])
    assert code_counts(np.array([[0, 1], [2, 2]]), (0, 1, 2, 3)) == {0: 1, 1: 1, 2: 2, 3: 0}


def test_config_checks():
    for kw, match in [({"bin_m": 0}, "bin"), ({"range_m": 1e-4}, "range"),
                      ({"ci_level": 1.0}, "level"), ({"n_bootstrap": -1}, "n_bootstrap"),
                      ({"bin_m": 1e-6, "range_m": 1e3}, "too"), ({"exact_max_count": -1}, "exact")]:
        with pytest.raises(InputError, match=match):
            StatsConfig(**kw)


def _report() -> EvaluationReport:
    acc = ClassedDz(StatsConfig(n_bootstrap=50))
    acc.add(np.array([0.1, -0.2, 0.3, 0.05]), np.array([2, 2, 6, 6]))
    crs = CrsInfo("WGS 84 / UTM zone 31N", "EPSG:32631", "PROJCRS[...]")
    empty = DzAccumulator().stats()
    return EvaluationReport(
        dem=DemInfo("dsm.tif", crs, "ellipsoidal", "tag", "m", 1.0, "assumed", 10, 20,
                    (2.0, 0.0, 0.0, 0.0, -2.0, 40.0), (0.0, 0.0, 20.0, 40.0)),
        lidar=LidarInfo("p.laz", crs, "file", "metre", 1.0, "metre", 1.0, "vertical CRS",
                        "egm96", "CRS: EGM96 height", 4, "1.4", 6, (1.0, 2.0, 3.0, 4.0)),
        landcover=LandcoverInfo("lc.tif", crs, ((1, "bare_soil"), (2, "forest")), "tags", 0),
        classes_from="landcover", class_filter=(2, 6), heights_compared="ellipsoidal",
        transformation="noop",
        points=PointCounts(4, 4, 0, 0, 0, 0, 4),
        classes={str(k): v for k, v in acc.class_stats().items()}, class_labels={"2": "", "6": ""},
        all=acc.overall(), stats_config=StatsConfig(n_bootstrap=50),
        mask=MaskSummary("m.tif", 8, 1, 1, 0, 10.0, 10.0),
        gcps=GcpCheck("g.json", 3, 1, empty),
    )


def test_report_round_trips_through_json():
    report = _report()
    d = json.loads(report.to_json())
    assert set(d["classes"]) == {"2", "6"}
    for s in (*d["classes"].values(), d["all"]):
        assert {"count", "mean", "std", "rmse", "nmad", "le68", "le90", "le68_ci"} <= set(s)
    assert d["gcps"]["rms_m"] is None and d["gcps"]["stats"]["mean"] is None  # NaN -> null
    back = EvaluationReport.from_dict(d)
    assert json.loads(back.to_json()) == d
    assert back.classes["2"] == report.classes["2"] and back.dem == report.dem
    with pytest.raises(InputError, match="evaluation report"):
        EvaluationReport.from_dict({"format": "other"})
