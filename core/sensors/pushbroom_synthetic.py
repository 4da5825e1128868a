"""SPOT-like pushbroom geometries for simulation: :func:`synthetic_pushbroom` from a
:class:`SyntheticSpec` (the scene centre, the view, the camera), solved for the orbit and the
roll that point the centre pixel at the target.

Depends one way on :class:`~core.sensors.pushbroom.PushbroomModel` (its public API only).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray
from scipy import optimize

from core.errors import ConvergenceError, InputError
from core.geodesy import WGS84_A_M, enu_rotation, geodetic_to_ecef, incidence_angles
from core.sensors.linear_array import LensDistortion, ParametricCamera
from core.sensors.orbit import GM_EARTH_M3_S2, Attitude, Orbit, circular_orbit_ecef
from core.sensors.pushbroom import DEFAULT_ADJUST, PushbroomModel

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class SyntheticSpec:
    """What a synthetic SPOT-like scene looks like; the orbit and pointing are solved from it.

    The centre pixel sees (``centre_lon_deg``, ``centre_lat_deg``, ``centre_h_m``).
    Orbit: circular Keplerian, radius ``WGS84 a + altitude_m``, inclination
    ``inclination_deg`` (98.7: near-polar, sun-synchronous like SPOT), descending over the scene
    unless ``ascending``; Earth rotation included (ECEF state vectors every
    ``state_vector_spacing_s`` s, by default enough to cover the acquisition with >= 3 samples of
    margin on each side; ``n_state_vectors`` overrides the count).
    Pointing: ``incidence_deg`` is the across-track incidence at the scene centre (angle at the
    ground from the vertical, in the plane across the track; positive = the satellite is west of
    the scene, looking east), reached by rolling the camera (a mirror, as on SPOT);
    ``pitch_deg`` tilts the camera forward (> 0) or aft (< 0) like HRS (+-20 deg stereo).
    Camera: ``n_cols`` detectors of ``detector_pitch_m`` with the focal length that gives a
    ground sample of ``gsd_m`` across track at the scene centre; the line period gives ``gsd_m``
    along track there too. ``along_track_offset_m``, ``ccd_rotation_rad`` and ``distortion``
    shape the focal plane (see ParametricCamera, LensDistortion). Times are seconds since
    ``epoch_utc``, the first state vector. Valid for |lat| up to about 75 deg.
    """

    centre_lon_deg: float
    centre_lat_deg: float
    centre_h_m: float = 0.0
    n_cols: int = 6000
    n_rows: int = 6000
    gsd_m: float = 10.0
    incidence_deg: float = 0.0
    pitch_deg: float = 0.0
    altitude_m: float = 822e3
    inclination_deg: float = 98.7
    ascending: bool = False
    detector_pitch_m: float = 6.5e-6
    along_track_offset_m: float = 0.0
    ccd_rotation_rad: float = 0.0
    distortion: LensDistortion = field(default_factory=LensDistortion)
    state_vector_spacing_s: float = 30.0
    n_state_vectors: int | None = None
    epoch_utc: str = "2024-06-01T10:00:00Z"
    adjust: tuple[str, ...] = DEFAULT_ADJUST

    def __post_init__(self) -> None:
        incl = self.inclination_deg
        reach = 180.0 - incl if incl > 90 else incl
        checks = [
            (abs(self.centre_lat_deg) < min(reach, 89.0) - 1.0,
             f"centre_lat_deg {self.centre_lat_deg} is beyond the orbit's reach "
             f"(|lat| < {reach - 1:.1f} for inclination {incl})"),
            (self.n_cols >= 2 and self.n_rows >= 2,
             f"image size {self.n_cols}x{self.n_rows} must be at least 2x2"),
            (self.gsd_m > 0 and self.altitude_m > 100e3,
             f"gsd_m {self.gsd_m} must be > 0 and altitude_m {self.altitude_m} > 100 km"),
            (abs(self.incidence_deg) < 60 and abs(self.pitch_deg) < 45,
             f"incidence_deg {self.incidence_deg} must be in (-60, 60) and pitch_deg "
             f"{self.pitch_deg} in (-45, 45)"),
            (self.state_vector_spacing_s > 0,
             f"state_vector_spacing_s must be > 0, got {self.state_vector_spacing_s}"),
        ]
        for ok, msg in checks:
            if not ok:
                raise InputError(f"synthetic pushbroom: {msg}")


def synthetic_pushbroom(spec: SyntheticSpec) -> PushbroomModel:
    """A SPOT-like pushbroom model whose centre pixel sees the centre of ``spec``."""
    radius = WGS84_A_M + spec.altitude_m
    v_ground = np.sqrt(GM_EARTH_M3_S2 / radius) * WGS84_A_M / radius
    duration = 1.5 * spec.n_rows * spec.gsd_m / v_ground
    n_sv = int(np.ceil(duration / spec.state_vector_spacing_s)) + 10
    n_sv = n_sv if spec.n_state_vectors is None else int(spec.n_state_vectors)
    times = np.arange(n_sv) * spec.state_vector_spacing_s
    t_c = 0.5 * (times[0] + times[-1])
    geo = _Geometry(
        target=(spec.centre_lon_deg, spec.centre_lat_deg, spec.centre_h_m), t_c=t_c, times=times,
        radius=radius, inclination=np.radians(spec.inclination_deg), ascending=spec.ascending,
        pitch=np.radians(spec.pitch_deg), epoch_utc=spec.epoch_utc, n_rows=spec.n_rows,
        distortion=spec.distortion,
        camera=ParametricCamera(
            focal_length_m=spec.detector_pitch_m * spec.altitude_m / spec.gsd_m,
            detector_pitch_m=spec.detector_pitch_m, n_cols=spec.n_cols,
            along_track_offset_m=spec.along_track_offset_m, rotation_rad=spec.ccd_rotation_rad,
        ),
    )
    model = geo.solve(np.radians(spec.incidence_deg), spec.gsd_m).with_adjust(spec.adjust)
    t_end = model.line_time_s(spec.n_rows - 1)
    if model.t0_s < times[min(3, n_sv - 1)] or t_end > times[max(n_sv - 4, 0)]:
        raise InputError(
            f"{n_sv} state vectors every {spec.state_vector_spacing_s} s do not cover the "
            f"acquisition ({model.t0_s:.1f}..{t_end:.1f} s) with 3 samples of margin; "
            "leave n_state_vectors to its default or raise it"
        )
    return model


@dataclass(frozen=True)
class _Geometry:
    """Solves the orbit (sub-satellite point at t_c) and roll that point the centre pixel."""

    target: tuple[float, float, float]
    t_c: float
    times: FloatArray
    radius: float
    inclination: float
    ascending: bool
    pitch: float
    epoch_utc: str
    n_rows: int
    distortion: LensDistortion
    camera: ParametricCamera

    def model(self, x: FloatArray, camera: ParametricCamera, period: float) -> PushbroomModel:
        """x = (sub-satellite geocentric lat, lon at t_c, roll), radians."""
        lat_s, lon_s, roll = (float(v) for v in x)
        i = self.inclination
        sin_u = np.clip(np.sin(lat_s) / np.sin(i), -1.0, 1.0)
        u0 = np.arcsin(sin_u) if self.ascending else np.pi - np.arcsin(sin_u)
        raan = lon_s - np.arctan2(np.cos(i) * np.sin(u0), np.cos(u0))
        pos, vel = circular_orbit_ecef(self.times, radius_m=self.radius, inclination_rad=i,
                                       raan_rad=raan, arg_lat0_rad=u0, t_c_s=self.t_c)
        return PushbroomModel(
            orbit=Orbit(self.times, pos, vel, epoch_utc=self.epoch_utc),
            attitude=Attitude(self.t_c, roll_rad=(roll,), pitch_rad=(self.pitch,)),
            camera=camera, n_rows=self.n_rows, line_period_s=period,
            t0_s=self.t_c - 0.5 * (self.n_rows - 1) * period, distortion=self.distortion,
        )

    def _centre(self, m: PushbroomModel, dt: float = 0.0, dcol: float = 0.0) -> FloatArray:
        c = np.array([0.5 * (m.n_cols - 1) + dcol])
        h = np.array([self.target[2]])
        lon, lat = m.localize_time(c, np.array([self.t_c + dt]), h)
        return np.stack(geodetic_to_ecef(lon, lat, h), axis=1)[0]

    def residual(self, x: FloatArray, camera: ParametricCamera, inc: float) -> FloatArray:
        m = self.model(x, camera, 1e-3)
        g = self._centre(m)
        lon, lat, h = self.target
        e, n = enu_rotation(lon, lat)[:2]
        d = g - np.stack(geodetic_to_ecef(lon, lat, h))
        pos, vel = m.orbit.interpolate(np.array([self.t_c]))
        _, across, _ = incidence_angles(pos, vel, g[None], np.array([lon]), np.array([lat]))
        return np.array([d @ e / 1e3, d @ n / 1e3, (across[0] - inc) * 1e3])

    def first_guess(self, inc: float) -> FloatArray:
        lon, lat, _ = self.target
        x = np.array([np.radians(lat), np.radians(lon), 0.0])
        m = self.model(x, self.camera, 1e-3)
        _, vel = m.orbit.interpolate(np.array([self.t_c]))
        e, n = enu_rotation(lon, lat)[:2]
        a = np.array([vel[0] @ e, vel[0] @ n])
        a /= np.linalg.norm(a)
        c = np.array([a[1], -a[0]]) * (1.0 if a[1] >= 0 else -1.0)  # across track, eastward
        re, h = WGS84_A_M, self.radius - WGS84_A_M
        eta = np.arcsin(re / (re + h) * np.sin(abs(inc)))
        gamma_c = abs(inc) - eta
        gamma_p = np.arcsin(min((re + h) / re * np.sin(abs(self.pitch)), 1.0)) - abs(self.pitch)
        move = -np.sign(inc) * gamma_c * c - np.sign(self.pitch) * gamma_p * a  # radians (e, n)
        left = np.array([-a[1], a[0]])
        roll = eta * np.sign(inc) * np.sign(c @ left)
        return np.array([x[0] + move[1], x[1] + move[0] / np.cos(x[0]), roll])

    def solve(self, inc: float, gsd_m: float) -> PushbroomModel:
        x, camera = self.first_guess(inc), self.camera
        for _ in range(8):
            sol = optimize.root(self.residual, x, args=(camera, inc), method="hybr",
                                options={"xtol": 1e-14})
            x = sol.x
            if np.max(np.abs(self.residual(x, camera, inc))) > 1e-8:
                raise ConvergenceError(
                    "synthetic pushbroom: could not point the centre pixel at the target; "
                    "lower |incidence_deg| or |pitch_deg|"
                )
            m = self.model(x, camera, 1e-3)
            across_m = np.linalg.norm(self._centre(m, dcol=0.5) - self._centre(m, dcol=-0.5))
            ratio = across_m / gsd_m
            camera = replace(camera, focal_length_m=camera.focal_length_m * ratio)
            if abs(ratio - 1.0) < 1e-13:
                break
        m = self.model(x, camera, 1e-3)
        speed = np.linalg.norm(self._centre(m, dt=0.05) - self._centre(m, dt=-0.05)) / 0.1
        return self.model(x, camera, gsd_m / speed)


def seen_in(models: list[PushbroomModel] | tuple[PushbroomModel, ...], lon: NDArray,
            lat: NDArray, h: NDArray, n_px: int, noise_px: float,
            rng: np.random.Generator) -> tuple[NDArray, NDArray]:
    """(n, N) columns and rows of the ground points in each of N square ``n_px`` images that
    sees them, with Gaussian noise of ``noise_px`` (NaN where an image does not): the
    observations of a synthetic block."""
    col = np.full((np.size(lon), len(models)), np.nan)
    row = np.full_like(col, np.nan)
    for k, m in enumerate(models):
        c, r = m.project(lon, lat, h)
        inside = (c >= 0) & (c <= n_px - 1) & (r >= 0) & (r <= n_px - 1)
        col[inside, k] = c[inside] + rng.normal(0, noise_px, inside.sum())
        row[inside, k] = r[inside] + rng.normal(0, noise_px, inside.sum())
    return col, row
