"""Simulated airborne lidar: point positions, heights with noise, LAS classes.

Points sit on a jittered lattice of ``spacing_m``: one point per lattice cell
``[i*s, (i+1)*s) x [j*s, (j+1)*s)``, displaced from the cell centre by hashed
uniform offsets. A tile keeps the points whose coordinates fall in its
half-open box ``[x_min, x_max) x [y_min, y_max)``, so adjacent tiles share no
point and miss none. Every later random draw (noise, dropouts, ground hits)
hashes the cell indices ``(cell_i, cell_j)`` that travel with each point.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.errors import InputError
from core.simulation.hashing import derive_seed, hash_normal, hash_uniform
from core.simulation.landcover import (
    LAS_BUILDING,
    LAS_GROUND,
    LAS_HIGH_VEGETATION,
    LAS_WATER,
    LandCover,
)
from core.simulation.surface import SurfaceSpec, ToLonLat, sample_surface

__all__ = [
    "LidarConfig",
    "LidarPoints",
    "LidarReturns",
    "LidarTile",
    "lidar_extent",
    "lidar_points",
    "lidar_returns",
    "lidar_tile",
]


@dataclass(frozen=True)
class LidarConfig:
    """Return model of the simulated lidar.

    - ``noise_sigma_m``: std of the vertical noise, metres (Gaussian).
    - ``ground_return_fraction``: share of FOREST points whose return comes from
      the ground under the canopy (classified ground, 2), as the last returns a
      real survey classifies as ground.
    - ``water_return_fraction``: share of WATER points that return (class 9);
      0 drops every water point (specular reflection away from the sensor).
    - ``dark_roof_return_fraction``: share of points on dark roofs that return;
      0 drops them all (low reflectance at the laser wavelength).
    """

    noise_sigma_m: float = 0.15
    ground_return_fraction: float = 0.15
    water_return_fraction: float = 0.0
    dark_roof_return_fraction: float = 0.0

    def __post_init__(self) -> None:
        if not (self.noise_sigma_m >= 0 and math.isfinite(self.noise_sigma_m)):
            raise InputError(f"noise_sigma_m must be >= 0 and finite, got {self.noise_sigma_m!r}")
        for name in ("ground_return_fraction", "water_return_fraction",
                     "dark_roof_return_fraction"):
            v = getattr(self, name)
            if not 0.0 <= v <= 1.0:
                raise InputError(f"{name} must be in [0, 1], got {v!r}")


@dataclass(frozen=True, eq=False)
class LidarPoints:
    """Planimetric lidar positions (metres, ground frame) and their lattice cell indices."""

    x_m: NDArray[np.float64]
    y_m: NDArray[np.float64]
    cell_i: NDArray[np.int64]
    cell_j: NDArray[np.int64]

    def __len__(self) -> int:
        return int(self.x_m.size)


@dataclass(frozen=True, eq=False)
class LidarReturns:
    """Kept returns: positions, noisy height ``z_m``, noise-free ``z_true_m``, LAS class."""

    x_m: NDArray[np.float64]
    y_m: NDArray[np.float64]
    z_m: NDArray[np.float64]
    z_true_m: NDArray[np.float64]
    las_class: NDArray[np.uint8]
    cell_i: NDArray[np.int64]
    cell_j: NDArray[np.int64]
    index: NDArray[np.intp]  # of each return in the points surveyed

    def __len__(self) -> int:
        return int(self.x_m.size)


def lidar_points(x_min_m: float, y_min_m: float, x_max_m: float, y_max_m: float, seed: int,
                 spacing_m: float = 3.0, jitter: float = 0.3) -> LidarPoints:
    """Lidar positions in the half-open box ``[x_min_m, x_max_m) x [y_min_m, y_max_m)``.

    Args:
        x_min_m, y_min_m, x_max_m, y_max_m: the box, metres.
        seed: lidar seed.
        spacing_m: lattice spacing; density is ``1 / spacing_m**2`` points per m^2.
        jitter: offsets are uniform in ``+-jitter/2 * spacing_m`` around the cell
            centre (0 a regular grid, 1 anywhere in the cell). With the default 0.3
            the mean nearest-neighbour distance is about 0.87 ``spacing_m``.

    Returns:
        Points ordered by cell row ``j`` then cell column ``i``.
    """
    if not (spacing_m > 0 and math.isfinite(spacing_m)):
        raise InputError(f"spacing_m must be positive, got {spacing_m!r}")
    if not 0.0 <= jitter <= 1.0:
        raise InputError(f"jitter must be in [0, 1], got {jitter!r}")
    if not (x_max_m > x_min_m and y_max_m > y_min_m):
        raise InputError(f"empty box: x [{x_min_m}, {x_max_m}), y [{y_min_m}, {y_max_m})")
    i = np.arange(math.floor(x_min_m / spacing_m), math.floor(x_max_m / spacing_m) + 1,
                  dtype=np.int64)
    j = np.arange(math.floor(y_min_m / spacing_m), math.floor(y_max_m / spacing_m) + 1,
                  dtype=np.int64)
    ci, cj = np.meshgrid(i, j)
    ci = ci.reshape(-1)
    cj = cj.reshape(-1)
    sx = derive_seed(seed, "lidar-jitter-x")
    sy = derive_seed(seed, "lidar-jitter-y")
    x = (ci.astype(np.float64) + 0.5 + jitter * (hash_uniform(sx, ci, cj) - 0.5)) * spacing_m
    y = (cj.astype(np.float64) + 0.5 + jitter * (hash_uniform(sy, ci, cj) - 0.5)) * spacing_m
    keep = (x >= x_min_m) & (x < x_max_m) & (y >= y_min_m) & (y < y_max_m)
    return LidarPoints(x[keep], y[keep], ci[keep], cj[keep])


def lidar_returns(points: LidarPoints, ground_h_m: ArrayLike, surface_h_m: ArrayLike,
                  classes: ArrayLike, on_building: ArrayLike, dark_roof: ArrayLike, seed: int,
                  config: LidarConfig = LidarConfig()) -> LidarReturns:
    """Heights and LAS classes of the returns at ``points``; dropped returns removed.

    Args:
        points: from :func:`lidar_points`.
        ground_h_m: true bare earth (DTM, water flattened) at the points, metres.
        surface_h_m: true surface (DSM: canopy top, roofs) at the points, metres.
        classes: :class:`LandCover` codes at the points.
        on_building: point is on a building footprint (``building_height_m > 0``).
        dark_roof: point is on a dark roof (``BuildingSample.dark_roof``).
        seed: lidar seed.
        config: return model.

    Classes: 6 on buildings; 5 on forest canopy; 2 on bare soil, urban ground
    and forest ground hits; 9 on returning water. ``z_true_m`` is the surface
    hit (ground for ground hits) and ``z_m = z_true_m + N(0, noise_sigma_m)``.
    """
    n = len(points)
    shape = (n,)

    def arr(name: str, a: ArrayLike, dtype: type) -> NDArray:
        v = np.asarray(a, dtype=dtype)
        if v.shape != shape:
            raise InputError(f"{name} has shape {v.shape}, expected ({n},) as the points")
        return v

    ground = arr("ground_h_m", ground_h_m, np.float64)
    surface = arr("surface_h_m", surface_h_m, np.float64)
    cls = arr("classes", classes, np.uint8)
    bld = arr("on_building", on_building, bool)
    dark = arr("dark_roof", dark_roof, bool)
    ci, cj = points.cell_i, points.cell_j

    forest = cls == LandCover.FOREST
    water = cls == LandCover.WATER
    building = bld & (cls == LandCover.URBAN)
    hits_ground = forest & (
        hash_uniform(derive_seed(seed, "lidar-ground-hit"), ci, cj) < config.ground_return_fraction
    )
    las = np.full(shape, LAS_GROUND, dtype=np.uint8)
    las[forest & ~hits_ground] = LAS_HIGH_VEGETATION
    las[building] = LAS_BUILDING
    las[water] = LAS_WATER
    z_true = np.where(hits_ground, ground, surface)

    keep = np.ones(shape, dtype=bool)
    u_drop = hash_uniform(derive_seed(seed, "lidar-dropout"), ci, cj)
    keep &= ~(water & (u_drop >= config.water_return_fraction))
    keep &= ~(building & dark & (u_drop >= config.dark_roof_return_fraction))
    noise = config.noise_sigma_m * hash_normal(derive_seed(seed, "lidar-noise"), ci, cj)
    z = z_true + noise
    return LidarReturns(points.x_m[keep], points.y_m[keep], z[keep], z_true[keep], las[keep],
                        ci[keep], cj[keep], np.flatnonzero(keep))


@dataclass(frozen=True, eq=False)
class LidarTile:
    """The returns of one tile and their orthometric heights (what a survey delivers)."""

    returns: LidarReturns
    z_orthometric_m: NDArray[np.float64]


def lidar_tile(spec: SurfaceSpec, bounds_m: tuple[float, float, float, float], seed: int,
               spacing_m: float, to_lonlat: ToLonLat,
               config: LidarConfig = LidarConfig()) -> LidarTile | None:
    """Survey the truth surface over the half-open box ``bounds_m`` (x_min, y_min, x_max, y_max):
    points (:func:`lidar_points`), returns (:func:`lidar_returns`), heights made orthometric
    with the geoid of ``spec``. None when the box holds no point."""
    pts = lidar_points(*bounds_m, seed, spacing_m=spacing_m)
    if len(pts) == 0:
        return None
    s = sample_surface(spec, pts.x_m, pts.y_m, to_lonlat)
    ret = lidar_returns(pts, s.dtm_m, s.dsm_m, s.classes, s.building_m > 0, s.dark_roof, seed,
                        config)
    lon, lat = s.lon_deg[ret.index], s.lat_deg[ret.index]
    return LidarTile(ret, spec.geoid.ellipsoidal_to_orthometric(lon, lat, ret.z_m))


def lidar_extent(grid_bounds_m: tuple[float, float, float, float], centre_x_m: float,
                 centre_y_m: float,
                 strip_m: tuple[float, float] | None) -> tuple[float, float, float, float]:
    """The surveyed box: a strip of ``strip_m`` (across, along) centred on the scene centre, or
    the whole grid when ``strip_m`` is None."""
    if strip_m is None:
        return grid_bounds_m
    across, along = strip_m
    return (centre_x_m - across / 2, centre_y_m - along / 2, centre_x_m + across / 2,
            centre_y_m + along / 2)
