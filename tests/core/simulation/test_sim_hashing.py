"""Counter-based hashing: reference values, determinism, distributions, scalar safety."""

from __future__ import annotations

import numpy as np
import pytest

from core.errors import InputError
from core.simulation.hashing import derive_seed, hash_normal, hash_u64, hash_uniform

M64 = (1 << 64) - 1
G = 0x9E3779B97F4A7C15


def _mix_py(z: int) -> int:
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & M64
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & M64
    return z ^ (z >> 31)


def _hash_py(seed: int, *keys: int) -> int:
    """Reference implementation with Python integers (no NumPy)."""
    h = _mix_py((seed + G) & M64)
    for n, k in enumerate(keys, start=1):
        h = _mix_py(h ^ ((k + G * n) & M64))
    return h


@pytest.mark.parametrize("seed, keys", [(0, ()), (1, (2, 3)), (42, (-7, 10**12, 5)),
                                         (2**64 - 1, (0,)), (-3, (1, -1))])
def test_hash_matches_pure_python_reference(seed: int, keys: tuple[int, ...]) -> None:
    got = hash_u64(seed, *keys)
    assert got.shape == ()
    assert int(got) == _hash_py(seed & M64, *(k & M64 for k in keys))


def test_scalar_and_array_inputs_raise_no_overflow_warning() -> None:
    # pyproject turns warnings into errors: wrapping uint64 maths must stay silent
    hash_u64(np.uint64(2**63), np.int64(-1), 3)
    hash_uniform(7, np.int64(2**62))
    hash_normal(7, 1, 2)
    hash_u64(5, np.arange(-5, 5), np.arange(10, dtype=np.uint32))


def test_broadcasting_and_elementwise_equality() -> None:
    i = np.arange(-20, 20)[None, :]
    j = np.arange(7)[:, None]
    grid = hash_u64(9, i, j)
    assert grid.shape == (7, 40)
    assert int(grid[3, 5]) == int(hash_u64(9, -15, 3))


def test_determinism_and_seed_sensitivity() -> None:
    k = np.arange(10_000)
    a = hash_uniform(11, k)
    assert a.tobytes() == hash_uniform(11, k).tobytes()
    b = hash_uniform(12, k)
    assert np.mean(a == b) < 1e-3
    assert np.mean(hash_uniform(11, k, 0) == hash_uniform(11, k, 1)) < 1e-3


def test_uniform_distribution() -> None:
    u = hash_uniform(3, np.arange(200_000), 17)
    assert u.min() >= 0.0 and u.max() < 1.0
    assert abs(u.mean() - 0.5) < 0.005
    counts, _ = np.histogram(u, bins=20, range=(0, 1))
    assert np.all(np.abs(counts / 10_000 - 1.0) < 0.05)
    # neighbouring keys are uncorrelated
    assert abs(np.corrcoef(u[:-1], u[1:])[0, 1]) < 0.01


def test_normal_distribution() -> None:
    z = hash_normal(5, np.arange(200_000))
    assert abs(z.mean()) < 0.01
    assert abs(z.std() - 1.0) < 0.01
    assert abs(np.mean(np.abs(z) < 1.0) - 0.6827) < 0.005
    assert np.all(np.isfinite(z))


def test_normal_independent_of_array_layout() -> None:
    k = np.arange(100_003)
    whole = hash_normal(2, k)
    parts = np.concatenate([hash_normal(2, k[:13]), hash_normal(2, k[13:1000]),
                            hash_normal(2, k[1000:])])
    strided = hash_normal(2, k[::-1])[::-1]
    assert whole.tobytes() == parts.tobytes() == strided.tobytes()


def test_bad_keys_and_seed_are_refused() -> None:
    with pytest.raises(InputError, match="integer"):
        hash_u64(1, np.array([0.5]))
    with pytest.raises(InputError, match="seed"):
        hash_u64(1.5, 1)  # type: ignore[arg-type]


def test_derive_seed_is_stable_and_distinct() -> None:
    assert derive_seed(1, "a") == derive_seed(1, "a")
    assert len({derive_seed(1, "a"), derive_seed(1, "b"), derive_seed(2, "a"),
                derive_seed(1, "a", 0)}) == 4
    assert 0 <= derive_seed(-1, "x") < 2**64
