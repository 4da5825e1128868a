"""Accuracy of a DEM against reference points (lidar): statistics of ``dz = DEM - reference``.

Step 6 of the chain (Toutin's evaluation): per class and overall, the count, the mean (bias),
the sample standard deviation, the RMSE, the median, the NMAD (:mod:`core.robust`),
LE68 / LE90 / LE95 (68th / 90th / 95th percentile of ``|dz|``) and a bootstrap confidence
interval on LE68. Every figure is in metres. Percentiles follow NumPy's default ("linear")
definition.

Streaming. Points arrive in chunks (a lidar file of 100 M points never loads whole), and the
statistics are accumulated chunk by chunk in bounded memory (:class:`DzAccumulator`):

- count, mean, std, RMSE, min and max are exact whatever the size: running mean and sum of
  squared deviations merged with Chan's formula;
- the order statistics (median, NMAD, LE68/LE90/LE95 and the LE68 interval) are exact while a
  class holds at most ``StatsConfig.exact_max_count`` values (default 1 M, 8 MB of float64),
  which are kept; beyond that the accumulator switches, once and for good, to a histogram of
  ``bin_m`` (default 1 mm) over ``+-range_m`` (default 500 m; 8 MB of counts), plus one
  under- and one overflow bin represented by the exact min and max. Percentiles from the
  histogram are within ``bin_m / 2`` of the exact ones, the NMAD within ``1.5 bin_m``.

  A histogram rather than the float32 values of every point: 100 M points would need 400 MB
  per pass and an exact sort of them, while 1 mm is far below any DEM's accuracy and the
  memory stays flat whatever the file size.

The LE68 interval is a seeded percentile bootstrap computed without resampling the data: a
resample of ``n`` points from the empirical distribution ``F`` has its ``k``-th order
statistic distributed as ``F^-1(U_(k))`` with ``U_(k) ~ Beta(k, n + 1 - k)``, so each bootstrap
replicate of a percentile costs two random draws, exact in distribution, for any ``n``.

What ``eval.json`` holds and the bookkeeping of the points (which are evaluated, where the
others went) are :mod:`core.evaluation.evaluation_report`. No I/O here: ``tasks.evaluation.lidar``
reads the points and the DEM and calls these functions; heights are brought to metres and one datum
by :mod:`core.heights`, points placed on the DEM's grid by :mod:`core.grid_points`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.errors import InputError
from core.robust import NMAD_FACTOR

FloatArray = NDArray[np.float64]

# ---------------------------------------------------------------------------- configuration


@dataclass(frozen=True)
class StatsConfig:
    """How the statistics are accumulated (see the module docstring).

    ``bin_m`` and ``range_m``: histogram used beyond ``exact_max_count`` values per class;
    ``ci_level`` the two-sided level of the LE68 interval, from ``n_bootstrap`` replicates
    drawn with ``seed`` (``n_bootstrap = 0``: no interval).
    """

    bin_m: float = 0.001
    range_m: float = 500.0
    exact_max_count: int = 1_000_000
    ci_level: float = 0.95
    n_bootstrap: int = 1000
    seed: int = 0

    def __post_init__(self) -> None:
        if not (self.bin_m > 0 and math.isfinite(self.bin_m)):
            raise InputError(f"histogram bin must be a positive number of metres, got {self.bin_m}")
        if not (self.range_m >= self.bin_m and math.isfinite(self.range_m)):
            raise InputError(f"histogram range {self.range_m} m must be finite and at least one "
                             f"bin ({self.bin_m} m)")
        if self.range_m / self.bin_m > 5e7:
            raise InputError(f"histogram of {self.range_m / self.bin_m:.3g} bins per side is too "
                             "large; widen bin_m or narrow range_m")
        if self.exact_max_count < 0:
            raise InputError(f"exact_max_count must be >= 0, got {self.exact_max_count}")
        if not 0.0 < self.ci_level < 1.0:
            raise InputError(f"confidence level must be in (0, 1), got {self.ci_level}; "
                             "e.g. 0.95")
        if self.n_bootstrap < 0:
            raise InputError(f"n_bootstrap must be >= 0, got {self.n_bootstrap}")
        if self.seed < 0:
            raise InputError(f"seed must be >= 0, got {self.seed}")

    @property
    def half_bins(self) -> int:
        """Regular bins on each side of zero."""
        return round(self.range_m / self.bin_m)


# ---------------------------------------------------------------------------- results


@dataclass(frozen=True)
class DzStats:
    """Statistics of ``dz = DEM - reference`` for one class (metres; NaN when undefined).

    ``std_m`` is the sample standard deviation (n - 1); ``le68_ci_m`` the bootstrap interval
    of ``le68_m`` at ``ci_level``. ``method`` is ``"exact"`` or ``"histogram"``, the order
    statistics of the latter being within ``resolution_m`` (half a bin) of the exact ones.
    """

    count: int
    mean_m: float
    std_m: float
    rmse_m: float
    median_m: float
    nmad_m: float
    le68_m: float
    le90_m: float
    le95_m: float
    min_m: float
    max_m: float
    le68_ci_m: tuple[float, float]
    ci_level: float
    method: str
    resolution_m: float

    #: eval.json's keys of the ``*_m`` fields (:data:`tasks.io.products.EVALUATION`)
    KEYS = ("mean", "std", "rmse", "median", "nmad", "le68", "le90", "le95", "min", "max")


# ---------------------------------------------------------------------------- order statistics


@dataclass(frozen=True, eq=False)
class _Sample:
    """A sorted sample, each value once (``cum`` None) or with counts (``cum`` cumulative)."""

    values: FloatArray
    cum: NDArray[np.int64] | None = None

    @property
    def n(self) -> int:
        return int(self.values.size if self.cum is None else (self.cum[-1] if self.cum.size
                                                               else 0))

    def order_stat(self, k: ArrayLike) -> FloatArray:
        """The ``k``-th smallest value (0-based; an array of ranks works)."""
        k = np.asarray(k, dtype=np.int64)
        if self.cum is None:
            return self.values[k]
        return self.values[np.searchsorted(self.cum, k, side="right")]

    def quantile(self, p: float) -> float:
        """NumPy's default ("linear") percentile ``p`` in [0, 1]; NaN when empty."""
        n = self.n
        if n == 0:
            return math.nan
        h = (n - 1) * p
        k = math.floor(h)
        g = h - k
        lo = float(self.order_stat(k))
        if g == 0.0 or k + 1 >= n:
            return lo
        return lo + g * (float(self.order_stat(k + 1)) - lo)

    def inverse_cdf(self, u: FloatArray) -> FloatArray:
        """``F^-1(u)`` of the empirical distribution, ``u`` in (0, 1]."""
        k = np.clip(np.ceil(self.n * np.asarray(u)) - 1, 0, self.n - 1)
        return self.order_stat(k)

    def deviations(self, centre: float) -> _Sample:
        """The sorted sample of ``|value - centre|`` with the same counts."""
        d = np.abs(self.values - centre)
        order = np.argsort(d, kind="stable")
        if self.cum is None:
            return _Sample(d[order])
        counts = np.diff(self.cum, prepend=0)
        return _Sample(d[order], np.cumsum(counts[order]))


def bootstrap_quantile_ci(sample: _Sample, p: float, level: float, n_boot: int,
                          seed: int) -> tuple[float, float]:
    """Percentile-bootstrap interval at ``level`` of the ``p`` quantile of ``sample``.

    Each replicate is the quantile of a resample of ``n`` values drawn with replacement;
    it is drawn from the order-statistic representation (module docstring), exact in
    distribution. ``(nan, nan)`` for fewer than 2 values or no replicates.
    """
    n = sample.n
    if n < 2 or n_boot == 0:
        return (math.nan, math.nan)
    rng = np.random.default_rng(seed)
    h = (n - 1) * p
    k = math.floor(h)  # 0-based rank: the (k+1)-th smallest of n
    g = h - k
    u_k = rng.beta(k + 1, n - k, size=n_boot)
    reps = sample.inverse_cdf(u_k)
    if g > 0.0 and k + 1 < n:
        # the next order statistic: the smallest of the n-k-1 uniforms above u_k
        v = rng.random(n_boot)
        u_next = u_k + (1.0 - u_k) * -np.expm1(np.log(v) / (n - k - 1))
        reps = reps + g * (sample.inverse_cdf(u_next) - reps)
    a = 0.5 * (1.0 - level)
    lo, hi = np.quantile(reps, [a, 1.0 - a])
    return (float(lo), float(hi))


# ---------------------------------------------------------------------------- accumulation


class DzAccumulator:
    """Streaming statistics of height differences of one class, in bounded memory.

    ``add`` chunks of finite dz (metres) in any order and size; ``merge`` another accumulator
    (chunks processed apart); ``stats`` the result. Chunking does not change the result
    beyond floating-point rounding of the mean and std (module docstring).
    """

    def __init__(self, config: StatsConfig | None = None) -> None:
        self.config = config or StatsConfig()
        self.count = 0
        self._mean = 0.0
        self._m2 = 0.0  # sum of squared deviations from the mean
        self._min = math.inf
        self._max = -math.inf
        self._values: list[FloatArray] | None = []  # exact values while few enough
        self._hist: NDArray[np.int64] | None = None

    @property
    def is_exact(self) -> bool:
        return self._values is not None

    def add(self, dz_m: ArrayLike) -> None:
        """Accumulate a chunk of height differences (metres, all finite)."""
        dz = np.asarray(dz_m, dtype=np.float64).ravel()
        if dz.size == 0:
            return
        if not np.isfinite(dz).all():
            raise InputError("height differences must be finite; drop the points without a DEM "
                             "value (NaN) before accumulating them")
        m = float(dz.mean())
        self._combine(dz.size, m, float(np.square(dz - m).sum()), float(dz.min()),
                      float(dz.max()))
        if self._values is not None:
            self._values.append(dz.copy())
            self._maybe_switch()
        else:
            self._bin(dz)

    def merge(self, other: DzAccumulator) -> None:
        """Add everything ``other`` accumulated (same configuration) to this accumulator."""
        if other.config != self.config:
            raise InputError("cannot merge accumulators of different StatsConfig")
        if other.count == 0:
            return
        self._combine(other.count, other._mean, other._m2, other._min, other._max)
        if self._values is not None and other._values is not None:
            self._values.extend(other._values)
            self._maybe_switch()
            return
        self._to_histogram()
        assert self._hist is not None
        if other._values is not None:
            for v in other._values:
                self._bin(v)
        else:
            self._hist += other._hist

    def _combine(self, n_b: int, mean_b: float, m2_b: float, min_b: float, max_b: float) -> None:
        n_a = self.count
        n = n_a + n_b
        delta = mean_b - self._mean
        self._mean += delta * n_b / n
        self._m2 += m2_b + delta * delta * n_a * n_b / n
        self.count = n
        self._min = min(self._min, min_b)
        self._max = max(self._max, max_b)

    def _maybe_switch(self) -> None:
        if self.count > self.config.exact_max_count:
            self._to_histogram()

    def _to_histogram(self) -> None:
        if self._hist is not None:
            return
        self._hist = np.zeros(2 * self.config.half_bins + 2, dtype=np.int64)
        values, self._values = self._values or [], None
        for v in values:
            self._bin(v)

    def _bin(self, dz: FloatArray) -> None:
        """Histogram counts: index 0 underflow, 1..2K bins [j w, (j+1) w) for j = -K..K-1,
        2K+1 overflow."""
        K = self.config.half_bins
        j = np.clip(np.floor(dz / self.config.bin_m), -K - 1, K).astype(np.int64) + K + 1
        assert self._hist is not None
        self._hist += np.bincount(j, minlength=self._hist.size)

    def _sample(self) -> _Sample:
        if self._values is not None:
            return _Sample(np.sort(np.concatenate(self._values)) if self._values
                           else np.zeros(0))
        assert self._hist is not None
        K, w = self.config.half_bins, self.config.bin_m
        nz = np.flatnonzero(self._hist)
        centres = (nz - K - 0.5) * w
        centres[nz == 0] = self._min
        centres[nz == 2 * K + 1] = self._max
        return _Sample(centres, np.cumsum(self._hist[nz]))

    def stats(self) -> DzStats:
        """The statistics of everything accumulated so far."""
        cfg = self.config
        n = self.count
        exact = self.is_exact
        method, res = ("exact", 0.0) if exact else ("histogram", 0.5 * cfg.bin_m)
        if n == 0:
            nan = math.nan
            return DzStats(0, nan, nan, nan, nan, nan, nan, nan, nan, nan, nan, (nan, nan),
                           cfg.ci_level, method, res)
        sample = self._sample()
        median = sample.quantile(0.5)
        abs_dz = sample.deviations(0.0)
        return DzStats(
            count=n, mean_m=self._mean,
            std_m=math.sqrt(self._m2 / (n - 1)) if n > 1 else math.nan,
            rmse_m=math.sqrt(self._mean ** 2 + self._m2 / n),
            median_m=median, nmad_m=NMAD_FACTOR * sample.deviations(median).quantile(0.5),
            le68_m=abs_dz.quantile(0.68), le90_m=abs_dz.quantile(0.90),
            le95_m=abs_dz.quantile(0.95), min_m=self._min, max_m=self._max,
            le68_ci_m=bootstrap_quantile_ci(abs_dz, 0.68, cfg.ci_level, cfg.n_bootstrap,
                                            cfg.seed),
            ci_level=cfg.ci_level, method=method, resolution_m=res,
        )


class ClassedDz:
    """One :class:`DzAccumulator` per class code, and the overall statistics."""

    def __init__(self, config: StatsConfig | None = None) -> None:
        self.config = config or StatsConfig()
        self._by_code: dict[int, DzAccumulator] = {}

    @property
    def codes(self) -> list[int]:
        return sorted(self._by_code)

    @property
    def count(self) -> int:
        return sum(a.count for a in self._by_code.values())

    def add(self, dz_m: ArrayLike, codes: ArrayLike) -> None:
        """Accumulate ``dz_m`` (metres, finite) split by the integer class ``codes``."""
        dz = np.asarray(dz_m, dtype=np.float64).ravel()
        codes = np.asarray(codes).ravel()
        if codes.shape != dz.shape:
            raise InputError(f"{dz.size} height differences but {codes.size} class codes")
        if dz.size == 0:
            return
        order = np.argsort(codes, kind="stable")
        uniq, start = np.unique(codes[order], return_index=True)
        for code, part in zip(uniq.tolist(), np.split(order, start[1:]), strict=True):
            self._by_code.setdefault(int(code), DzAccumulator(self.config)).add(dz[part])

    def merge(self, other: ClassedDz) -> None:
        for code, acc in other._by_code.items():
            self._by_code.setdefault(code, DzAccumulator(self.config)).merge(acc)

    def class_stats(self) -> dict[int, DzStats]:
        return {code: self._by_code[code].stats() for code in self.codes}

    def overall(self) -> DzStats:
        total = DzAccumulator(self.config)
        for code in self.codes:
            total.merge(self._by_code[code])
        return total.stats()
