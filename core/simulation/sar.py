"""The SAR scene simulator's kernels: an ERS-like or Sentinel-1-like product of the truth world.

Pure numerics (no I/O). Here the geometry and the annotation's content; the rendering and
the radiometry are :mod:`core.simulation.sar_render`.

**Geometry** (:func:`sar_models`): a circular orbit solved so that the scene centre is seen
at zero Doppler, to the right, at the mission's incidence; the image grid sized to cover the
given ground points; the *true* :class:`~core.sensors.sar.SarModel` (true orbit, the image's
true timing) and the *delivered* one (what the annotation states: the orbit with the
mission's orbit error, the timing without the azimuth-time and range-delay errors). The
truth is the delivered model with the true orbit and the drawn errors as its corrections
(``azimuth_offset_s``, ``range_delay_s``), so an adjustment of those two parameters recovers
them where the orbit error is negligible (Sentinel-1-like) and absorbs most of it otherwise
(ERS-like). :class:`OrbitFit` gives zero-Doppler times of many points fast (polynomials fitted
to the orbit's own interpolation; agrees with :meth:`SarModel.zero_doppler` to 1e-6 px).
**Annotation content**: the geolocation grid (:func:`geolocation_grid`) and the inverse
ground-to-slant polynomials (:func:`grsr_coefficients`) of a product.

Mission figures (:data:`MISSIONS`), with where they come from:

- ERS-1/2 (C band, 5.3 GHz): 785-790 km altitude, 98.5 deg inclination, 23 deg mid-swath
  incidence, right-looking; range sampling 18.96 MHz (7.9 m slant, ~20 m on the ground at
  23 deg), PRF ~1680 Hz (~4 m along track per SLC line). The simulated product is a
  *slant-range, multi-looked amplitude* product (ERS SLC timing, 5 azimuth looks: ~20 x 20 m
  on the ground, L = 5), annotated as kind ``slc`` (slant-range geometry). Delivered
  geolocation of the ~10 m class: the precise orbits (D-PAF/DEOS) reach 5-10 cm radially, but
  the state vectors in delivered products are restituted/predicted ones with metre-level to
  10 m along-track errors, and the products had azimuth time-tag and range (electronic delay)
  biases of some metres; the figures below (1 sigma: orbit 5 m along, 3 m across, 1 m radial;
  azimuth time 1 ms = 6.6 m; instrument range bias 3 m) are chosen to give that ~10 m class,
  not measured here.
- Sentinel-1 IW GRD (C band, 5.405 GHz): 693 km, 98.18 deg, IW swath 29-46 deg (the scene is a
  piece of it, centred at 38 deg), right-looking; GRDH 10 m pixels, ENL 4.4 (ESA's product
  definition); range sampling rate 64.345 MHz as in the annotations. Absolute geolocation
  of a few metres before corrections (Schubert et al., Remote Sensing 2015 and 2017: ALE of
  IW products ~2-3 m, dominated by the uncorrected tropospheric path delay and azimuth
  timing biases; restituted orbits ~5-10 cm): orbit 0.05 m per axis, azimuth time 0.3 ms
  (~2 m), instrument range bias 0.5 m (1 sigma).
- Both: the tropospheric path delay, its hydrostatic part 2.3 m at zenith at sea level
  scaled by exp(-h/7 km), its wet part drawn in 5-30 cm at zenith (the mid-latitude range of
  the zenith wet delay, which no standard atmosphere predicts: Bevis et al. 1992, Schubert
  et al. 2017), both by 1/cos(incidence) (one way), added to the random range bias (it is
  what products really lack, Schubert et al.). A processor can take out the hydrostatic part
  with a standard atmosphere (:func:`core.sensors.sar.standard_tropospheric_delay_m`); the
  wet part stays.

Scaling: presets coarser than 10 m (``pixel_scale`` > 1, the tiny preset) multiply both pixel
spacings by ``pixel_scale`` and the looks by its square (the product implies averaging that
many independent nominal pixels).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass, replace

import numpy as np
from numpy.polynomial import polynomial as P
from numpy.typing import NDArray
from scipy import optimize

from core.errors import ConvergenceError, InputError
from core.geodesy import WGS84_A_M, enu_rotation, geodetic_to_ecef
from core.sensors.orbit import GM_EARTH_M3_S2, Orbit, circular_orbit_ecef, orbital_frame
from core.sensors.sar import SPEED_OF_LIGHT_M_S, SarModel
from core.sensors.sentinel1 import GeolocationGrid

FloatArray = NDArray[np.float64]
ToLonLat = Callable[[FloatArray, FloatArray], tuple[FloatArray, FloatArray]]

ZENITH_DELAY_M = 2.3  # tropospheric path delay at zenith, sea level (one way)
TROPO_SCALE_HEIGHT_M = 7000.0
ZENITH_WET_DELAY_M = (0.05, 0.30)  # the zenith wet delay's range at mid latitudes
STATE_VECTOR_SPACING_S = 10.0  # as Sentinel-1 annotations
SRGR_RECORD_SPACING_S = 1.0  # slant-to-ground records, about every second as in S1 GRD
SRGR_DEGREE = 5


@dataclass(frozen=True)
class SarMission:
    """One mission's geometry, sampling, radiometry and delivered-product errors (1 sigma)."""

    name: str
    mission_id: str  # adsHeader/missionId of the annotation
    mode: str
    kind: str  # "slc" (slant range) or "grd" (ground range)
    altitude_m: float
    inclination_deg: float
    incidence_deg: float  # at the scene centre
    radar_frequency_hz: float
    range_sampling_rate_hz: float  # annotation rangeSamplingRate
    range_spacing_m: float  # slant (slc) or ground (grd) pixel spacing at scale 1
    azimuth_spacing_m: float  # along-track pixel spacing at scale 1
    looks: float  # independent looks of one pixel at scale 1 (ENL)
    nesz_db: float
    orbit_sigma_m: tuple[float, float, float]  # along, across, radial
    azimuth_time_sigma_s: float
    range_bias_sigma_m: float  # instrument range bias, one way, metres of slant range
    epoch_utc: str  # time of the first state vector
    ascending: bool = False

    def __post_init__(self) -> None:
        if self.kind not in ("slc", "grd"):
            raise InputError(f"SAR mission {self.name}: kind must be slc or grd")


MISSIONS: dict[str, SarMission] = {
    "ers": SarMission(
        "ers", "ERS2", "SM", "slc", altitude_m=790e3, inclination_deg=98.52,
        incidence_deg=23.0, radar_frequency_hz=5.3e9, range_sampling_rate_hz=18.962468e6,
        range_spacing_m=SPEED_OF_LIGHT_M_S / (2 * 18.962468e6), azimuth_spacing_m=20.0,
        looks=5.0, nesz_db=-24.0, orbit_sigma_m=(5.0, 3.0, 1.0), azimuth_time_sigma_s=1e-3,
        range_bias_sigma_m=3.0, epoch_utc="2023-07-12T10:05:00Z"),
    "s1": SarMission(
        "s1", "S1A", "IW", "grd", altitude_m=693e3, inclination_deg=98.18,
        incidence_deg=38.0, radar_frequency_hz=5.405e9, range_sampling_rate_hz=64345238.12571428,
        range_spacing_m=10.0, azimuth_spacing_m=10.0, looks=4.4, nesz_db=-22.0,
        orbit_sigma_m=(0.05, 0.05, 0.05), azimuth_time_sigma_s=3e-4, range_bias_sigma_m=0.5,
        epoch_utc="2023-07-12T05:50:00Z"),
}


def mission(name: str) -> SarMission:
    if name not in MISSIONS:
        raise InputError(f"SAR mission {name!r} unknown; use one of {sorted(MISSIONS)}")
    return MISSIONS[name]


@dataclass(frozen=True)
class SarErrors:
    """What the delivered annotation gets wrong (the truth record): the orbit offset in the
    local orbital frame (m), the azimuth-time offset (s, delivered image times minus true
    zero-Doppler ones: the truth model's ``azimuth_offset_s``), the range delay (two-way s,
    the truth model's ``range_delay_s``) and its parts in metres of one-way slant range."""

    orbit_along_m: float
    orbit_across_m: float
    orbit_radial_m: float
    azimuth_offset_s: float
    range_delay_s: float
    range_troposphere_m: float
    range_instrument_m: float

    def to_dict(self) -> dict[str, float]:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> SarErrors:
        try:
            return cls(**{k: float(d[k]) for k in cls.__dataclass_fields__})
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f"SAR error record is malformed ({exc!r})") from None


@dataclass(frozen=True, eq=False)
class SarModels:
    truth: SarModel
    delivered: SarModel
    errors: SarErrors
    looks: float
    nesz: float  # linear
    ground_spacing_m: tuple[float, float]  # (range, azimuth) on flat ground at the centre

    def centre_error_m(self, h_m: float) -> float:
        """Ground distance between what the delivered and the true model localise for the
        centre pixel at height ``h_m``."""
        d, t = self.delivered, self.truth
        c, r = 0.5 * (d.n_cols - 1), 0.5 * (d.n_rows - 1)
        pd = np.array(geodetic_to_ecef(*d.localize(c, r, h_m), h_m)).ravel()
        pt = np.array(geodetic_to_ecef(*t.localize(c, r, h_m), h_m)).ravel()
        return float(np.linalg.norm(pd - pt))

    def pixel_area_m2(self, incidence_rad: FloatArray) -> FloatArray:
        """Flat-ground area of one pixel at an ellipsoid incidence: azimuth spacing times
        the ground range spacing (slant spacing / sin(incidence) for slant-range products)."""
        m = self.truth
        az = self.ground_spacing_m[1]
        if m.kind == "grd":
            return np.full(np.shape(incidence_rad), az * m.range_pixel_spacing_m)
        dr = SPEED_OF_LIGHT_M_S / (2.0 * m.range_sampling_rate_hz)
        return az * dr / np.sin(np.asarray(incidence_rad, dtype=np.float64))


def _round_us(t_s: float) -> float:
    """A time rounded to the microsecond the way the annotation reader gives it back
    (integer nanoseconds as float64, times 1e-9), so the written model reads back exactly."""
    return float(float(round(t_s * 1e6) * 1000)) * 1e-9


# ---------------------------------------------------------------------------- orbit


def _orbit_of(lat_s: float, lon_s: float, times: FloatArray, t_c: float, radius: float,
              incl: float, ascending: bool) -> tuple[FloatArray, FloatArray]:
    """State vectors of the circular orbit whose sub-satellite point (geocentric, radians) at
    t_c is (lat_s, lon_s)."""
    sin_u = np.clip(np.sin(lat_s) / np.sin(incl), -1.0, 1.0)
    u0 = np.arcsin(sin_u) if ascending else np.pi - np.arcsin(sin_u)
    raan = lon_s - np.arctan2(np.cos(incl) * np.sin(u0), np.cos(u0))
    return circular_orbit_ecef(times, radius_m=radius, inclination_rad=incl, raan_rad=raan,
                               arg_lat0_rad=u0, t_c_s=t_c)


def solve_orbit(m: SarMission, lon_deg: float, lat_deg: float, h_m: float,
                duration_s: float) -> tuple[Orbit, float]:
    """The orbit (state vectors every 10 s, >= 4 of margin each side of ``duration_s``) that
    sees (lon, lat, h) at zero Doppler, to the right, at ``m.incidence_deg``, at its middle
    time t_c; returns (orbit, t_c)."""
    n_sv = int(np.ceil(duration_s / STATE_VECTOR_SPACING_S)) + 9
    # times as the annotation reader gives them back (integer ns as float64, times 1e-9)
    times = (np.arange(n_sv) * round(STATE_VECTOR_SPACING_S * 1e9)).astype(np.float64) * 1e-9
    t_c = float(times[n_sv // 2]) + 0.5 * STATE_VECTOR_SPACING_S
    radius = WGS84_A_M + m.altitude_m
    incl = np.radians(m.inclination_deg)
    target = np.array(geodetic_to_ecef(lon_deg, lat_deg, h_m), dtype=np.float64).ravel()
    up = enu_rotation(lon_deg, lat_deg)[2]
    inc = np.radians(m.incidence_deg)

    def state(x: FloatArray) -> tuple[FloatArray, FloatArray]:
        pos, vel = _orbit_of(x[0], x[1], np.array([t_c]), t_c, radius, incl, m.ascending)
        return pos[0], vel[0]

    def residual(x: FloatArray) -> FloatArray:
        s, v = state(x)
        d = target - s
        cos_i = up @ (-d) / np.linalg.norm(d)
        return np.array([d @ v / np.linalg.norm(v) / 1e3, (np.arccos(cos_i) - inc) * 1e3])

    # first guess: the sub-satellite point left of the track by the ground angle of the view
    lat0, lon0 = np.radians(lat_deg), np.radians(lon_deg)
    _, v = state(np.array([lat0, lon0]))
    e, n = enu_rotation(lon_deg, lat_deg)[:2]
    a = np.array([v @ e, v @ n])
    a /= np.linalg.norm(a)
    right = np.array([a[1], -a[0]])
    gamma = inc - np.arcsin(WGS84_A_M / radius * np.sin(inc))
    move = -right * gamma
    x0 = np.array([lat0 + move[1], lon0 + move[0] / np.cos(lat0)])
    sol = optimize.root(residual, x0, method="hybr", options={"xtol": 1e-14})
    if np.max(np.abs(residual(sol.x))) > 1e-7:
        raise ConvergenceError("SAR simulator: no orbit sees the scene centre at the mission's "
                               "incidence; choose another --center")
    s, v = state(sol.x)
    side = np.cross(-s / np.linalg.norm(s), v / np.linalg.norm(v))
    if (target - s) @ side <= 0:
        raise ConvergenceError("SAR simulator: the solved orbit looks left; report this")
    pos, vel = _orbit_of(sol.x[0], sol.x[1], times, t_c, radius, incl, m.ascending)
    epoch = str(np.datetime64(m.epoch_utc.rstrip("Z"), "ns")) + "Z"  # as the reader writes it
    return Orbit(times, pos, vel, epoch_utc=epoch), t_c


@dataclass(frozen=True, eq=False)
class OrbitFit:
    """Positions and velocities of an orbit as polynomials of ``(t - t_mid) / half`` (fitted to
    the orbit's own interpolation over a time span): fast zero-Doppler for many points."""

    t_mid: float
    half: float
    pos_coef: FloatArray  # (deg + 1, 3)
    vel_coef: FloatArray

    @classmethod
    def of(cls, orbit: Orbit, t0: float, t1: float, degree: int = 9) -> OrbitFit:
        t_mid, half = 0.5 * (t0 + t1), max(0.5 * (t1 - t0), 1.0)
        t = t_mid + half * np.cos(np.linspace(0, np.pi, 4 * degree + 1))  # Chebyshev nodes
        pos, vel = orbit.interpolate(t)
        vel = orbit.ground_velocity(pos, vel)
        u = (t - t_mid) / half
        return cls(t_mid, half, P.polyfit(u, pos, degree), P.polyfit(u, vel, degree))

    def state(self, t: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Position, velocity and d(velocity)/dt (m, 3) at times t (m,)."""
        u = ((t - self.t_mid) / self.half)[:, None]
        return (_horner(u, self.pos_coef), _horner(u, self.vel_coef),
                _horner(u, P.polyder(self.vel_coef)) / self.half)

    def zero_doppler(self, g: FloatArray, t_start: float) -> tuple[FloatArray, FloatArray,
                                                                     FloatArray]:
        """Zero-Doppler time, slant range and sensor position of ECEF points (n, 3): the
        Newton iteration of :meth:`SarModel.zero_doppler` on the fitted orbit."""
        t = np.full(g.shape[0], t_start)
        for _ in range(30):
            s, v, a = self.state(t)
            d = g - s
            step = np.einsum("ij,ij->i", d, v) / (np.einsum("ij,ij->i", v, v)
                                                   - np.einsum("ij,ij->i", d, a))
            t = t + step
            if not np.any(np.abs(step) > 1e-10):
                s, _, _ = self.state(t)
                return t, np.linalg.norm(g - s, axis=1), s
        raise ConvergenceError("SAR simulator: zero-Doppler time did not converge; the ground "
                               "lies outside the orbit span")


def _horner(u: FloatArray, coef: FloatArray) -> FloatArray:
    """Polynomials (deg + 1, 3), power 0 first, at u (m, 1): (m, 3)."""
    out = np.broadcast_to(coef[-1], (u.shape[0], coef.shape[1])).copy()
    for c in coef[-2::-1]:
        out *= u
        out += c
    return out


# ---------------------------------------------------------------------------- models


def _srgr_records(model: SarModel, times: FloatArray, sr0: float, sr1: float,
                  h_ref_m: float) -> FloatArray:
    """Slant-to-ground-range polynomials (one per time, coefficient of power 0 first, in
    metres of ``sr - sr0``): ground range = arc length on the ellipsoid raised by h_ref from
    the near edge, in the zero-Doppler plane (as Sentinel-1 GRD defines it)."""
    sr = np.linspace(sr0, sr1, 400)
    out = []
    for t in times:
        col = (2.0 * sr / SPEED_OF_LIGHT_M_S - model.slant_range_time_s) \
            * model.range_sampling_rate_hz
        row = np.full(sr.shape, (t - model.first_line_time_s) / model.line_interval_s)
        p = model.localize_ecef(col, row, np.full(sr.shape, h_ref_m))
        gr = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])
        scale = sr1 - sr0
        c = P.polyfit((sr - sr0) / scale, gr, SRGR_DEGREE)
        out.append(c / scale ** np.arange(SRGR_DEGREE + 1))
    return np.array(out)


def sar_models(m: SarMission, lon_deg: FloatArray, lat_deg: FloatArray, h_m: FloatArray,
               centre: tuple[float, float, float], h_ref_m: float, pixel_scale: float,
               rng: np.random.Generator, margin_px: int = 8) -> SarModels:
    """True and delivered models of a product covering the ground points (lon, lat, h) with
    ``margin_px`` pixels to spare, centred on ``centre`` (lon, lat, h) seen at the mission's
    incidence; ``h_ref_m`` the terrain height of the GRD projection and of the geolocation
    grid; errors drawn from ``rng``."""
    if not pixel_scale >= 1:
        raise InputError(f"SAR pixel scale must be >= 1, got {pixel_scale}")
    clon, clat, ch = centre
    radius = WGS84_A_M + m.altitude_m
    v_ground = np.sqrt(GM_EARTH_M3_S2 / radius) * WGS84_A_M / radius
    lon, lat, h = (np.ravel(np.asarray(a, dtype=np.float64)) for a in (lon_deg, lat_deg, h_m))
    g = np.stack(geodetic_to_ecef(lon, lat, h), axis=1)
    span = float(np.max(np.linalg.norm(g - g.mean(axis=0), axis=1)))
    orbit, t_c = solve_orbit(m, clon, clat, ch, 3.0 * span / v_ground + 10.0)
    az_m = m.azimuth_spacing_m * pixel_scale
    fs = m.range_sampling_rate_hz
    # a provisional slant-range model: zero-Doppler times and ranges of the points
    probe = SarModel(orbit=orbit, kind="slc", n_cols=1, n_rows=1, first_line_time_s=t_c,
                     line_interval_s=1e-3, slant_range_time_s=0.0, range_sampling_rate_hz=fs)
    dt = az_m / float(probe.along_track_speed_m_s(t_c)[0])
    t, r = probe.zero_doppler(g)
    t0 = _round_us(float(t.min()) - margin_px * dt)
    n_rows = int(np.ceil((float(t.max()) + margin_px * dt - t0) / dt)) + 1
    if m.kind == "slc":
        fs_img = fs / pixel_scale
        dr = SPEED_OF_LIGHT_M_S / (2.0 * fs_img)
    else:
        fs_img, dr = fs, m.range_spacing_m * pixel_scale
    dr_slant = dr if m.kind == "slc" else dr * np.sin(np.radians(m.incidence_deg))
    sr0 = float(r.min()) - margin_px * dr_slant
    tau0 = 2.0 * sr0 / SPEED_OF_LIGHT_M_S
    base = SarModel(orbit=orbit, kind="slc", n_cols=1, n_rows=n_rows, first_line_time_s=t0,
                    line_interval_s=dt, slant_range_time_s=tau0, range_sampling_rate_hz=fs_img,
                    mission=m.mission_id, mode=m.mode)
    if m.kind == "slc":
        n_cols = int(np.ceil((float(r.max()) - sr0) / dr + margin_px)) + 1
        delivered0 = replace(base, n_cols=n_cols, range_pixel_spacing_m=dr)
        ground_rg = dr / np.sin(np.radians(m.incidence_deg))
    else:
        sr1 = float(r.max()) + (margin_px + 2) * dr_slant
        t_end = t0 + n_rows * dt
        rec_t = np.array([_round_us(x) for x in np.arange(
            t0 - SRGR_RECORD_SPACING_S, t_end + 2 * SRGR_RECORD_SPACING_S,
            SRGR_RECORD_SPACING_S)])
        coeffs = _srgr_records(base, rec_t, sr0, sr1, h_ref_m)
        gr_max = float(np.max([P.polyval(sr1 - sr0, c) for c in coeffs]))
        n_cols = int(np.ceil(gr_max / dr))
        delivered0 = replace(base, kind="grd", n_cols=n_cols, range_pixel_spacing_m=dr,
                             srgr_times_s=rec_t, srgr_sr0_m=np.full(rec_t.shape, sr0),
                             srgr_coeffs=coeffs)
        ground_rg = dr
    errors = draw_errors(m, rng, ch)
    truth = replace(delivered0, azimuth_offset_s=errors.azimuth_offset_s,
                    range_delay_s=errors.range_delay_s)
    delivered = replace(delivered0, orbit=offset_orbit(
        orbit, (errors.orbit_along_m, errors.orbit_across_m, errors.orbit_radial_m)))
    return SarModels(truth, delivered, errors, m.looks * pixel_scale**2,
                     10.0 ** (m.nesz_db / 10.0), (float(ground_rg), float(az_m)))


def draw_errors(m: SarMission, rng: np.random.Generator, h_centre_m: float) -> SarErrors:
    """The delivered product's errors, drawn with the mission's 1-sigma figures; the
    tropospheric delay is the hydrostatic zenith delay plus a wet delay drawn in
    :data:`ZENITH_WET_DELAY_M`, mapped to the incidence."""
    along, across, radial = (float(s * rng.normal()) for s in m.orbit_sigma_m)
    az = float(m.azimuth_time_sigma_s * rng.normal())
    instr = float(m.range_bias_sigma_m * rng.normal())
    wet = float(rng.uniform(*ZENITH_WET_DELAY_M))  # drawn last: the draws above unchanged
    tropo = float((ZENITH_DELAY_M * np.exp(-max(h_centre_m, 0.0) / TROPO_SCALE_HEIGHT_M) + wet)
                  / np.cos(np.radians(m.incidence_deg)))
    delay = 2.0 * (tropo + instr) / SPEED_OF_LIGHT_M_S
    return SarErrors(along, across, radial, az, delay, tropo, instr)


def offset_orbit(orbit: Orbit, offset_m: tuple[float, float, float]) -> Orbit:
    """The orbit moved by a constant (along, across, radial) offset in its local orbital frame
    (radial up; across = the frame's Y, to the right of the track)."""
    along, across, radial = offset_m
    frame = orbital_frame(orbit.positions_m, orbit.velocities_m_s)  # columns X, Y, Z (down)
    d = frame @ np.array([along, across, -radial])
    return replace(orbit, positions_m=orbit.positions_m + d)


# ---------------------------------------------------------------------------- annotation content


@dataclass(frozen=True, eq=False)
class GridPoints(GeolocationGrid):
    """A geolocation grid as Sentinel-1 annotations give it (the reader's
    :class:`~core.sensors.sentinel1.GeolocationGrid`), with the ellipsoid incidence and the
    elevation (off-nadir look) angle of each point, degrees, which annotations also write."""

    incidence_deg: FloatArray
    elevation_deg: FloatArray


def geolocation_grid(model: SarModel, h_m: float, n_lines: int = 10,
                     n_pixels: int = 21) -> GridPoints:
    """The grid of ``n_lines`` x ``n_pixels`` points spanning the image (first and last line
    and pixel included), localised by ``model`` at height ``h_m`` (a product's grid comes from
    its own annotated orbit and timing)."""
    lines = np.rint(np.linspace(0, model.n_rows - 1, n_lines))
    pixels = np.rint(np.linspace(0, model.n_cols - 1, n_pixels))
    r, c = (a.ravel() for a in np.meshgrid(lines, pixels, indexing="ij"))
    h = np.full(r.shape, float(h_m))
    t, tau = model.times_of_image(c, r)
    lon, lat = model.localize(c, r, h)
    g = np.stack(geodetic_to_ecef(lon, lat, h), axis=1)
    s, _ = model.orbit.interpolate(t - model.azimuth_offset_s)
    los = (s - g) / np.linalg.norm(s - g, axis=1, keepdims=True)
    up = enu_rotation(lon, lat)[:, 2, :]
    inc = np.degrees(np.arccos(np.einsum("ij,ij->i", up, los)))
    nadir = -s / np.linalg.norm(s, axis=1, keepdims=True)
    elev = np.degrees(np.arccos(np.einsum("ij,ij->i", nadir, -los)))
    return GridPoints(t, tau, r, c, lon, lat, h, inc, elev)


def grsr_coefficients(model: SarModel) -> FloatArray:
    """The inverse of each slant-to-ground record: slant range (m) as a polynomial of ground
    range (m) from the near edge (``grsrCoefficients`` of a GRD annotation)."""
    out = []
    for k in range(model.srgr_times_s.size):
        c = model.srgr_coeffs[k]
        x = np.linspace(0.0, 1.0, 400) * (model.n_cols + 2) * model.range_pixel_spacing_m
        sr = model.srgr_sr0_m[k] + _invert_poly(c, x)
        scale = float(x[-1])
        f = P.polyfit(x / scale, sr, SRGR_DEGREE)
        out.append(f / scale ** np.arange(SRGR_DEGREE + 1))
    return np.array(out)


def _invert_poly(c: FloatArray, y: FloatArray) -> FloatArray:
    """x with polyval(x, c) = y for a monotonic polynomial (Newton from the linear guess)."""
    x = (y - c[0]) / c[1]
    dc = P.polyder(c)
    for _ in range(30):
        step = (P.polyval(x, c) - y) / P.polyval(x, dc)
        x = x - step
        if not np.any(np.abs(step) > 1e-9):
            break
    return x
