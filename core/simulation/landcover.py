"""Land cover, canopy and buildings as pure functions of ground coordinates.

Every rule here decides a point from its own coordinates, its own terrain
height and slope, the seed and the configuration, never from a neighbourhood
or a scene-wide statistic, so tiles are independent:

- **water**: ``terrain_h_m < water_level_m`` (a configured absolute level; the
  water surface is that level, flat). Lakes fill basins below the level; no
  connectivity is tested (that would need the whole scene). Pick the level for
  a wanted area share once per scene with :func:`water_level_for_fraction` on
  the coarse DEM, and put it in the configuration.
- **urban**: the street grid has square blocks of ``block_m``; a whole block is
  urban when a low-frequency fbm at the block centre exceeds the threshold for
  ``urban_fraction``, and a point of it stays urban where its slope is below
  ``urban_max_slope_deg``. Streets of ``street_width_m`` run along the block
  edges; each block holds at most one rectangular building with hashed
  presence, setbacks, height, roof darkness and reflectance.
- **forest**: fbm patches (a second field) elsewhere, threshold set so forest
  covers about ``forest_fraction`` of the land.
- **bare soil**: the rest.

Fractions are of the land (water excluded) and hold over areas many patch
wavelengths wide; a scene of a few wavelengths varies more.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from enum import IntEnum

import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.errors import InputError
from core.simulation.fields import broadcast_xy, fbm, fbm_threshold, floor_index
from core.simulation.hashing import derive_seed, hash_uniform

__all__ = [
    "LANDCOVER_NODATA",
    "LAS_BUILDING",
    "LAS_CLASS",
    "LAS_GROUND",
    "LAS_HIGH_VEGETATION",
    "LAS_WATER",
    "BuildingSample",
    "LandCover",
    "LandCoverConfig",
    "building_height_m",
    "canopy_height_m",
    "classify",
    "dsm_m",
    "dtm_m",
    "sample_buildings",
    "water_level_for_fraction",
]


class LandCover(IntEnum):
    """Land-cover codes of the simulator (uint8 rasters; 0 is nodata)."""

    BARE_SOIL = 1
    FOREST = 2
    URBAN = 3
    WATER = 4


LANDCOVER_NODATA = 0
LAS_GROUND = 2
LAS_HIGH_VEGETATION = 5
LAS_BUILDING = 6
LAS_WATER = 9

#: ASPRS LAS class of the dominant surface of each land cover. Lidar streets and
#: yards inside URBAN are ground (2); only building footprints are 6.
LAS_CLASS: dict[LandCover, int] = {
    LandCover.BARE_SOIL: LAS_GROUND,
    LandCover.FOREST: LAS_HIGH_VEGETATION,
    LandCover.URBAN: LAS_BUILDING,
    LandCover.WATER: LAS_WATER,
}


def _in_unit(name: str, v: float) -> None:
    if not 0.0 <= v <= 1.0:
        raise InputError(f"{name} must be in [0, 1], got {v!r}")


def _range(name: str, r: tuple[float, float], lo: float = 0.0) -> None:
    if len(r) != 2 or not lo <= r[0] <= r[1]:
        raise InputError(f"{name} must be (low, high) with {lo} <= low <= high, got {r!r}")


@dataclass(frozen=True)
class LandCoverConfig:
    """Parameters of the land-cover rules (lengths in metres, angles in degrees).

    ``water_level_m`` None means no water. ``urban_fraction`` and
    ``forest_fraction`` are target shares of the land area.
    """

    water_level_m: float | None = None
    urban_fraction: float = 0.08
    forest_fraction: float = 0.30
    urban_patch_wavelength_m: float = 2000.0
    forest_patch_wavelength_m: float = 800.0
    patch_octaves: int = 4
    urban_max_slope_deg: float = 10.0
    block_m: float = 50.0
    street_width_m: float = 10.0
    min_setback_m: float = 1.5
    building_presence: float = 0.85
    building_height_range_m: tuple[float, float] = (4.0, 15.0)
    dark_roof_fraction: float = 0.15
    canopy_height_range_m: tuple[float, float] = (10.0, 25.0)
    crown_wavelength_m: float = 8.0
    stand_wavelength_m: float = 150.0

    def __post_init__(self) -> None:
        if self.water_level_m is not None and not np.isfinite(self.water_level_m):
            raise InputError(f"water_level_m must be finite or None, got {self.water_level_m!r}")
        for name in ("urban_fraction", "forest_fraction", "building_presence",
                     "dark_roof_fraction"):
            _in_unit(name, getattr(self, name))
        if self.urban_fraction + self.forest_fraction > 1.0:
            raise InputError(
                f"urban_fraction + forest_fraction must not exceed 1, got "
                f"{self.urban_fraction} + {self.forest_fraction}"
            )
        for name in ("urban_patch_wavelength_m", "forest_patch_wavelength_m", "block_m",
                     "crown_wavelength_m", "stand_wavelength_m"):
            if not getattr(self, name) > 0:
                raise InputError(f"{name} must be positive, got {getattr(self, name)!r}")
        if self.patch_octaves < 1:
            raise InputError(f"patch_octaves must be >= 1, got {self.patch_octaves}")
        if not 0.0 < self.urban_max_slope_deg <= 90.0:
            raise InputError(f"urban_max_slope_deg must be in (0, 90], got "
                             f"{self.urban_max_slope_deg}")
        lot = self.block_m - self.street_width_m - 2.0 * self.min_setback_m
        if self.street_width_m < 0 or self.min_setback_m < 0 or lot < 2.0:
            raise InputError(
                f"block_m ({self.block_m}) must exceed street_width_m ({self.street_width_m}) "
                f"plus twice min_setback_m ({self.min_setback_m}) by at least 2 m"
            )
        _range("building_height_range_m", self.building_height_range_m)
        _range("canopy_height_range_m", self.canopy_height_range_m)


@dataclass(frozen=True, eq=False)
class BuildingSample:
    """The street-grid structure at each point (arrays of the input shape).

    ``in_footprint`` ignores land cover: a point is on a building only where it
    is also classified URBAN. ``height_m`` is the building's height above the
    terrain (0 outside footprints). ``centre_x_m``/``centre_y_m`` are the
    footprint centre, where the caller may sample the terrain to put a flat roof
    at ``terrain(centre) + height_m`` (see :func:`dsm_m`).
    """

    urban_block: NDArray[np.bool_]
    street: NDArray[np.bool_]
    in_footprint: NDArray[np.bool_]
    height_m: NDArray[np.float64]
    dark_roof: NDArray[np.bool_]
    roof_reflectance: NDArray[np.float64]
    centre_x_m: NDArray[np.float64]
    centre_y_m: NDArray[np.float64]


def _per_block(bi: NDArray[np.int64], bj: NDArray[np.int64],
               fn: Callable[[NDArray[np.int64], NDArray[np.int64]], dict[str, NDArray]]
               ) -> dict[str, NDArray]:
    """Evaluate per-block attributes ``fn(i, j)`` once per block and spread them to the points.

    When the points share blocks, ``fn`` runs on the blocks of the bounding box
    and the points look their block up; the values are the same either way,
    because ``fn`` depends on the block indices only.
    """
    if bi.size == 0:
        return fn(bi, bj)
    imin, jmin = int(bi.min()), int(bj.min())
    ni, nj = int(bi.max()) - imin + 1, int(bj.max()) - jmin + 1
    if ni * nj > bi.size:
        return fn(bi, bj)
    gi = np.broadcast_to(np.arange(imin, imin + ni, dtype=np.int64)[None, :], (nj, ni))
    gj = np.broadcast_to(np.arange(jmin, jmin + nj, dtype=np.int64)[:, None], (nj, ni))
    grid = fn(gi.reshape(-1), gj.reshape(-1))
    lin = (bj - jmin) * ni + (bi - imin)
    return {k: v.take(lin) for k, v in grid.items()}


def _block_attributes(bi: NDArray[np.int64], bj: NDArray[np.int64], seed: int,
                      config: LandCoverConfig) -> dict[str, NDArray]:
    """Urban-patch membership and building of each block (pure function of its indices)."""
    b = config.block_m
    half = 0.5 * config.street_width_m
    bseed = derive_seed(seed, "buildings")
    extra = max(0.25 * (b - config.street_width_m) - config.min_setback_m, 0.0)
    inner = half + config.min_setback_m
    lo, hi = config.building_height_range_m
    dark = hash_uniform(bseed, bi, bj, 6) < config.dark_roof_fraction
    cx = (bi.astype(np.float64) + 0.5) * b
    cy = (bj.astype(np.float64) + 0.5) * b
    urban_thr = fbm_threshold(config.urban_fraction, config.patch_octaves)
    urban = fbm(cx, cy, derive_seed(seed, "urban-patches"), config.urban_patch_wavelength_m,
                config.patch_octaves) > urban_thr
    return {
        "west": inner + extra * hash_uniform(bseed, bi, bj, 0),
        "east": b - inner - extra * hash_uniform(bseed, bi, bj, 1),
        "south": inner + extra * hash_uniform(bseed, bi, bj, 2),
        "north": b - inner - extra * hash_uniform(bseed, bi, bj, 3),
        "present": hash_uniform(bseed, bi, bj, 4) < config.building_presence,
        "height": lo + (hi - lo) * hash_uniform(bseed, bi, bj, 5),
        "dark": dark,
        "refl": np.where(dark, 0.05 + 0.05 * hash_uniform(bseed, bi, bj, 7),
                         0.35 + 0.35 * hash_uniform(bseed, bi, bj, 8)),
        "urban": urban,
    }


def sample_buildings(x_m: ArrayLike, y_m: ArrayLike, seed: int,
                     config: LandCoverConfig = LandCoverConfig()) -> BuildingSample:
    """Street grid, building footprints and building attributes at each point.

    Block ``(i, j)`` covers ``[i*block_m, (i+1)*block_m) x [j*block_m, (j+1)*block_m)``;
    half a street runs inside each edge. The lot left inside holds one
    rectangle inset by hashed setbacks (``min_setback_m`` up to a quarter of
    the lot) on each side, present with probability ``building_presence``.
    All attributes hash the block indices only, so every point of a building
    agrees on them.
    """
    x, y = broadcast_xy(x_m, y_m)
    b = config.block_m
    finite = np.isfinite(x) & np.isfinite(y)
    bi = np.where(finite, floor_index(x / b), 0)
    bj = np.where(finite, floor_index(y / b), 0)
    lx = x - bi.astype(np.float64) * b
    ly = y - bj.astype(np.float64) * b
    half = 0.5 * config.street_width_m
    street = finite & ((lx < half) | (lx >= b - half) | (ly < half) | (ly >= b - half))
    at = _per_block(bi.reshape(-1), bj.reshape(-1),
                    lambda i, j: _block_attributes(i, j, seed, config))
    at = {k: v.reshape(x.shape) for k, v in at.items()}
    in_fp = (at["present"] & (lx >= at["west"]) & (lx < at["east"])
             & (ly >= at["south"]) & (ly < at["north"]))
    return BuildingSample(
        urban_block=at["urban"] & finite,
        street=street,
        in_footprint=in_fp,
        height_m=np.where(in_fp, at["height"], 0.0),
        dark_roof=at["dark"] & in_fp,
        roof_reflectance=np.where(in_fp, at["refl"], 0.0),
        centre_x_m=np.where(finite, bi * b + 0.5 * (at["west"] + at["east"]), np.nan),
        centre_y_m=np.where(finite, bj * b + 0.5 * (at["south"] + at["north"]), np.nan),
    )


def classify(x_m: ArrayLike, y_m: ArrayLike, terrain_h_m: ArrayLike, slope_deg: ArrayLike,
             seed: int, config: LandCoverConfig = LandCoverConfig(),
             buildings: BuildingSample | None = None) -> NDArray[np.uint8]:
    """Land-cover code (:class:`LandCover`) at each point, by the rules of the module docstring.

    Args:
        x_m, y_m: ground coordinates, metres.
        terrain_h_m: bare-terrain height at the points, metres (any datum the
            ``water_level_m`` of the configuration uses).
        slope_deg: terrain slope at the points, degrees.
        seed: scene seed.
        config: the rules' parameters.
        buildings: :func:`sample_buildings` at the points, when the caller has it already.

    Returns:
        uint8 array of the broadcast shape.
    """
    x, y = broadcast_xy(x_m, y_m)
    h = np.broadcast_to(np.asarray(terrain_h_m, dtype=np.float64), x.shape)
    slope = np.broadcast_to(np.asarray(slope_deg, dtype=np.float64), x.shape)
    if config.water_level_m is None:
        water = np.zeros(x.shape, dtype=bool)
    else:
        water = h < config.water_level_m
    bld = sample_buildings(x, y, seed, config) if buildings is None else buildings
    urban = ~water & bld.urban_block & (slope < config.urban_max_slope_deg)
    share = min(1.0, config.forest_fraction / max(1.0 - config.urban_fraction, 1e-12))
    thr = fbm_threshold(share, config.patch_octaves)
    forest_field = fbm(x, y, derive_seed(seed, "forest-patches"),
                       config.forest_patch_wavelength_m, config.patch_octaves)
    forest = ~water & ~urban & (forest_field > thr)
    out = np.full(x.shape, LandCover.BARE_SOIL, dtype=np.uint8)
    out[forest] = LandCover.FOREST
    out[urban] = LandCover.URBAN
    out[water] = LandCover.WATER
    return out


def _soft_unit(v: NDArray[np.float64], gain: float) -> NDArray[np.float64]:
    """Smooth saturation of ``gain * v`` into (-1, 1): s / sqrt(1 + s^2)."""
    s = gain * v
    return s / np.sqrt(1.0 + s * s)


def canopy_height_m(x_m: ArrayLike, y_m: ArrayLike, classes: ArrayLike, seed: int,
                    config: LandCoverConfig = LandCoverConfig()) -> NDArray[np.float64]:
    """Canopy height above the terrain, metres: within ``canopy_height_range_m`` on FOREST, else 0.

    Stand-scale variation (``stand_wavelength_m``) plus crown-scale bumps
    (``crown_wavelength_m``), squeezed smoothly into the range (never outside).
    """
    x, y = broadcast_xy(x_m, y_m)
    cls = np.broadcast_to(np.asarray(classes), x.shape)
    stand = fbm(x, y, derive_seed(seed, "canopy-stand"), config.stand_wavelength_m, 3)
    crown = fbm(x, y, derive_seed(seed, "canopy-crown"), config.crown_wavelength_m, 2)
    lo, hi = config.canopy_height_range_m
    h = 0.5 * (lo + hi) + 0.5 * (hi - lo) * _soft_unit(0.6 * stand + 0.4 * crown, 4.0)
    return np.where(cls == LandCover.FOREST, h, 0.0)


def building_height_m(x_m: ArrayLike, y_m: ArrayLike, classes: ArrayLike, seed: int,
                      config: LandCoverConfig = LandCoverConfig(),
                      buildings: BuildingSample | None = None) -> NDArray[np.float64]:
    """Building height above the terrain, metres: the building's hashed height on URBAN
    footprints (constant over each footprint), 0 on streets, yards and other classes
    (``buildings``: :func:`sample_buildings` at the points, when the caller has it)."""
    x, y = broadcast_xy(x_m, y_m)
    cls = np.broadcast_to(np.asarray(classes), x.shape)
    bld = sample_buildings(x, y, seed, config) if buildings is None else buildings
    return np.where(cls == LandCover.URBAN, bld.height_m, 0.0)


def dtm_m(terrain_h_m: ArrayLike, classes: ArrayLike,
          config: LandCoverConfig = LandCoverConfig()) -> NDArray[np.float64]:
    """Bare-earth heights, metres: the terrain, with WATER flattened to ``water_level_m``."""
    h = np.asarray(terrain_h_m, dtype=np.float64)
    cls = np.asarray(classes)
    if config.water_level_m is None:
        if np.any(cls == LandCover.WATER):
            raise InputError("classes contain WATER but config.water_level_m is None; "
                             "classify with the same configuration")
        return np.broadcast_arrays(h, cls)[0].copy()
    return np.where(cls == LandCover.WATER, config.water_level_m, h)


def dsm_m(terrain_h_m: ArrayLike, classes: ArrayLike, canopy_h_m: ArrayLike,
          building_h_m: ArrayLike, config: LandCoverConfig = LandCoverConfig(),
          roof_base_h_m: ArrayLike | None = None) -> NDArray[np.float64]:
    """Surface heights, metres: DTM + canopy, with roofs on building footprints.

    A roof is at ``roof_base_h_m + building_h_m`` where ``roof_base_h_m`` is the
    terrain at the footprint centre (:class:`BuildingSample` gives the centre),
    which makes roofs exactly flat; without it the roof follows the terrain
    (flat to within slope x footprint size).
    """
    dtm = dtm_m(terrain_h_m, classes, config)
    canopy = np.asarray(canopy_h_m, dtype=np.float64)
    bh = np.asarray(building_h_m, dtype=np.float64)
    base = dtm if roof_base_h_m is None else np.asarray(roof_base_h_m, dtype=np.float64)
    return np.where(bh > 0, base + bh, dtm + canopy)


def water_level_for_fraction(terrain_h_m: ArrayLike, fraction: float) -> float:
    """The level below which ``fraction`` of the given heights lie (NaNs ignored).

    Call once per scene on the coarse DEM and put the result in
    ``LandCoverConfig.water_level_m``; never per tile (it is a scene statistic).
    """
    _in_unit("fraction", fraction)
    h = np.asarray(terrain_h_m, dtype=np.float64)
    h = h[np.isfinite(h)]
    if h.size == 0:
        raise InputError("no finite heights to choose a water level from")
    return float(np.quantile(h, fraction))
