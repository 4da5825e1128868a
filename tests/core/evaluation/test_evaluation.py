"""Accuracy statistics of dz: against NumPy (exact path) and within the bin width (histogram
path), streaming in chunks, the bootstrap interval against brute-force resampling, the
bookkeeping of a run (point tally, class names, mask and GCP checks) and the report's JSON
round trip."""

import json
import math

import numpy as np
import pytest

from core.errors import InputError
from core.evaluation.evaluation import ClassedDz, DzAccumulator, DzStats, StatsConfig
from core.evaluation.evaluation_report import (
    NO_CODE,
    NO_LANDCOVER,
    CrsInfo,
    DemInfo,
    EvaluationReport,
    GcpCheck,
    LandcoverInfo,
    LidarInfo,
    MaskSummary,
    PointCounts,
    PointTally,
    class_tables,
    code_counts,
    gcp_check,
    mask_summary,
    select_points,
)
from core.geoid import GeoidGrid
from core.heights import HeightFrame
from core.points import GeoPoint


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


def test_point_selection_and_code_counts():
    codes = np.array([1, 2, 7, 18, 5, 2])
    withheld = np.array([0, 0, 0, 0, 1, 0], bool)
    np.testing.assert_array_equal(select_points(codes, withheld), [1, 1, 0, 0, 0, 1])
    np.testing.assert_array_equal(select_points(codes, None, keep=(2, 7)), [0, 1, 1, 0, 0, 1])
    assert code_counts(np.array([[0, 1], [2, 2]]), (0, 1, 2, 3)) == {0: 1, 1: 1, 2: 2, 3: 0}


def test_point_tally_accounts_for_every_point():
    withheld = np.array([0, 1, 0, 0, 0, 0], bool)
    keep = np.array([1, 0, 0, 1, 1, 1], bool)  # class 7 at index 2
    inside = np.array([1, 1, 0, 1])  # over the 4 kept points
    valid = np.array([1, 0, 0, 1])
    tally = PointTally()
    tally.add(withheld, keep, inside, valid)
    tally.add(withheld[:2], keep[:2], inside[:1], valid[:1])
    c = tally.counts(in_file=10)
    assert c == PointCounts(in_file=10, read=8, withheld=2, excluded_class=1, outside_dem=1,
                            on_void=1, evaluated=3)
    assert c.read == c.withheld + c.excluded_class + c.outside_dem + c.on_void + c.evaluated


def test_class_tables_name_las_and_landcover_classes():
    s = DzAccumulator(StatsConfig(n_bootstrap=0)).stats()
    classes, labels = class_tables({2: s, 64: s}, None)
    assert list(classes) == ["2", "64"] and labels == {"2": "ground", "64": ""}
    classes, labels = class_tables({NO_CODE: s, 1: s, 3: s}, ((1, "bare_soil"), (2, "forest")))
    assert list(classes) == [NO_LANDCOVER, "bare_soil", "3"]
    assert set(labels.values()) == {""}


def test_mask_summary_over_blocks():
    blocks = [np.array([[0, 1], [2, 2]], np.uint8), np.array([[0, 0, 7, 0]], np.uint8)]
    m = mask_summary("m.tif", iter(blocks))
    assert (m.valid, m.mismatch, m.occluded_or_outside, m.other) == (4, 1, 2, 1)
    assert m.mismatched_pct == pytest.approx(12.5) and m.occluded_pct == pytest.approx(25.0)
    assert mask_summary("empty.tif", []).mismatched_pct == 0.0


def test_gcp_check_in_the_dem_datum():
    geoid = GeoidGrid(np.full((3, 3), 48.0), 43.0, 4.0, 1.0, 1.0)  # N = 48 m everywhere
    points = (GeoPoint(5.0, 44.0, 100.0), GeoPoint(5.1, 44.1, 200.0), GeoPoint(5.2, 44.2, 0.0))
    cfg = StatsConfig(n_bootstrap=0)
    g = gcp_check("g.json", points, [101.0, 202.0, np.nan], HeightFrame("ellipsoidal"), None,
                  cfg)
    assert (g.path, g.points, g.outside_dem, g.stats.count) == ("g.json", 3, 1, 2)
    assert g.stats.mean_m == pytest.approx(1.5)
    egm = gcp_check("g.json", points, [52.0, 152.0, np.nan], HeightFrame("egm96"), geoid, cfg)
    assert egm.stats.mean_m == pytest.approx(0.0, abs=1e-9)  # H = h - N exactly
    with pytest.raises(InputError, match="geoid"):
        gcp_check("g.json", points, [52.0, 152.0, 1.0], HeightFrame("egm96"), None, cfg)


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
    from core.jsonio import to_json
    from tasks.io.products import EVALUATION

    report = _report()
    d = json.loads(to_json(EVALUATION.dump(report)))
    assert set(d["classes"]) == {"2", "6"}
    for s in (*d["classes"].values(), d["all"]):
        assert {"count", "mean", "std", "rmse", "nmad", "le68", "le90", "le68_ci"} <= set(s)
    assert d["gcps"]["rms_m"] is None and d["gcps"]["stats"]["mean"] is None  # NaN -> null
    back = EVALUATION.load(d)
    assert json.loads(to_json(EVALUATION.dump(back))) == d
    assert back.classes["2"] == report.classes["2"] and back.dem == report.dem
    assert back.landcover == report.landcover and back.class_filter == (2, 6)
    with pytest.raises(InputError, match="eval.json: key 'format' is 'other'"):
        EVALUATION.load({"format": "other"})
