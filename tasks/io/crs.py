"""Coordinate transformations the tasks hand to core functions as plain callables (pyproj)."""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np
import pyproj

_local = threading.local()


def _transformer(epsg: int, inverse: bool) -> pyproj.Transformer:
    """A per-thread cached EPSG:epsg <-> lon/lat transformer (pyproj's are not thread-safe)."""
    cache = _local.__dict__.setdefault("tr", {})
    key = (epsg, inverse)
    if key not in cache:
        src, dst = (f"EPSG:{epsg}", "EPSG:4326") if inverse else ("EPSG:4326", f"EPSG:{epsg}")
        cache[key] = pyproj.Transformer.from_crs(src, dst, always_xy=True)
    return cache[key]


@dataclass(frozen=True)
class Projection:
    """A projected CRS (EPSG code, e.g. a UTM zone) and its transforms to and from lon/lat."""

    epsg: int

    def to_lonlat(self, x_m: np.ndarray, y_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Projected metres -> WGS84 degrees."""
        lon, lat = _transformer(self.epsg, True).transform(x_m, y_m)
        return np.asarray(lon), np.asarray(lat)

    def to_xy(self, lon_deg: np.ndarray, lat_deg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """WGS84 degrees -> projected metres."""
        x, y = _transformer(self.epsg, False).transform(lon_deg, lat_deg)
        return np.asarray(x), np.asarray(y)
