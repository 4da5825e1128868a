"""Counter-based random numbers: pure functions of a seed and integer keys.

The simulator never draws from a global random state. Every random quantity is
the hash of ``(seed, key_1, key_2, ...)`` where the keys are integers the caller
can recompute anywhere (lattice indices, image row and column, building block
indices). A tile of a scene can therefore be computed on its own and joins its
neighbours bit for bit: "same seed, same bytes".

The hash is the SplitMix64 finaliser (Steele, Lea & Flood 2014), applied once
per key so that each key avalanches into the running state::

    h_0     = mix(seed + G)
    h_{n+1} = mix(h_n ^ (key_n + G * (n + 1)))

with ``G = 0x9E3779B97F4A7C15`` and ``mix`` the three xor-shift-multiply rounds
of SplitMix64. All arithmetic is on ``uint64`` and wraps modulo 2**64 on
purpose. NumPy checks overflow only on scalar integer maths, so inputs are
worked on as 1-D arrays inside ``np.errstate(over="ignore")`` and no warning is
raised, for arrays or scalars alike.
"""

from __future__ import annotations

import hashlib
from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.errors import InputError

__all__ = ["derive_seed", "hash_normal", "hash_state", "hash_u64", "hash_uniform"]

_MASK64 = (1 << 64) - 1
_S11 = np.uint64(11)
_TWO_POW_M53 = 2.0**-53


def _as_key(a: ArrayLike) -> NDArray[np.uint64]:
    """An integer key array as uint64 (negative int64 wraps, two's complement)."""
    arr = np.asarray(a)
    if arr.dtype == np.bool_:
        arr = arr.astype(np.int64)
    if arr.dtype.kind == "u":
        return arr.astype(np.uint64)
    if arr.dtype.kind != "i":
        raise InputError(
            f"hash keys must be integer arrays (lattice indices, rows, cols), "
            f"got dtype {arr.dtype}; "
            "floor coordinates to integers first"
        )
    return arr.astype(np.int64).astype(np.uint64)


def _seed_u64(seed: int) -> np.uint64:
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)):
        raise InputError(f"seed must be an integer, got {seed!r}")
    return np.uint64(int(seed) & _MASK64)


def hash_u64(seed: int, *keys: ArrayLike) -> NDArray[np.uint64]:
    """64-bit hash of ``(seed, *keys)``, element-wise over the broadcast keys.

    Args:
        seed: any Python or NumPy integer (taken modulo 2**64).
        *keys: integer arrays (or scalars), broadcast together.

    Returns:
        uint64 array of the broadcast shape (0-d for scalar keys).
    """
    from core.simulation.field_kernels import hash_keys

    arrays = [_as_key(k) for k in keys]
    shape = np.broadcast_shapes(*(a.shape for a in arrays)) if arrays else ()
    n = int(np.prod(shape, dtype=np.int64))
    stacked = np.empty((len(arrays), n), dtype=np.uint64)
    for row, a in zip(stacked, arrays, strict=True):
        row[:] = np.broadcast_to(a, shape).reshape(n)
    return hash_keys(hash_state(seed), stacked.view(np.int64)).reshape(shape)


def hash_state(seed: int) -> np.uint64:
    """The hash's running state after ``seed`` alone (``mix(seed + G)``), where every key
    starts from."""
    from core.simulation.field_kernels import seed_state

    return np.uint64(seed_state(_seed_u64(seed)))


def hash_uniform(seed: int, *keys: ArrayLike) -> NDArray[np.float64]:
    """Uniform numbers in [0, 1) from the top 53 bits of :func:`hash_u64`.

    Same broadcasting as :func:`hash_u64`; float64 output (0-d for scalar keys).
    """
    h = hash_u64(seed, *keys)
    return (h >> _S11).astype(np.float64) * _TWO_POW_M53


def hash_normal(seed: int, *keys: ArrayLike) -> NDArray[np.float64]:
    """Standard normal numbers (mean 0, std 1) by Box-Muller on two hashed uniforms.

    The two uniforms come from the same keys under two derived seeds, so the
    result is again a pure function of ``(seed, *keys)``. ``u1`` is taken in
    (0, 1] so the logarithm is finite; the output is bounded by about 8.6.
    """
    u1 = 1.0 - hash_uniform(derive_seed(seed, "normal-radius"), *keys)
    u2 = hash_uniform(derive_seed(seed, "normal-angle"), *keys)
    shape = u1.shape
    # contiguous 1-D arrays so every element goes through the same libm/SIMD path
    u1 = np.ascontiguousarray(u1.reshape(-1))
    u2 = np.ascontiguousarray(u2.reshape(-1))
    r = np.sqrt(-2.0 * np.log(u1))
    return (r * np.cos((2.0 * np.pi) * u2)).reshape(shape)


@lru_cache(maxsize=4096)
def derive_seed(seed: int, *tags: str | int) -> int:
    """A new 64-bit seed for a named sub-stream of ``seed`` (stable across processes).

    Uses BLAKE2b of the seed and tags, never Python's randomised ``hash``, so a
    Dask worker derives the same sub-seed as the client.

    Example: ``derive_seed(seed, "forest-patches")``.
    """
    s = _seed_u64(seed)
    text = "|".join([str(int(s)), *(str(t) for t in tags)]).encode()
    return int.from_bytes(hashlib.blake2b(text, digest_size=8).digest(), "little")
