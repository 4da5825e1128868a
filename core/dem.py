"""A DEM held in memory as an immutable value, sampled bilinearly in lon/lat.

Used by the sensor models to intersect lines of sight with the terrain. Heights
are WGS84 ellipsoidal metres (convert SRTM with the geoid first). No I/O here.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.ndimage import map_coordinates

from core.errors import InputError


def sample_bilinear(z: NDArray[np.floating], fi: ArrayLike, fj: ArrayLike) -> NDArray[np.float64]:
    """Bilinear value of grid ``z`` at fractional (row, col) indices; NaN outside the grid.

    Cells next to a NaN node give NaN (voids are not invented).
    """
    fi = np.asarray(fi, dtype=np.float64)
    fj = np.asarray(fj, dtype=np.float64)
    fi, fj = np.broadcast_arrays(fi, fj)
    nr, nc = np.shape(z)
    inside = (fi >= 0) & (fi <= nr - 1) & (fj >= 0) & (fj <= nc - 1)
    out = map_coordinates(np.asarray(z, dtype=np.float64), [fi.ravel(), fj.ravel()], order=1,
                          mode="nearest", prefilter=False).reshape(fi.shape)
    return np.where(inside, out, np.nan)


@dataclass(frozen=True, eq=False)
class GeoDEM:
    """Heights on a regular lon/lat grid; grid nodes are pixel centres.

    ``h_m[i, j]`` is the height at lon ``lon0_deg + j * dlon_deg`` and lat
    ``lat0_deg + i * dlat_deg``. For a north-up raster ``dlat_deg`` is negative
    and (lon0, lat0) is the centre of the top-left pixel. NaN marks voids.
    """

    h_m: NDArray[np.float64]
    lon0_deg: float
    lat0_deg: float
    dlon_deg: float
    dlat_deg: float

    def __post_init__(self) -> None:
        h = np.asarray(self.h_m, dtype=np.float64)
        if h.ndim != 2 or min(h.shape) < 2:
            raise InputError(f"a DEM must be a 2-D array of at least 2x2 cells, got {h.shape}")
        if self.dlon_deg == 0 or self.dlat_deg == 0:
            raise InputError("DEM spacing must be non-zero in both directions")
        h.setflags(write=False)
        object.__setattr__(self, "h_m", h)

    @classmethod
    def from_transform(cls, h_m: NDArray, transform: tuple[float, ...]) -> GeoDEM:
        """From a GDAL/affine geotransform (a, b, c, d, e, f) whose origin is the pixel corner.

        Accepts ``affine.Affine`` order (a, b, c, d, e, f) = (dlon, 0, lon_corner, 0, dlat, lat_corner).
        """
        a, b, c, d, e, f = (float(v) for v in tuple(transform)[:6])
        if b != 0 or d != 0:
            raise InputError("rotated DEM geotransforms are not supported; warp the DEM north-up")
        return cls(np.asarray(h_m), c + 0.5 * a, f + 0.5 * e, a, e)

    @property
    def shape(self) -> tuple[int, int]:
        return self.h_m.shape  # type: ignore[return-value]

    def bounds_deg(self) -> tuple[float, float, float, float]:
        """(lon_min, lat_min, lon_max, lat_max) of the node grid."""
        lons = (self.lon0_deg, self.lon0_deg + (self.shape[1] - 1) * self.dlon_deg)
        lats = (self.lat0_deg, self.lat0_deg + (self.shape[0] - 1) * self.dlat_deg)
        return min(lons), min(lats), max(lons), max(lats)

    def height_range_m(self) -> tuple[float, float]:
        return float(np.nanmin(self.h_m)), float(np.nanmax(self.h_m))

    def height_m(self, lon_deg: ArrayLike, lat_deg: ArrayLike) -> NDArray[np.float64]:
        """Bilinear height at (lon, lat); NaN outside the grid or next to a void."""
        fi = (np.asarray(lat_deg, dtype=np.float64) - self.lat0_deg) / self.dlat_deg
        fj = (np.asarray(lon_deg, dtype=np.float64) - self.lon0_deg) / self.dlon_deg
        return sample_bilinear(self.h_m, fi, fj)

    def cell_size_m(self) -> float:
        """Approximate smaller ground cell size in metres at the DEM centre."""
        lat_c = self.lat0_deg + 0.5 * (self.shape[0] - 1) * self.dlat_deg
        dy = abs(self.dlat_deg) * 111_320.0
        dx = abs(self.dlon_deg) * 111_320.0 * np.cos(np.radians(lat_c))
        return float(min(dx, dy))
