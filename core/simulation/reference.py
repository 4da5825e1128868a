"""An SRTM-like reference DEM of a simulated world: the bare terrain as SRTM would have measured
it, so that GCP-free orientation is never tested against the truth itself.

SRTM differs from the world by (Rodriguez et al. 2006; Farr et al. 2007): a posting of 3"
(no detail finer than ~90 m), spatially correlated height errors of a few metres (long
wavelength: the mission's attitude and baseline errors, short: speckle and slope effects),
a planimetric misregistration of a few metres, voids on steep slopes (radar shadow and
layover), and no canopy (the C band reaches partly into the trees; the bare terrain is the
simpler, harder stand-in). :func:`srtm_like` applies these to heights sampled by the caller
at shifted node positions.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.errors import InputError
from core.simulation.fields import fractal_detail_m
from core.simulation.hashing import derive_seed, hash_uniform

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class ReferenceErrors:
    """How the reference differs from the world: correlated height noise (``noise_m`` standard
    deviation, wavelengths from ``correlation_m`` to 8 times it), misregistration
    (``shift_east_m``, ``shift_north_m``: the reference shows the terrain moved by that much),
    and voids on ``void_share`` of the slopes steeper than ``void_slope_deg``."""

    noise_m: float = 4.5
    correlation_m: float = 300.0
    shift_east_m: float = 0.0
    shift_north_m: float = 0.0
    void_slope_deg: float = 35.0
    void_share: float = 0.5

    def __post_init__(self) -> None:
        if not (self.noise_m >= 0 and self.correlation_m > 0 and 0 < self.void_slope_deg <= 90
                and 0 <= self.void_share <= 1):
            raise InputError("reference errors: need noise_m >= 0, correlation_m > 0, "
                             "0 < void_slope_deg <= 90 and 0 <= void_share <= 1")

    @classmethod
    def drawn(cls, seed: int, max_shift_m: float = 5.0, **kw: float) -> ReferenceErrors:
        """Errors with a misregistration drawn from ``seed`` (uniform direction, magnitude up
        to ``max_shift_m``)."""
        u = hash_uniform(derive_seed(seed, "reference-shift"), np.arange(2))
        angle, size = 2 * np.pi * float(u[0]), max_shift_m * float(u[1])
        return cls(shift_east_m=size * np.sin(angle), shift_north_m=size * np.cos(angle), **kw)


def srtm_like(terrain_m: ArrayLike, x_m: ArrayLike, y_m: ArrayLike, slope_deg: ArrayLike,
              seed: int, errors: ReferenceErrors) -> FloatArray:
    """Reference heights at nodes: ``terrain_m`` (the world's bare terrain sampled by the
    caller at the node positions moved by the misregistration), plus correlated noise (a
    function of the nodes' projected ``x_m``, ``y_m``), with voids (NaN) on steep slopes."""
    h = np.asarray(terrain_m, dtype=np.float64)
    x, y = np.broadcast_arrays(np.asarray(x_m, dtype=np.float64), np.asarray(y_m, dtype=np.float64))
    noise = fractal_detail_m(x, y, derive_seed(seed, "reference-noise"), errors.noise_m,
                             errors.correlation_m, 8.0 * errors.correlation_m, 0.9) \
        if errors.noise_m > 0 else 0.0
    cell = np.floor(x / errors.correlation_m).astype(np.int64), \
        np.floor(y / errors.correlation_m).astype(np.int64)
    steep = np.asarray(slope_deg, dtype=np.float64) > errors.void_slope_deg
    holes = steep & (hash_uniform(derive_seed(seed, "reference-voids"), *cell) < errors.void_share)
    return np.where(holes, np.nan, h + noise)
