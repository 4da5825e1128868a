"""Geoid undulation grids (EGM96) as immutable values, interpolated bilinearly
(:func:`core.dem.sample_bilinear`).

No I/O here: ``tasks.io.geoid`` reads the GTX file and builds a :class:`GeoidGrid`.
Orthometric heights H (SRTM) become ellipsoidal heights with ``h = H + N``.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.dem import sample_bilinear
from core.errors import InputError


@dataclass(frozen=True, eq=False)
class GeoidGrid:
    """A regular lon/lat grid of geoid undulations N in metres.

    ``values_m[i, j]`` is N at latitude ``lat0_deg + i * dlat_deg`` and longitude
    ``lon0_deg + j * dlon_deg`` (row 0 at the south, as in GTX files). Grid nodes
    are the sample points. A grid spanning 360 degrees of longitude wraps.
    """

    values_m: NDArray[np.float64]
    lat0_deg: float
    lon0_deg: float
    dlat_deg: float
    dlon_deg: float
    name: str = "geoid"
    _global_lon: bool = field(init=False, repr=False)
    _nodes: NDArray[np.float64] = field(init=False, repr=False)

    def __post_init__(self) -> None:
        v = np.asarray(self.values_m, dtype=np.float64)
        if v.ndim != 2 or min(v.shape) < 2:
            raise InputError(
                f"geoid grid {self.name!r} must be a 2-D array of at least 2x2 nodes, got shape "
                f"{v.shape}; check the grid file header"
            )
        if not (self.dlat_deg > 0 and self.dlon_deg > 0):
            raise InputError(
                f"geoid grid {self.name!r} has non-positive spacing "
                f"(dlat={self.dlat_deg}, dlon={self.dlon_deg}); check the grid file header"
            )
        v.setflags(write=False)
        object.__setattr__(self, "values_m", v)
        span = v.shape[1] * self.dlon_deg
        object.__setattr__(self, "_global_lon", abs(span - 360.0) < 1e-9)
        # a global grid repeats its first column after the last, so the seam interpolates
        object.__setattr__(self, "_nodes", np.hstack([v, v[:, :1]]) if self._global_lon else v)

    @property
    def shape(self) -> tuple[int, int]:
        return self.values_m.shape  # type: ignore[return-value]

    @cached_property
    def _digest(self) -> str:
        return hashlib.blake2b(self.values_m.tobytes(), digest_size=16).hexdigest()

    def __dask_tokenize__(self) -> tuple:
        """A cheap, content-based token so Dask graphs don't rehash the grid for every block."""
        return ("GeoidGrid", self._digest, self.lat0_deg, self.lon0_deg, self.dlat_deg, self.dlon_deg)

    def undulation_m(self, lon_deg: ArrayLike, lat_deg: ArrayLike) -> NDArray[np.float64]:
        """Geoid undulation N (metres) at the given points, by bilinear interpolation.

        Longitudes are wrapped into the grid when it is global. Points outside a
        regional grid raise :class:`InputError`.
        """
        lon = np.asarray(lon_deg, dtype=np.float64)
        lat = np.asarray(lat_deg, dtype=np.float64)
        lon, lat = np.broadcast_arrays(lon, lat)
        nrows, ncols = self.shape
        fi = (lat - self.lat0_deg) / self.dlat_deg
        fj = (lon - self.lon0_deg) / self.dlon_deg
        if self._global_lon:
            fj = np.mod(fj, ncols)
        # clamp exactly-on-edge latitudes (the poles) to the last cell
        bad_lat = ~((fi >= -1e-9) & (fi <= nrows - 1 + 1e-9))
        bad_lon = (
            np.zeros_like(bad_lat) if self._global_lon else ~((fj >= -1e-9) & (fj <= ncols - 1 + 1e-9))
        )
        if np.any(bad_lat | bad_lon):
            k = int(np.argmax(bad_lat | bad_lon))
            raise InputError(
                f"point lon={lon.flat[k]:.6f} lat={lat.flat[k]:.6f} lies outside geoid grid "
                f"{self.name!r}; use a grid that covers the area"
            )
        fi = np.clip(fi, 0.0, nrows - 1)
        if not self._global_lon:
            fj = np.clip(fj, 0.0, ncols - 1)
        return sample_bilinear(self._nodes, fi, fj)

    def orthometric_to_ellipsoidal(
        self, lon_deg: ArrayLike, lat_deg: ArrayLike, H_m: ArrayLike
    ) -> NDArray[np.float64]:
        """h = H + N."""
        return np.asarray(H_m, dtype=np.float64) + self.undulation_m(lon_deg, lat_deg)

    def ellipsoidal_to_orthometric(
        self, lon_deg: ArrayLike, lat_deg: ArrayLike, h_m: ArrayLike
    ) -> NDArray[np.float64]:
        """H = h - N."""
        return np.asarray(h_m, dtype=np.float64) - self.undulation_m(lon_deg, lat_deg)
