"""Procedural fields evaluated at arbitrary ground coordinates.

Everything here is a pure function of ``(x_m, y_m, seed, parameters)``, with
``x_m``, ``y_m`` easting and northing in metres of a local projected frame
(UTM, say). The noise lattice is anchored to that frame, not to a tile, so a
tile computed on its own equals the same window of the whole area bit for bit.
Only exactly rounded operations (+, -, *, /, floor, table look-ups) touch the
per-point values, so the result does not depend on array layout or SIMD path.

Gradient noise (Perlin 2002 "improved noise", 2-D): each lattice node gets one
of 16 unit gradients chosen by :func:`hash_u64` of its integer indices; the
value is the quintic-faded blend of the four corner ramps. It is zero on the
lattice nodes, lies in [-1, 1] after scaling by sqrt(2), and has a standard
deviation of about 0.3.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.errors import InputError
from core.simulation.hashing import derive_seed, hash_state, hash_uniform

__all__ = [
    "broadcast_xy",
    "cell_uniform",
    "fbm",
    "fbm_threshold",
    "floor_index",
    "fractal_detail_m",
    "gradient_noise",
]


def broadcast_xy(x_m: ArrayLike, y_m: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Ground coordinates as float64 arrays broadcast against each other."""
    x = np.asarray(x_m, dtype=np.float64)
    y = np.asarray(y_m, dtype=np.float64)
    x, y = np.broadcast_arrays(x, y)
    return x, y


def _check_positive(**values: float) -> None:
    for name, v in values.items():
        if not np.isfinite(v) or v <= 0:
            raise InputError(f"{name} must be a positive finite number, got {v!r}")


def floor_index(v: NDArray[np.float64]) -> NDArray[np.int64]:
    """``floor(v)`` as int64; non-finite values give an arbitrary index without a warning.

    Callers keep the NaN in their own arithmetic, so fields come out NaN (or
    False for masks) at non-finite coordinates instead of raising.
    """
    with np.errstate(invalid="ignore"):
        return np.floor(v).astype(np.int64)


def _octaves(x: NDArray[np.float64], y: NDArray[np.float64], seeds: list[int],
             wavelengths_m: list[float], coefs: list[float] | None) -> NDArray[np.float64]:
    """``sum_k coefs[k] * gradient_noise(x, y, seeds[k], wavelengths_m[k])``, added from 0 in
    the octaves' order, in one compiled pass (:func:`core.simulation.field_kernels.noise_sum`);
    ``coefs`` None: the single octave's noise itself."""
    from core.simulation import field_kernels as K

    states = np.array([hash_state(s) for s in seeds], dtype=np.uint64)
    off_x = np.array([hash_uniform(derive_seed(s, "offset-x")) for s in seeds])
    off_y = np.array([hash_uniform(derive_seed(s, "offset-y")) for s in seeds])
    out = K.noise_sum(np.ascontiguousarray(x).reshape(-1), np.ascontiguousarray(y).reshape(-1),
                      states, np.array(wavelengths_m, dtype=np.float64), off_x, off_y,
                      np.array(coefs if coefs is not None else [1.0], dtype=np.float64),
                      coefs is None, K.GX, K.GY)
    return out.reshape(x.shape)


def gradient_noise(x_m: ArrayLike, y_m: ArrayLike, seed: int,
                   wavelength_m: float) -> NDArray[np.float64]:
    """One octave of gradient noise with lattice spacing ``wavelength_m``.

    Args:
        x_m, y_m: ground coordinates in metres (broadcast together).
        seed: integer seed.
        wavelength_m: lattice spacing in metres (the feature size).

    Returns:
        float64 values in [-1, 1], mean 0, std about 0.3, shape of the broadcast inputs.
        A per-seed sub-lattice offset keeps the nodes off the frame origin.
    """
    _check_positive(wavelength_m=wavelength_m)
    x, y = broadcast_xy(x_m, y_m)
    return _octaves(x, y, [seed], [wavelength_m], None)


def _check_octaves(octaves: int, persistence: float, lacunarity: float) -> None:
    if isinstance(octaves, bool) or not isinstance(octaves, (int, np.integer)) or octaves < 1:
        raise InputError(f"octaves must be an integer >= 1, got {octaves!r}")
    _check_positive(persistence=persistence)
    if not np.isfinite(lacunarity) or lacunarity <= 1.0:
        raise InputError(f"lacunarity must be > 1 (each octave finer), got {lacunarity!r}")


def fbm(x_m: ArrayLike, y_m: ArrayLike, seed: int, base_wavelength_m: float, octaves: int,
        persistence: float = 0.5, lacunarity: float = 2.0) -> NDArray[np.float64]:
    """Fractional Brownian motion: a weighted sum of gradient-noise octaves.

    Octave ``k`` has wavelength ``base_wavelength_m / lacunarity**k``, weight
    ``persistence**k`` and its own derived seed. The sum is divided by the sum of
    the weights, so the result lies in [-1, 1] with mean 0 (std about 0.2-0.3,
    depending on ``persistence``). Use :func:`fbm_threshold` to turn an area
    fraction into a threshold.

    Args:
        x_m, y_m: ground coordinates in metres.
        seed: integer seed.
        base_wavelength_m: wavelength of the coarsest octave, metres.
        octaves: number of octaves (>= 1).
        persistence: amplitude ratio between successive octaves (> 0).
        lacunarity: wavelength ratio between successive octaves (> 1).
    """
    _check_positive(base_wavelength_m=base_wavelength_m)
    _check_octaves(octaves, persistence, lacunarity)
    x, y = broadcast_xy(x_m, y_m)
    weights = [persistence**k for k in range(int(octaves))]
    total = _octaves(x, y, [derive_seed(seed, "fbm-octave", k) for k in range(int(octaves))],
                     [base_wavelength_m / lacunarity**k for k in range(int(octaves))], weights)
    weight_sum = 0.0
    for w in weights:
        weight_sum += w
    return total / weight_sum


@lru_cache(maxsize=64)
def _reference_sample(octaves: int, persistence: float, lacunarity: float) -> NDArray[np.float64]:
    """Sorted fbm values on a fixed 400x400 grid spanning ~150 base wavelengths."""
    g = np.arange(400, dtype=np.float64) * 0.3731
    x, y = np.meshgrid(g, g)
    vals = fbm(x, y, 0x5EED, 1.0, octaves, persistence, lacunarity).reshape(-1)
    vals.sort()
    vals.setflags(write=False)
    return vals


def fbm_threshold(fraction: float, octaves: int, persistence: float = 0.5,
                  lacunarity: float = 2.0) -> float:
    """The value ``t`` such that ``fbm(...) > t`` covers about ``fraction`` of a large area.

    Calibrated once per (octaves, persistence, lacunarity) on a fixed reference
    sample, so it is a constant of the configuration, identical on every tile.
    ``fraction`` 0 gives +inf-like 2.0 (nothing), 1 gives -2.0 (everything).
    """
    if not 0.0 <= fraction <= 1.0:
        raise InputError(f"fraction must be in [0, 1], got {fraction!r}")
    _check_octaves(octaves, persistence, lacunarity)
    if fraction == 0.0:
        return 2.0
    if fraction == 1.0:
        return -2.0
    sample = _reference_sample(int(octaves), float(persistence), float(lacunarity))
    return float(np.quantile(sample, 1.0 - fraction))


@lru_cache(maxsize=1)
def _unit_noise_std() -> float:
    return float(np.std(_reference_sample(1, 0.5, 2.0)))


def fractal_detail_m(x_m: ArrayLike, y_m: ArrayLike, seed: int, amplitude_m: float,
                     min_wavelength_m: float, max_wavelength_m: float,
                     hurst: float) -> NDArray[np.float64]:
    """Terrain detail finer than a DEM cell: a power-law (fractal) height field.

    Octaves have wavelengths ``max_wavelength_m / 2**k`` down to
    ``min_wavelength_m`` (at least one octave), each with amplitude proportional
    to ``wavelength**hurst``, so the height spectrum follows a power law and the
    increments grow as ``lag**hurst`` between the two wavelengths. Set
    ``max_wavelength_m`` near the DEM cell size so the detail adds only what the
    DEM cannot show.

    Args:
        x_m, y_m: ground coordinates in metres.
        seed: integer seed.
        amplitude_m: standard deviation of the detail over a large area, metres.
        min_wavelength_m, max_wavelength_m: band of wavelengths, metres.
        hurst: Hurst exponent in (0, 1]; 0.7-0.9 looks like natural terrain.

    Returns:
        Heights in metres, mean about 0, std about ``amplitude_m``.
    """
    _check_positive(min_wavelength_m=min_wavelength_m, max_wavelength_m=max_wavelength_m)
    if amplitude_m < 0 or not np.isfinite(amplitude_m):
        raise InputError(f"amplitude_m must be >= 0 and finite, got {amplitude_m!r}")
    if min_wavelength_m > max_wavelength_m:
        raise InputError(
            f"min_wavelength_m ({min_wavelength_m}) must not exceed max_wavelength_m "
            f"({max_wavelength_m})"
        )
    if not 0.0 < hurst <= 1.0:
        raise InputError(f"hurst must be in (0, 1], got {hurst!r}")
    x, y = broadcast_xy(x_m, y_m)
    wavelengths = [max_wavelength_m]
    while wavelengths[-1] / 2.0 >= min_wavelength_m * (1.0 - 1e-9):
        wavelengths.append(wavelengths[-1] / 2.0)
    weights = [(wl / max_wavelength_m) ** hurst for wl in wavelengths]
    norm = amplitude_m / (_unit_noise_std() * float(np.sqrt(sum(w * w for w in weights))))
    return _octaves(x, y, [derive_seed(seed, "detail-octave", k) for k in range(len(wavelengths))],
                    wavelengths, [w * norm for w in weights])


def cell_uniform(x_m: ArrayLike, y_m: ArrayLike, seed: int, cell_m: float) -> NDArray[np.float64]:
    """Piecewise-constant uniform [0, 1) field: one hashed value per square cell of ``cell_m``.

    Cells are ``[i*cell_m, (i+1)*cell_m) x [j*cell_m, (j+1)*cell_m)`` in the ground frame.
    """
    from core.simulation import field_kernels as K

    _check_positive(cell_m=cell_m)
    x, y = broadcast_xy(x_m, y_m)
    u = K.cell_uniform(np.ascontiguousarray(x).reshape(-1), np.ascontiguousarray(y).reshape(-1),
                       hash_state(seed), float(cell_m))
    return u.reshape(x.shape)
