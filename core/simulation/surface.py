"""The truth surface of a simulated scene as a function of ground position.

Everything here is a deterministic function of the point (projected x, y and its
lon/lat) and the scene seed, so the truth DSM/DTM grid, the lidar returns and the
check points all sample one and the same surface, tile by tile.

Terrain (WGS84 ellipsoidal): the reference DEM's orthometric heights H (relief already
scaled by the caller) bilinearly interpolated, plus the geoid N, plus fractal detail finer
than the DEM cell. Land cover from :mod:`core.simulation.landcover`; the DSM adds canopy
and flat-roofed buildings; water is flat.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.dem import GeoDEM
from core.errors import InputError
from core.geodesy import metres_per_degree
from core.geoid import GeoidGrid
from core.simulation.fields import fractal_detail_m
from core.simulation.hashing import derive_seed
from core.simulation.landcover import (
    LandCover,
    LandCoverConfig,
    building_height_m,
    canopy_height_m,
    classify,
    dsm_m,
    dtm_m,
    sample_buildings,
)

FloatArray = NDArray[np.float64]
ToLonLat = Callable[[FloatArray, FloatArray], tuple[FloatArray, FloatArray]]


@dataclass(frozen=True, eq=False)
class SurfaceSpec:
    """What defines the truth surface: the (relief-scaled) DEM, the geoid, the seed, rules."""

    dem_H: GeoDEM  # orthometric heights, relief already scaled
    geoid: GeoidGrid
    seed: int
    landcover: LandCoverConfig
    detail_amplitude_m: float
    detail_min_wavelength_m: float
    detail_hurst: float = 0.8

    def __post_init__(self) -> None:
        if self.detail_amplitude_m < 0 or self.detail_min_wavelength_m <= 0:
            raise InputError("detail amplitude must be >= 0 and its min wavelength > 0")

    @property
    def dem_cell_m(self) -> float:
        return self.dem_H.cell_size_m()


@dataclass(frozen=True)
class SurfaceSample:
    """The truth at a set of points (all arrays of the points' shape)."""

    terrain_m: FloatArray  # ellipsoidal bare terrain before water flattening
    classes: NDArray[np.uint8]
    canopy_m: FloatArray
    building_m: FloatArray
    dark_roof: NDArray[np.bool_]
    dtm_m: FloatArray  # ellipsoidal bare earth, water flat
    dsm_m: FloatArray  # ellipsoidal surface: canopy top, roofs
    lon_deg: FloatArray  # the points' geodetic coordinates
    lat_deg: FloatArray


def dem_height_m(dem: GeoDEM, lon: ArrayLike, lat: ArrayLike) -> FloatArray:
    """``dem.height_m(lon, lat)`` in one compiled pass (the same values:
    :func:`core.simulation.raycast_kernels.sample_grid` is SciPy's bilinear sample)."""
    from core.simulation.raycast_kernels import sample_grid

    lon, lat = np.broadcast_arrays(np.asarray(lon, dtype=np.float64),
                                   np.asarray(lat, dtype=np.float64))
    x0, y0, dx, dy = dem.axes
    return sample_grid(dem.h_m, x0, y0, dx, dy, np.ascontiguousarray(lon).reshape(-1),
                       np.ascontiguousarray(lat).reshape(-1)).reshape(lon.shape)


def terrain_m(spec: SurfaceSpec, x_m: FloatArray, y_m: FloatArray, lon: FloatArray,
              lat: FloatArray) -> FloatArray:
    """Ellipsoidal bare terrain: DEM H + geoid N + sub-cell fractal detail."""
    H = dem_height_m(spec.dem_H, lon, lat)
    detail = fractal_detail_m(
        x_m, y_m, derive_seed(spec.seed, "terrain-detail"), spec.detail_amplitude_m,
        spec.detail_min_wavelength_m, max(spec.dem_cell_m, spec.detail_min_wavelength_m),
        spec.detail_hurst,
    ) if spec.detail_amplitude_m > 0 else 0.0
    return H + spec.geoid.undulation_m(lon, lat) + detail


def slope_deg(spec: SurfaceSpec, lon: FloatArray, lat: FloatArray) -> FloatArray:
    """Terrain slope of the DEM at the points (central differences over one DEM cell)."""
    d = spec.dem_H
    hx = 0.5 * abs(d.dlon_deg)
    hy = 0.5 * abs(d.dlat_deg)
    m_lon, m_lat = metres_per_degree(lat)
    dzdx = (dem_height_m(d, lon + hx, lat) - dem_height_m(d, lon - hx, lat)) / (2 * hx * m_lon)
    dzdy = (dem_height_m(d, lon, lat + hy) - dem_height_m(d, lon, lat - hy)) / (2 * hy * m_lat)
    g = np.hypot(dzdx, dzdy)
    return np.degrees(np.arctan(np.where(np.isfinite(g), g, 0.0)))


def sample_surface(spec: SurfaceSpec, x_m: FloatArray, y_m: FloatArray,
                   to_lonlat: ToLonLat) -> SurfaceSample:
    """The truth at projected points (x, y); ``to_lonlat`` maps them to degrees."""
    x = np.asarray(x_m, dtype=np.float64)
    y = np.asarray(y_m, dtype=np.float64)
    x, y = np.broadcast_arrays(x, y)
    lon, lat = to_lonlat(x, y)
    terr = terrain_m(spec, x, y, lon, lat)
    lc = spec.landcover
    bld = sample_buildings(x, y, spec.seed, lc)
    cls = classify(x, y, terr, slope_deg(spec, lon, lat), spec.seed, lc, bld)
    canopy = canopy_height_m(x, y, cls, spec.seed, lc)
    building = building_height_m(x, y, cls, spec.seed, lc, bld)
    on_bld = building > 0
    # flat roofs: the terrain under each building's centre
    roof_base = None
    if np.any(on_bld):
        roof_base = terr.copy()
        cx, cy = bld.centre_x_m[on_bld], bld.centre_y_m[on_bld]
        clon, clat = to_lonlat(cx, cy)
        roof_base[on_bld] = terrain_m(spec, cx, cy, clon, clat)
    dtm = dtm_m(terr, cls, lc)
    dsm = dsm_m(terr, cls, canopy, building, lc, roof_base_h_m=roof_base)
    dark = bld.dark_roof & on_bld & (cls == LandCover.URBAN)
    return SurfaceSample(terr, cls, canopy, building, dark, dtm, dsm, lon, lat)
