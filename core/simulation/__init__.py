"""Scene simulation kernels: deterministic fields of ground coordinates and a seed.

Every function is a pure function of its coordinates (ground metres, image
rows/cols or times), a seed and a configuration, so a Dask tile computes the
same bytes as the whole scene would. See :mod:`core.simulation.hashing`.
"""

from core.simulation.fields import (
    cell_uniform,
    fbm,
    fbm_threshold,
    fractal_detail_m,
    gradient_noise,
)
from core.simulation.hashing import derive_seed, hash_normal, hash_u64, hash_uniform
from core.simulation.jitter import jitter_profile
from core.simulation.landcover import (
    LANDCOVER_NODATA,
    LAS_BUILDING,
    LAS_CLASS,
    LAS_GROUND,
    LAS_HIGH_VEGETATION,
    LAS_WATER,
    BuildingSample,
    LandCover,
    LandCoverConfig,
    building_height_m,
    canopy_height_m,
    classify,
    dsm_m,
    dtm_m,
    sample_buildings,
    water_level_for_fraction,
)
from core.simulation.lidar import (
    LidarConfig,
    LidarPoints,
    LidarReturns,
    lidar_points,
    lidar_returns,
)
from core.simulation.render import (
    ChangeKind,
    apply_date_change,
    date_change_kind,
    date_change_mask,
    date_change_weight,
    hillshade,
    radiance_to_dn,
    texture,
)

__all__ = [
    "LANDCOVER_NODATA",
    "LAS_BUILDING",
    "LAS_CLASS",
    "LAS_GROUND",
    "LAS_HIGH_VEGETATION",
    "LAS_WATER",
    "BuildingSample",
    "ChangeKind",
    "LandCover",
    "LandCoverConfig",
    "LidarConfig",
    "LidarPoints",
    "LidarReturns",
    "apply_date_change",
    "building_height_m",
    "canopy_height_m",
    "cell_uniform",
    "classify",
    "date_change_kind",
    "date_change_mask",
    "date_change_weight",
    "derive_seed",
    "dsm_m",
    "dtm_m",
    "fbm",
    "fbm_threshold",
    "fractal_detail_m",
    "gradient_noise",
    "hash_normal",
    "hash_u64",
    "hash_uniform",
    "hillshade",
    "jitter_profile",
    "lidar_points",
    "lidar_returns",
    "radiance_to_dn",
    "sample_buildings",
    "texture",
    "water_level_for_fraction",
]
