"""An SRTM-like reference DEM of a simulated world: the bare terrain as SRTM would have measured
it, so that GCP-free orientation is never tested against the truth itself.

SRTM differs from the world by (Rodriguez et al. 2006; Farr et al. 2007): a posting of 3"
(no detail finer than ~90 m), spatially correlated height errors of a few metres (long
wavelength: the mission's attitude and baseline errors, short: speckle and slope effects),
a planimetric misregistration of a few metres, voids on steep slopes (radar shadow and
layover), and no canopy (the C band reaches partly into the trees; the bare terrain is the
simpler, harder stand-in). :func:`srtm_like` applies these to heights sampled by the caller
at shifted node positions.

With ``--errors realistic`` (:meth:`ReferenceErrors.drawn_realistic`) the reference has what
SRTM is measured to have instead: C-band partial penetration (SRTM's phase centre lies part
way down the canopy: it shows 30-70 % of the canopy and building height, drawn per forest
stand; :func:`seen_surface`), a misregistration up to 10 m, noise growing with slope (SRTM's
height error grows with the terrain slope, from ~4 m on flat ground to more than twice that on
steep slopes: Falorni et al. 2005, Gorokhovich and Voustianiouk 2006), voids where SRTM's own
radar shadow and layover fall for its look direction and incidence (30-58 degrees;
:func:`radar_voids`), and a long-wavelength tilt up to 2 m across the scene (the residual
roll and baseline errors of the mission, Rodriguez et al. 2006).
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
    # realistic errors (all off by default): the canopy and building height share seen, drawn
    # per stand of ``stand_m`` squares from ``canopy_seen``; noise std ``slope_noise_m`` per
    # unit tan(slope); a tilt in m/km about ``tilt_origin_m`` (projected x, y); SRTM's radar
    # shadow and layover for a look of ``radar_incidence_deg`` (0: none) towards
    # ``radar_look_azimuth_deg`` (from the radar to the ground, clockwise from north)
    canopy_seen: tuple[float, float] = (0.0, 0.0)
    stand_m: float = 400.0
    slope_noise_m: float = 0.0
    tilt_east_m_per_km: float = 0.0
    tilt_north_m_per_km: float = 0.0
    tilt_origin_m: tuple[float, float] = (0.0, 0.0)
    radar_incidence_deg: float = 0.0
    radar_look_azimuth_deg: float = 0.0

    def __post_init__(self) -> None:
        if not (self.noise_m >= 0 and self.correlation_m > 0 and 0 < self.void_slope_deg <= 90
                and 0 <= self.void_share <= 1):
            raise InputError("reference errors: need noise_m >= 0, correlation_m > 0, "
                             "0 < void_slope_deg <= 90 and 0 <= void_share <= 1")
        lo, hi = self.canopy_seen
        if not (0 <= lo <= hi <= 1 and self.stand_m > 0 and self.slope_noise_m >= 0
                and 0 <= self.radar_incidence_deg < 90):
            raise InputError("reference errors: need 0 <= canopy_seen min <= max <= 1, "
                             "stand_m > 0, slope_noise_m >= 0, 0 <= radar_incidence_deg < 90")

    @classmethod
    def drawn(cls, seed: int, max_shift_m: float = 5.0, **kw: float) -> ReferenceErrors:
        """Errors with a misregistration drawn from ``seed`` (uniform direction, magnitude up
        to ``max_shift_m``)."""
        u = hash_uniform(derive_seed(seed, "reference-shift"), np.arange(2))
        angle, size = 2 * np.pi * float(u[0]), max_shift_m * float(u[1])
        return cls(shift_east_m=size * np.sin(angle), shift_north_m=size * np.cos(angle), **kw)

    @classmethod
    def drawn_realistic(cls, seed: int, origin_m: tuple[float, float],
                        extent_m: float) -> ReferenceErrors:
        """The errors SRTM has (module docstring), drawn from ``seed``: misregistration up to
        10 m, canopy seen 30-70 % per stand, slope noise, a tilt up to 2 m over ``extent_m``
        about ``origin_m``, SRTM's look from an ascending or descending pass."""
        u = hash_uniform(derive_seed(seed, "reference-realistic"), np.arange(5))
        tilt = 2.0 * float(u[0]) / (extent_m / 1000.0)  # m/km: up to 2 m across the scene
        az = 2 * np.pi * float(u[1])
        heading = 20.0 if u[3] < 0.5 else 160.0  # SRTM's 57 deg orbit at mid latitudes
        return cls.drawn(
            seed, max_shift_m=10.0, void_share=0.0, canopy_seen=(0.3, 0.7),
            slope_noise_m=10.0, tilt_east_m_per_km=tilt * float(np.sin(az)),
            tilt_north_m_per_km=tilt * float(np.cos(az)),
            tilt_origin_m=(float(origin_m[0]), float(origin_m[1])),
            radar_incidence_deg=30.0 + 28.0 * float(u[2]),
            radar_look_azimuth_deg=float(np.mod(heading + 90.0 if u[4] < 0.5 else heading - 90.0,
                                                360.0)),
        )


def canopy_fraction_seen(x_m: ArrayLike, y_m: ArrayLike, seed: int,
                         errors: ReferenceErrors) -> FloatArray:
    """The share of the canopy and building height the reference sees at projected points:
    one value per stand (``stand_m`` squares), uniform in ``errors.canopy_seen``."""
    lo, hi = errors.canopy_seen
    x, y = np.broadcast_arrays(np.asarray(x_m, dtype=np.float64), np.asarray(y_m, dtype=np.float64))
    u = hash_uniform(derive_seed(seed, "reference-canopy"),
                     np.floor(x / errors.stand_m).astype(np.int64),
                     np.floor(y / errors.stand_m).astype(np.int64))
    return lo + (hi - lo) * u


def seen_surface(dtm_m: ArrayLike, dsm_m: ArrayLike, x_m: ArrayLike, y_m: ArrayLike, seed: int,
                 errors: ReferenceErrors) -> FloatArray:
    """What a C-band radar sees: the bare terrain plus the stand's share of the canopy and
    building height above it (the bare terrain when ``canopy_seen`` is (0, 0))."""
    dtm = np.asarray(dtm_m, dtype=np.float64)
    if errors.canopy_seen == (0.0, 0.0):
        return dtm
    above = np.maximum(np.asarray(dsm_m, dtype=np.float64) - dtm, 0.0)
    return dtm + canopy_fraction_seen(x_m, y_m, seed, errors) * above


def radar_voids(h_m: ArrayLike, dx_m: float, dy_m: float, errors: ReferenceErrors) -> NDArray:
    """Where SRTM's own radar geometry leaves holes on a north-up grid of heights (rows to the
    south, ``dx_m``/``dy_m`` the column and row spacings): layover where the slope facing the
    radar is steeper than the incidence, shadow where the slope facing away is steeper than its
    complement (local slopes; none when ``radar_incidence_deg`` is 0)."""
    h = np.asarray(h_m, dtype=np.float64)
    if errors.radar_incidence_deg == 0 or min(h.shape) < 2:
        return np.zeros(h.shape, dtype=bool)
    dh_drow, dh_dcol = np.gradient(h, dy_m, dx_m)
    gx, gy = dh_dcol, -dh_drow  # east, north
    az = np.radians(errors.radar_look_azimuth_deg)
    rise_away = gx * np.sin(az) + gy * np.cos(az)  # terrain rising along the look: faces radar
    slope_along = np.degrees(np.arctan(np.where(np.isfinite(rise_away), rise_away, 0.0)))
    inc = errors.radar_incidence_deg
    return (slope_along > inc) | (slope_along < -(90.0 - inc))


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
    out = h + noise
    if errors.slope_noise_m > 0:  # short-wavelength noise growing with tan(slope)
        tan = np.tan(np.radians(np.asarray(slope_deg, dtype=np.float64)))
        out = out + tan * fractal_detail_m(x, y, derive_seed(seed, "reference-slope-noise"),
                                           errors.slope_noise_m, 90.0, 360.0, 0.9)
    if errors.tilt_east_m_per_km or errors.tilt_north_m_per_km:
        x0, y0 = errors.tilt_origin_m
        out = out + (errors.tilt_east_m_per_km * (x - x0)
                     + errors.tilt_north_m_per_km * (y - y0)) / 1000.0
    return np.where(holes, np.nan, out)
