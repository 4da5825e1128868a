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
from core.simulation.hashing import derive_seed, hash_u64, hash_uniform

__all__ = [
    "broadcast_xy",
    "cell_uniform",
    "fbm",
    "fbm_threshold",
    "floor_index",
    "fractal_detail_m",
    "gradient_noise",
]

_N_GRAD = 16
_ANGLES = (np.arange(_N_GRAD) + 0.5) * (2.0 * np.pi / _N_GRAD)
_GX = np.cos(_ANGLES)
_GY = np.sin(_ANGLES)
_S60 = np.uint64(60)
_CORNERS = ((0, 0), (1, 0), (0, 1), (1, 1))
_SQRT2 = float(np.sqrt(2.0))


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


def _fade(t: NDArray[np.float64]) -> NDArray[np.float64]:
    """Quintic fade 6t^5 - 15t^4 + 10t^3 (zero first and second derivative at 0 and 1)."""
    return t * t * t * (t * (t * 6.0 - 15.0) + 10.0)


def _node_gradients(seed: int, i: NDArray[np.int64],
                    j: NDArray[np.int64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Unit gradient (gx, gy) of lattice node (i, j): one of 16 directions, chosen by the hash."""
    k = (hash_u64(seed, i, j) >> _S60).astype(np.intp)
    return _GX[k], _GY[k]


def _corner_gradients(seed: int, i0: NDArray[np.int64], j0: NDArray[np.int64]
                      ) -> list[tuple[NDArray[np.float64], NDArray[np.float64]]]:
    """Gradients at the four corners (00, 10, 01, 11) of the cells whose low corner is (i0, j0).

    When the cells share nodes (coarse octaves), the nodes of the bounding box
    are hashed once and looked up; the values are the same hashes either way.
    """
    if i0.size == 0:
        empty = np.zeros(i0.shape)
        return [(empty, empty)] * 4
    imin, imax = int(i0.min()), int(i0.max()) + 1
    jmin, jmax = int(j0.min()), int(j0.max()) + 1
    ni, nj = imax - imin + 1, jmax - jmin + 1
    if ni * nj > 2 * i0.size:
        return [_node_gradients(seed, i0 + di, j0 + dj) for di, dj in _CORNERS]
    gi = np.arange(imin, imax + 1, dtype=np.int64)
    gj = np.arange(jmin, jmax + 1, dtype=np.int64)
    gx, gy = _node_gradients(seed, gi[None, :], gj[:, None])
    gx = gx.reshape(-1)
    gy = gy.reshape(-1)
    lin = (j0 - jmin) * ni + (i0 - imin)
    return [(gx.take(lin + (dj * ni + di)), gy.take(lin + (dj * ni + di)))
            for di, dj in _CORNERS]


def _lattice_noise(u: NDArray[np.float64], v: NDArray[np.float64],
                   seed: int) -> NDArray[np.float64]:
    """Gradient noise at lattice coordinates (u, v); values in [-1, 1], NaN where not finite."""
    bad = ~(np.isfinite(u) & np.isfinite(v))
    if bad.any():
        u = np.where(bad, np.nan, u)
        v = np.where(bad, np.nan, v)
    fu = np.floor(u)
    fv = np.floor(v)
    xf = u - fu
    yf = v - fv
    (gx00, gy00), (gx10, gy10), (gx01, gy01), (gx11, gy11) = _corner_gradients(
        seed, floor_index(fu), floor_index(fv))
    xf1 = xf - 1.0
    yf1 = yf - 1.0
    n00 = gx00 * xf + gy00 * yf
    n10 = gx10 * xf1 + gy10 * yf
    n01 = gx01 * xf + gy01 * yf1
    n11 = gx11 * xf1 + gy11 * yf1
    sx = _fade(xf)
    sy = _fade(yf)
    a = n00 + sx * (n10 - n00)
    b = n01 + sx * (n11 - n01)
    return (a + sy * (b - a)) * _SQRT2


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
    ox = float(hash_uniform(derive_seed(seed, "offset-x")))
    oy = float(hash_uniform(derive_seed(seed, "offset-y")))
    return _lattice_noise(x / wavelength_m + ox, y / wavelength_m + oy, seed)


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
    total = np.zeros(x.shape, dtype=np.float64)
    weight_sum = 0.0
    for k in range(int(octaves)):
        w = persistence**k
        total += w * gradient_noise(x, y, derive_seed(seed, "fbm-octave", k),
                                    base_wavelength_m / lacunarity**k)
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
    total = np.zeros(x.shape, dtype=np.float64)
    for k, (wl, w) in enumerate(zip(wavelengths, weights, strict=True)):
        total += (w * norm) * gradient_noise(x, y, derive_seed(seed, "detail-octave", k), wl)
    return total


def cell_uniform(x_m: ArrayLike, y_m: ArrayLike, seed: int, cell_m: float) -> NDArray[np.float64]:
    """Piecewise-constant uniform [0, 1) field: one hashed value per square cell of ``cell_m``.

    Cells are ``[i*cell_m, (i+1)*cell_m) x [j*cell_m, (j+1)*cell_m)`` in the ground frame.
    """
    _check_positive(cell_m=cell_m)
    x, y = broadcast_xy(x_m, y_m)
    u = hash_uniform(seed, floor_index(x / cell_m), floor_index(y / cell_m))
    return np.where(np.isfinite(x) & np.isfinite(y), u, np.nan)
