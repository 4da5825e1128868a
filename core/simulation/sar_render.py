"""The SAR simulator's rendering and radiometry (pure numerics, no I/O); the geometry is
:mod:`core.simulation.sar`.

**Rendering** (:func:`render_block`): every ground cell of the truth DSM (oversampled
``oversample`` x ``oversample``, heights bilinear) goes to its true image position (zero
Doppler on :class:`~core.simulation.sar.OrbitFit` of the true orbit, then the true model's
image coordinates), carries ``sigma0(local incidence, land cover) x its surface area`` and is
splatted bilinearly (energy and centroid preserved) into the image, normalised by the
flat-ground area of one pixel, so flat terrain shows its sigma0. Cells hidden from the sensor
by terrain between them and the sensor (a ray march on the DSM, compiled with Numba) add
nothing (shadow); ground that folds over (layover: terrain rising away from the sensor more
steeply than the incidence) lands where the geometry puts it, summed with the ground before
it. The layover and shadow flags of every cell are returned too.

**Radiometry** (:func:`speckle_and_noise`, :func:`to_dn`): the intensity plus thermal noise at
the mission's NESZ, times a unit-mean gamma variate of shape L (the looks the product
implies); amplitude DN = round(sqrt(I) * DN_PER_AMPLITUDE) as uint16. Corner reflectors
(:func:`point_targets`) are coherent: added after the speckle.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numba import njit
from numpy.typing import NDArray

from core.dem import sample_bilinear
from core.errors import InputError
from core.geodesy import enu_rotation, geodetic_to_ecef
from core.sensors.sar import SPEED_OF_LIGHT_M_S, SarModel
from core.simulation.landcover import LandCover
from core.simulation.sar import OrbitFit

FloatArray = NDArray[np.float64]
ToLonLat = Callable[[FloatArray, FloatArray], tuple[FloatArray, FloatArray]]

DN_PER_AMPLITUDE = 1000.0  # DN = sqrt(sigma0) * 1000 (uint16): sigma0 = (DN / 1000)^2


# ---------------------------------------------------------------------------- backscatter


# sigma0 (dB) at 30 deg local incidence and its slope (dB per degree), C band, co-polarised;
# forest is a volume: gamma0 constant, sigma0 = gamma0 cos(theta)
SIGMA0_DB: dict[int, tuple[float, float]] = {
    int(LandCover.BARE_SOIL): (-11.0, -0.25),
    int(LandCover.URBAN): (-4.0, -0.10),
    int(LandCover.WATER): (-19.0, -0.50),
}
FOREST_GAMMA0_DB = -7.0


def sigma0(local_incidence_rad: FloatArray, classes: NDArray) -> FloatArray:
    """Backscatter coefficient (linear) of facets at their local incidence; 0 for facets
    turned away from the sensor (local incidence >= 90 deg)."""
    th = np.asarray(local_incidence_rad, dtype=np.float64)
    deg = np.degrees(th)
    out = np.zeros(th.shape)
    cls = np.asarray(classes)
    for c, (db30, slope) in SIGMA0_DB.items():
        sel = cls == c
        out[sel] = 10.0 ** ((db30 + slope * (deg[sel] - 30.0)) / 10.0)
    sel = cls == int(LandCover.FOREST)
    out[sel] = 10.0 ** (FOREST_GAMMA0_DB / 10.0) * np.cos(th[sel])
    return np.where(th < 0.5 * np.pi, out, 0.0)


# ---------------------------------------------------------------------------- rendering


@dataclass(frozen=True, eq=False)
class GroundBlock:
    """A block of the truth grid with its halo: heights ``dsm_m`` (rows to the south, NaN
    where unknown) and ``classes`` on cells of ``res_m`` whose cell (0, 0) has its centre at
    (``x0_m``, ``y0_m``); the cells to render are rows ``r0..r1-1``, columns ``c0..c1-1``."""

    dsm_m: FloatArray
    classes: NDArray
    x0_m: float
    y0_m: float
    res_m: float
    r0: int
    r1: int
    c0: int
    c1: int


@dataclass(frozen=True, eq=False)
class RenderedBlock:
    """Intensity (sigma0-calibrated, before speckle) added by one block to the image window
    whose pixel (0, 0) is image pixel (``col0``, ``row0``); per rendered cell the flags
    ``shadow`` and ``layover`` (the block's r0..r1, c0..c1)."""

    col0: int
    row0: int
    intensity: FloatArray
    shadow: NDArray[np.bool_]
    layover: NDArray[np.bool_]


def render_block(truth: SarModel, fit: OrbitFit, block: GroundBlock, to_lonlat: ToLonLat,
                 oversample: int, pixel_area_m2: Callable[[FloatArray], FloatArray]
                 ) -> RenderedBlock:
    """The intensity one block of ground adds to the image (see the module docstring).

    ``pixel_area_m2(incidence_rad)`` is the flat-ground area of one pixel at an ellipsoid
    incidence (slant-range products: azimuth spacing x slant spacing / sin(incidence)).
    """
    b, k = block, int(oversample)
    rows, cols = b.r1 - b.r0, b.c1 - b.c0
    # sub-cell centres in fractional cell indices of the block's arrays
    sub = (np.arange(k) + 0.5) / k - 0.5
    rr = (b.r0 + np.arange(rows)[:, None] + sub[None, :]).ravel()
    cc = (b.c0 + np.arange(cols)[:, None] + sub[None, :]).ravel()
    R, C = np.meshgrid(rr, cc, indexing="ij")
    R, C = R.ravel(), C.ravel()
    h = sample_bilinear(b.dsm_m, R, C)
    cls = b.classes[np.clip(np.rint(R).astype(np.int64), 0, b.classes.shape[0] - 1),
                    np.clip(np.rint(C).astype(np.int64), 0, b.classes.shape[1] - 1)]
    x = b.x0_m + C * b.res_m
    y = b.y0_m - R * b.res_m
    lon, lat = to_lonlat(x, y)
    ok = np.isfinite(h)
    g = np.stack(geodetic_to_ecef(lon, lat, np.where(ok, h, 0.0)), axis=1)
    t, rng_m, s = fit.zero_doppler(g, fit.t_mid)
    look = (s - g) / rng_m[:, None]  # unit vectors ground -> sensor
    enu = enu_rotation(lon, lat)  # (n, 3, 3)
    up = enu[:, 2, :]
    gx, gy = _grid_axes(x, y, to_lonlat, enu)
    cos_inc = np.einsum("ij,ij->i", up, look)
    # the surface normal from the DSM gradient (east, north in the grid), rotated to ECEF
    d, z = 0.5 / k, b.dsm_m
    dzdx = (sample_bilinear(z, R, C + d) - sample_bilinear(z, R, C - d)) / (2 * d * b.res_m)
    dzdy = (sample_bilinear(z, R - d, C) - sample_bilinear(z, R + d, C)) / (2 * d * b.res_m)
    dzdx, dzdy = np.nan_to_num(dzdx), np.nan_to_num(dzdy)
    n_local = np.stack([-dzdx, -dzdy, np.ones_like(dzdx)], axis=1)
    n_local /= np.linalg.norm(n_local, axis=1, keepdims=True)
    normal = n_local[:, :1] * gx + n_local[:, 1:2] * gy + n_local[:, 2:] * up
    cos_loc = np.einsum("ij,ij->i", normal, look)
    # horizontal unit direction towards the sensor (grid east, north) and its elevation
    le, ln = np.einsum("nj,nj->n", gx, look), np.einsum("nj,nj->n", gy, look)
    hn = np.hypot(le, ln)
    ue, un = le / hn, ln / hn
    tan_e = cos_inc / hn
    # layover: the terrain rises away from the sensor faster than the line of sight falls
    rise_away = -(dzdx * ue + dzdy * un)
    layover = rise_away > 1.0 / tan_e
    shadow = _ray_shadow(b, R, C, h, ue, un, tan_e)
    area = (b.res_m / k) ** 2 / n_local[:, 2]  # the facet's surface area
    power = sigma0(np.arccos(np.clip(cos_loc, -1.0, 1.0)), cls) * area \
        / pixel_area_m2(np.arccos(np.clip(cos_inc, -1.0, 1.0)))
    power = np.where(ok & ~shadow, power, 0.0)
    col, row = truth.image_of_times(t + truth.azimuth_offset_s,
                                    2.0 * rng_m / SPEED_OF_LIGHT_M_S + truth.range_delay_s)
    img, c0, r0 = splat(col, row, power)
    flags = (rows, k, cols, k)
    return RenderedBlock(c0, r0, img, shadow.reshape(flags).any(axis=(1, 3)),
                         layover.reshape(flags).any(axis=(1, 3)))


def _grid_axes(x: FloatArray, y: FloatArray, to_lonlat: ToLonLat, enu: FloatArray
               ) -> tuple[FloatArray, FloatArray]:
    """The projected grid's x and y axes (n, 3) in ECEF at each point: its east and north
    turned by the projection's convergence, taken at the points' mean position."""
    xm, ym = np.array([np.mean(x), np.mean(x) + 100.0]), np.array([np.mean(y)] * 2)
    glon, glat = to_lonlat(xm, ym)
    pe = np.array(geodetic_to_ecef(glon, glat, 0.0)).T
    de = enu_rotation(glon[0], glat[0]) @ (pe[1] - pe[0])
    gam = np.arctan2(de[1], de[0])  # grid x relative to true east, counter-clockwise
    return (np.cos(gam) * enu[:, 0, :] + np.sin(gam) * enu[:, 1, :],
            -np.sin(gam) * enu[:, 0, :] + np.cos(gam) * enu[:, 1, :])


def _ray_shadow(b: GroundBlock, R: FloatArray, C: FloatArray, h: FloatArray, ue: FloatArray,
                un: FloatArray, tan_e: FloatArray) -> NDArray[np.bool_]:
    """Whether the DSM rises above the line of sight between each point and the sensor:
    march towards the sensor in steps of half a cell while the ray is below the block's
    highest cell (the block's halo must reach that far; beyond the block: not shadowed)."""
    z = np.ascontiguousarray(b.dsm_m, dtype=np.float64)
    return _ray_shadow_kernel(z, float(np.nanmax(z)), R, C, h, ue, un, tan_e * b.res_m)


@njit(cache=True)
def _ray_shadow_kernel(z: FloatArray, top: float, R: FloatArray, C: FloatArray, h: FloatArray,
                       ue: FloatArray, un: FloatArray, rise_per_cell: FloatArray
                       ) -> NDArray[np.bool_]:  # pragma: no cover - compiled
    n_r, n_c = z.shape
    out = np.zeros(R.size, dtype=np.bool_)
    for i in range(R.size):
        if not np.isfinite(h[i]):
            continue
        k = 1
        while True:
            d = 0.5 * k
            ray = h[i] + d * rise_per_cell[i]
            if ray >= top:
                break
            r = R[i] - d * un[i]
            c = C[i] + d * ue[i]
            r0 = int(np.floor(r))
            c0 = int(np.floor(c))
            if r0 < 0 or c0 < 0 or r0 >= n_r - 1 or c0 >= n_c - 1:
                break
            fr = r - r0
            fc = c - c0
            v = (z[r0, c0] * (1 - fr) * (1 - fc) + z[r0, c0 + 1] * (1 - fr) * fc
                 + z[r0 + 1, c0] * fr * (1 - fc) + z[r0 + 1, c0 + 1] * fr * fc)
            if not np.isfinite(v):
                break
            if v > ray + 1e-6:
                out[i] = True
                break
            k += 1
    return out


def splat(col: FloatArray, row: FloatArray, w: FloatArray) -> tuple[FloatArray, int, int]:
    """Bilinear splatting of weights at fractional (col, row) into the smallest window that
    holds them: (window, col0, row0). Sum and centroid of the weights are preserved."""
    ok = np.isfinite(col) & np.isfinite(row) & (w != 0)
    if not ok.any():
        return np.zeros((0, 0)), 0, 0
    col, row, w = col[ok], row[ok], w[ok]
    ci, ri = np.floor(col).astype(np.int64), np.floor(row).astype(np.int64)
    fc, fr = col - ci, row - ri
    c0, r0 = int(ci.min()), int(ri.min())
    width, height = int(ci.max()) - c0 + 2, int(ri.max()) - r0 + 2
    idx = (ri - r0) * width + (ci - c0)
    out = np.zeros(width * height)
    for di, wt in ((0, (1 - fr) * (1 - fc)), (1, (1 - fr) * fc), (width, fr * (1 - fc)),
                   (width + 1, fr * fc)):
        out += np.bincount(idx + di, weights=w * wt, minlength=out.size)
    return out.reshape(height, width), c0, r0


def add_window(image: FloatArray, window: FloatArray, col0: int, row0: int) -> None:
    """Add a window whose pixel (0, 0) is image pixel (col0, row0), clipped to the image."""
    if window.size == 0:
        return
    h, w = window.shape
    r0, c0 = max(row0, 0), max(col0, 0)
    r1, c1 = min(row0 + h, image.shape[0]), min(col0 + w, image.shape[1])
    if r1 > r0 and c1 > c0:
        image[r0:r1, c0:c1] += window[r0 - row0:r1 - row0, c0 - col0:c1 - col0]


def speckle_and_noise(intensity: FloatArray, looks: float, nesz: float,
                      rng: np.random.Generator) -> FloatArray:
    """L-look intensity: the clean intensity plus thermal noise (``nesz``, linear), times a
    unit-mean gamma variate of shape L (fully developed speckle averaged over L looks)."""
    if not looks > 0:
        raise InputError(f"looks must be > 0, got {looks}")
    g = rng.standard_gamma(looks, size=intensity.shape) / looks
    return (intensity + nesz) * g


def to_dn(intensity: FloatArray) -> NDArray[np.uint16]:
    """uint16 amplitude DN: round(sqrt(I) * DN_PER_AMPLITUDE), clipped to 1..65535 (0 is
    nodata)."""
    a = np.sqrt(np.maximum(intensity, 0.0)) * DN_PER_AMPLITUDE
    return np.clip(np.rint(a), 1, 65535).astype(np.uint16)


def point_targets(truth: SarModel, lon_deg: FloatArray, lat_deg: FloatArray, h_m: FloatArray,
                  rcs_m2: float, pixel_area_m2: Callable[[FloatArray], FloatArray]
                  ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Corner reflectors of radar cross-section ``rcs_m2``: their true image (col, row) and
    the intensity each adds (rcs over one pixel's flat-ground area), to be splatted after
    speckle (a point target is coherent: no speckle)."""
    col, row = truth.project(lon_deg, lat_deg, h_m)
    los = truth.line_of_sight_ecef(col, row, h_m)
    up = enu_rotation(lon_deg, lat_deg)[..., 2, :].reshape(-1, 3)
    inc = np.arccos(np.clip(np.einsum("ij,ij->i", up, los), -1, 1))
    return col, row, rcs_m2 / pixel_area_m2(inc)



def reflector_cells(mask: NDArray, shape_rc: tuple[int, int], n: int,
                    rng: np.random.Generator, border: int) -> tuple[NDArray, NDArray]:
    """Up to ``n`` (row, col) cells of a grid of ``shape_rc`` for corner reflectors: drawn at
    random at least ``border`` cells from the edges, where ``mask`` (the layover/shadow
    flags, same shape) is 0 in the 5x5 cells around."""
    rows, cols = [], []
    h, w = shape_rc
    for _ in range(50 * n):
        r, c = (int(rng.integers(border, h - border)), int(rng.integers(border, w - border)))
        if not np.any(mask[r - 2:r + 3, c - 2:c + 3]) and all(
                abs(r - r2) + abs(c - c2) > 2 * border // max(n, 1) for r2, c2 in zip(rows, cols)):
            rows.append(r)
            cols.append(c)
        if len(rows) == n:
            break
    return np.array(rows, dtype=np.int64), np.array(cols, dtype=np.int64)
