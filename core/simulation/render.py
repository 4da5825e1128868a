"""Image rendering kernels: shading, ground reflectance, date changes, digital numbers.

Reflectance is fixed to the ground (a function of ground coordinates, land
cover and seed), so both images of a pair see the same texture; shading is
Lambertian from the DEM; sensor noise hashes the image row and column, so a
tile of an image is reproducible on its own.
"""

from __future__ import annotations

from enum import IntEnum

import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.errors import InputError
from core.sensors.base import SensorModel
from core.simulation.fields import broadcast_xy, cell_uniform, fbm, fbm_threshold
from core.simulation.hashing import derive_seed, hash_normal
from core.simulation.landcover import LandCover, LandCoverConfig, sample_buildings
from core.simulation.raycast import SurfaceReader, ToXY, cast_on_surface, image_rays

__all__ = [
    "AMBIENT",
    "ChangeKind",
    "apply_date_change",
    "date_change_kind",
    "date_change_mask",
    "date_change_weight",
    "ground_radiance",
    "hillshade",
    "illuminate",
    "radiance_to_dn",
    "render_dn",
    "texture",
]

AMBIENT = 0.2  # diffuse share of the illumination

_DEFAULT_LANDCOVER = LandCoverConfig()


def _pad_linear(a: NDArray[np.float64]) -> NDArray[np.float64]:
    """Pad one cell on every side by linear extrapolation (exact for planes)."""
    p = np.empty((a.shape[0] + 2, a.shape[1] + 2), dtype=np.float64)
    p[1:-1, 1:-1] = a
    p[0, 1:-1] = 2.0 * a[0] - a[1]
    p[-1, 1:-1] = 2.0 * a[-1] - a[-2]
    p[:, 0] = 2.0 * p[:, 1] - p[:, 2]
    p[:, -1] = 2.0 * p[:, -2] - p[:, -3]
    return p


def hillshade(dem_h_m: ArrayLike, dx_m: float, dy_m: float, sun_azimuth_deg: float,
              sun_elevation_deg: float) -> NDArray[np.float64]:
    """Lambertian shading ``max(0, n . s)`` of a gridded DEM (no cast shadows).

    Gradients use Horn's 3x3 kernel (as GDAL's hillshade)::

        dz/dcol = ((c + 2f + i) - (a + 2d + g)) / 8      a b c
        dz/drow = ((g + 2h + i) - (a + 2b + c)) / 8      d e f
                                                         g h i

    Each output cell depends only on its 3x3 neighbourhood, so under
    ``dask.array.map_overlap(depth=1)`` the trimmed blocks join exactly. The
    outermost ring of the array (of the whole raster, or of a block's halo) is
    computed after linear extrapolation of the DEM by one cell, exact for planar
    ground.

    Args:
        dem_h_m: 2-D heights in metres, indexed [row, col]; at least 2x2.
        dx_m: easting step from one column to the next, metres (non-zero).
        dy_m: northing step from one row to the next, metres (GDAL's transform
            ``e``: negative for a north-up raster).
        sun_azimuth_deg: direction of the sun, clockwise from north.
        sun_elevation_deg: sun elevation above the horizon.

    Returns:
        float64 shade in [0, 1] of the DEM's shape; NaN where the 3x3 window has NaN.
    """
    z = np.asarray(dem_h_m, dtype=np.float64)
    if z.ndim != 2 or min(z.shape) < 2:
        raise InputError(f"hillshade needs a 2-D DEM of at least 2x2 cells, got {z.shape}")
    if dx_m == 0 or dy_m == 0 or not (np.isfinite(dx_m) and np.isfinite(dy_m)):
        raise InputError(f"dx_m and dy_m must be finite and non-zero, got {dx_m}, {dy_m}")
    if not -90.0 <= sun_elevation_deg <= 90.0:
        raise InputError(f"sun_elevation_deg must be in [-90, 90], got {sun_elevation_deg}")
    p = _pad_linear(z)
    a, b, c = p[:-2, :-2], p[:-2, 1:-1], p[:-2, 2:]
    d, f = p[1:-1, :-2], p[1:-1, 2:]
    g, h, i = p[2:, :-2], p[2:, 1:-1], p[2:, 2:]
    dz_dx = ((c + 2.0 * f + i) - (a + 2.0 * d + g)) / (8.0 * dx_m)
    dz_dy = ((g + 2.0 * h + i) - (a + 2.0 * b + c)) / (8.0 * dy_m)
    az = np.deg2rad(sun_azimuth_deg)
    el = np.deg2rad(sun_elevation_deg)
    sx, sy, sz = np.sin(az) * np.cos(el), np.cos(az) * np.cos(el), np.sin(el)
    shade = (sz - sx * dz_dx - sy * dz_dy) / np.sqrt(1.0 + dz_dx * dz_dx + dz_dy * dz_dy)
    return np.clip(shade, 0.0, 1.0)  # NaN stays NaN


def texture(x_m: ArrayLike, y_m: ArrayLike, classes: ArrayLike, seed: int,
            config: LandCoverConfig = _DEFAULT_LANDCOVER) -> NDArray[np.float64]:
    """Ground-fixed reflectance in [0, 1] by land cover.

    - bare soil: about 0.30: a mosaic of field parcels (hashed reflectance per 150 m and
      330 m cell, sharp edges, as agricultural land shows at every GSD), plus fbm from
      400 m down to 12 m (texture at every scale a 2.5-40 m sensor resolves);
    - forest: 0.09 +- 0.05, stand-scale (``stand_wavelength_m``) and crown-scale
      (``crown_wavelength_m``) noise;
    - urban: each roof its hashed reflectance (0.35-0.70, dark roofs 0.05-0.10),
      streets 0.12, yards 0.22, with 3 m noise;
    - water: 0.04 +- 0.01.

    ``config`` must be the one the classes came from (it fixes the street grid).
    """
    x, y = broadcast_xy(x_m, y_m)
    cls = np.broadcast_to(np.asarray(classes), x.shape)
    out = np.zeros(x.shape, dtype=np.float64)

    bare = cls == LandCover.BARE_SOIL
    if bare.any():
        xb, yb = x[bare], y[bare]
        parcels = (0.12 * (cell_uniform(xb, yb, derive_seed(seed, "tex-parcel"), 150.0) - 0.5)
                   + 0.10 * (cell_uniform(xb + 71.0, yb + 37.0,
                                          derive_seed(seed, "tex-parcel-2"), 330.0) - 0.5))
        v = 0.30 + parcels + 0.22 * fbm(xb, yb, derive_seed(seed, "tex-field"), 400.0, 6) \
            + 0.10 * fbm(xb, yb, derive_seed(seed, "tex-fine"), 12.0, 3)
        out[bare] = v
    forest = cls == LandCover.FOREST
    if forest.any():
        xf, yf = x[forest], y[forest]
        out[forest] = (0.09 + 0.08 * fbm(xf, yf, derive_seed(seed, "tex-stand"),
                                         config.stand_wavelength_m, 4)
                       + 0.12 * fbm(xf, yf, derive_seed(seed, "tex-crown"),
                                    config.crown_wavelength_m, 3))
    urban = cls == LandCover.URBAN
    if urban.any():
        xu, yu = x[urban], y[urban]
        bld = sample_buildings(xu, yu, seed, config)
        base = np.where(bld.in_footprint, bld.roof_reflectance,
                        np.where(bld.street, 0.12, 0.22))
        out[urban] = base + 0.06 * fbm(xu, yu, derive_seed(seed, "tex-urban"), 3.0, 2)
    water = cls == LandCover.WATER
    if water.any():
        out[water] = 0.04 + 0.03 * fbm(x[water], y[water], derive_seed(seed, "tex-water"),
                                       40.0, 2)
    return np.clip(out, 0.0, 1.0)


class ChangeKind(IntEnum):
    """What changed between the two acquisition dates in a change blob."""

    NONE = 0
    VEGETATION = 1
    SNOW = 2
    CLOUD = 3


_BLOB_OCTAVES = 3


def date_change_weight(x_m: ArrayLike, y_m: ArrayLike, seed: int, fraction: float,
                       blob_wavelength_m: float = 500.0,
                       edge_width: float = 0.08) -> NDArray[np.float64]:
    """Change weight in [0, 1]: 0 outside the blobs, ramping to 1 inside.

    Blobs are where an fbm (``blob_wavelength_m``, 3 octaves) exceeds the
    threshold for ``fraction``; the weight is ``clip((fbm - t) / edge_width, 0, 1)``,
    so ``weight > 0`` covers about ``fraction`` of a large area and the edges are
    soft over ``edge_width`` fbm units (tens of metres for the default).
    """
    if not edge_width > 0:
        raise InputError(f"edge_width must be positive, got {edge_width!r}")
    x, y = broadcast_xy(x_m, y_m)
    thr = fbm_threshold(fraction, _BLOB_OCTAVES)
    v = fbm(x, y, derive_seed(seed, "change-blobs"), blob_wavelength_m, _BLOB_OCTAVES)
    return np.clip((v - thr) / edge_width, 0.0, 1.0)


def date_change_mask(x_m: ArrayLike, y_m: ArrayLike, seed: int, fraction: float,
                     blob_wavelength_m: float = 500.0) -> NDArray[np.bool_]:
    """Boolean mask of about ``fraction`` of the area, in blobs (``date_change_weight > 0``)."""
    return date_change_weight(x_m, y_m, seed, fraction, blob_wavelength_m) > 0.0


def date_change_kind(x_m: ArrayLike, y_m: ArrayLike, seed: int,
                     kinds: tuple[ChangeKind, ...] = (ChangeKind.VEGETATION, ChangeKind.SNOW,
                                                      ChangeKind.CLOUD),
                     region_wavelength_m: float = 3000.0) -> NDArray[np.uint8]:
    """Which kind of change applies where: equal-area regions of a low-frequency fbm.

    Returns uint8 :class:`ChangeKind` codes; combine with a change weight in
    :func:`apply_date_change`.
    """
    if len(kinds) == 0:
        raise InputError("kinds must name at least one ChangeKind")
    x, y = broadcast_xy(x_m, y_m)
    v = fbm(x, y, derive_seed(seed, "change-kind"), region_wavelength_m, 2)
    idx = np.zeros(x.shape, dtype=np.intp)
    for k in range(1, len(kinds)):
        idx += v > fbm_threshold(k / len(kinds), 2)
    # idx counts thresholds exceeded: 0 .. n-1, the high values of v get the first kinds
    table = np.asarray([int(kd) for kd in kinds], dtype=np.uint8)
    return table[idx]


def apply_date_change(reflectance: ArrayLike, weight: ArrayLike,
                      kind: ChangeKind | ArrayLike) -> NDArray[np.float64]:
    """Reflectance of the second date: each kind blended in by the change weight.

    - VEGETATION: hard-edged (weight > 0) swap of dark and bright cover,
      ``r -> clip(0.5 - r, 0.05, 0.45)`` (clearing / crop growth);
    - SNOW: hard-edged, ``r -> 0.8 + 0.15 r``;
    - CLOUD: soft-edged, ``r -> (1 - w) r + w 0.9``;
    - NONE: unchanged.

    Args:
        reflectance: first-date reflectance in [0, 1].
        weight: change weight in [0, 1] (:func:`date_change_weight`).
        kind: one :class:`ChangeKind`, or an array of codes (:func:`date_change_kind`).
    """
    r = np.asarray(reflectance, dtype=np.float64)
    w = np.asarray(weight, dtype=np.float64)
    k = np.asarray(kind)
    r, w, k = np.broadcast_arrays(r, w, k)
    hard = (w > 0.0).astype(np.float64)
    veg = np.clip(0.5 - r, 0.05, 0.45)
    out = np.where(k == ChangeKind.VEGETATION, (1.0 - hard) * r + hard * veg, r)
    out = np.where(k == ChangeKind.SNOW, (1.0 - hard) * r + hard * (0.8 + 0.15 * r), out)
    out = np.where(k == ChangeKind.CLOUD, (1.0 - w) * r + w * 0.9, out)
    return np.clip(out, 0.0, 1.0)


def illuminate(reflectance: ArrayLike, shade: ArrayLike,
               ambient: float = AMBIENT) -> NDArray[np.float64]:
    """Ground radiance (relative units): ``reflectance * (ambient + (1 - ambient) * shade)``.

    ``shade`` is the Lambertian shade in [0, 1] (:func:`hillshade`; 1 for flat, sunlit
    ground), ``ambient`` the diffuse share of the illumination, in [0, 1].
    """
    if not 0.0 <= ambient <= 1.0:
        raise InputError(f"ambient must be in [0, 1], got {ambient!r}")
    r = np.asarray(reflectance, dtype=np.float64)
    return r * (ambient + (1.0 - ambient) * np.asarray(shade, dtype=np.float64))


def ground_radiance(x_m: ArrayLike, y_m: ArrayLike, classes: ArrayLike, surface_h_m: ArrayLike,
                    cell_m: float, sun_azimuth_deg: float, sun_elevation_deg: float, seed: int,
                    date_change: float = 0.0, ambient: float = AMBIENT,
                    change_seed: int | None = None) -> NDArray[np.float64]:
    """Radiance of a north-up block of ground cells on one date.

    ``x_m``, ``y_m`` are the cell centres, ``surface_h_m`` the surface heights (NaN cells take
    the block mean, so shading stays defined), ``cell_m`` the grid spacing. The ground-fixed
    :func:`texture` is shaded by the date's sun (:func:`hillshade`); with ``date_change`` > 0
    (the second date) that fraction of the ground changes (:func:`apply_date_change`) and clouds
    hide the terrain's shading; ``change_seed`` (default ``seed``: a pair's second date) draws
    where and how, so each later date of a block changes in its own pattern. Each cell depends
    on its 3x3 neighbourhood only: run it over tiles with a one-cell halo.
    """
    z = np.asarray(surface_h_m, dtype=np.float64)
    dem = np.where(np.isfinite(z), z, np.nanmean(z) if np.isfinite(z).any() else 0.0)
    shade = hillshade(dem, cell_m, -cell_m, sun_azimuth_deg, sun_elevation_deg)
    refl = texture(x_m, y_m, np.asarray(classes).astype(np.uint8), seed)
    if date_change > 0:
        cs = seed if change_seed is None else change_seed
        w = date_change_weight(x_m, y_m, derive_seed(cs, "date-change"), date_change)
        kind = date_change_kind(x_m, y_m, derive_seed(cs, "date-change-kind"))
        refl = apply_date_change(refl, w, kind)
        cloud = w * (kind == ChangeKind.CLOUD)
        shade = shade * (1 - cloud) + cloud  # clouds are not shaded by the terrain below
    return illuminate(refl, shade, ambient)


def radiance_to_dn(radiance: ArrayLike, noise_sigma_dn: float, bits: int, seed: int,
                   rows: ArrayLike, cols: ArrayLike,
                   gain_dn: float | None = None) -> NDArray[np.uint8] | NDArray[np.uint16]:
    """Digital numbers: ``rint(gain * radiance + noise)``, clipped to the range of ``bits``.

    The noise is ``noise_sigma_dn * hash_normal(seed, rows, cols)``: a pure
    function of the image pixel, so tiles of an image reproduce exactly. Use a
    different ``seed`` (``derive_seed(seed, "left")``) per image.

    Args:
        radiance: ground radiance (:func:`illuminate`), 1 for a white surface in full sun.
        noise_sigma_dn: standard deviation of the sensor noise, DN (>= 0).
        bits: 8 (uint8 out) or 12 (uint16 out, values up to 4095).
        seed: noise seed.
        rows, cols: integer image row and column of each pixel (global to the image).
        gain_dn: DN of radiance 1; default 80 % of the range.

    Returns:
        uint8 or uint16 array of the broadcast shape; NaN inputs give 0.
    """
    if bits not in (8, 12):
        raise InputError(f"bits must be 8 or 12, got {bits!r}")
    if not noise_sigma_dn >= 0:
        raise InputError(f"noise_sigma_dn must be >= 0, got {noise_sigma_dn!r}")
    dn_max = float(2**bits - 1)
    gain = 0.8 * dn_max if gain_dn is None else float(gain_dn)
    signal = gain * np.asarray(radiance, dtype=np.float64)
    noise = noise_sigma_dn * hash_normal(seed, rows, cols)
    dn = np.clip(np.rint(signal + noise), 0.0, dn_max)
    dn = np.where(np.isnan(dn), 0.0, dn)
    return dn.astype(np.uint8 if bits == 8 else np.uint16)


def render_dn(model: SensorModel, rows: NDArray, cols: NDArray, levels: tuple[float, float, float],
              to_xy: ToXY, read_surface: SurfaceReader, read_radiance: SurfaceReader,
              noise_sigma_dn: float, bits: int,
              seed: int) -> NDArray[np.uint8] | NDArray[np.uint16]:
    """DN of the image block ``rows x cols``: each pixel's line of sight is cast on the surface
    (:func:`core.simulation.raycast.cast_on_surface`, occlusions included) and the ground
    radiance is sampled bilinearly where it lands. ``read_surface``/``read_radiance`` give the
    grids (frame of ``to_xy``) covering some ground bounds. Zero where no surface is under the
    block.
    """
    shape = (rows.size, cols.size)
    rays = image_rays(model, rows, cols, levels, to_xy)
    hit = cast_on_surface(rays, read_surface, tol_m=0.01)
    if hit is None:
        return np.zeros(shape, dtype=np.uint8 if bits == 8 else np.uint16)
    x, y = hit
    radiance = read_radiance(rays.ground_bounds())
    L = radiance.sample(x, y) if radiance is not None else np.full(x.shape, np.nan)
    rr, cc = np.meshgrid(rows, cols, indexing="ij")
    return radiance_to_dn(L.reshape(shape), noise_sigma_dn, bits, seed, rr, cc)
