"""Geometry solver behind :meth:`PushbroomModel.synthetic` (SPOT-like scenes for simulation)."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray
from scipy import optimize

from core.errors import ConvergenceError, InputError
from core.geodesy import WGS84_A_M, geodetic_to_ecef
from core.sensors.linear_array import LensDistortion, ParametricCamera
from core.sensors.orbit import Attitude, Orbit, circular_orbit_ecef
from core.sensors.pushbroom import PushbroomModel, enu_axes, incidences

FloatArray = NDArray[np.float64]


def check_synthetic(lat: float, n_cols: int, n_rows: int, gsd_m: float, inc: float,
                     pitch: float, alt_m: float, incl: float, spacing_s: float) -> None:
    reach = 180.0 - incl if incl > 90 else incl
    checks = [
        (abs(lat) < min(reach, 89.0) - 1.0, (f"center_lat_deg {lat} is beyond the orbit's "
         f"reach (|lat| < {reach - 1:.1f} for inclination {incl})")),
        (n_cols >= 2 and n_rows >= 2, f"image size {n_cols}x{n_rows} must be at least 2x2"),
        (gsd_m > 0 and alt_m > 100e3, f"gsd_m {gsd_m} must be > 0 and altitude_m {alt_m} > 100 km"),
        (abs(inc) < 60 and abs(pitch) < 45, (f"incidence_deg {inc} must be in (-60, 60) and "
         f"pitch_deg {pitch} in (-45, 45)")),
        (spacing_s > 0, f"state_vector_spacing_s must be > 0, got {spacing_s}"),
    ]
    for ok, msg in checks:
        if not ok:
            raise InputError(f"synthetic pushbroom: {msg}")


@dataclass(frozen=True)
class SyntheticGeometry:
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
        lon, lat = m._localize_t(c, np.array([self.t_c + dt]), h)
        return np.stack(geodetic_to_ecef(lon, lat, h), axis=1)[0]

    def residual(self, x: FloatArray, camera: ParametricCamera, inc: float) -> FloatArray:
        m = self.model(x, camera, 1e-3)
        g = self._centre(m)
        lon, lat, h = self.target
        e, n, _ = enu_axes(np.array([lon]), np.array([lat]))
        d = g - np.stack(geodetic_to_ecef(lon, lat, h))
        pos, vel = m.orbit.interpolate(np.array([self.t_c]))
        _, across, _ = incidences(pos, vel, g[None], np.array([lon]), np.array([lat]))
        return np.array([d @ e[0] / 1e3, d @ n[0] / 1e3, (across[0] - inc) * 1e3])

    def first_guess(self, inc: float) -> FloatArray:
        lon, lat, _ = self.target
        x = np.array([np.radians(lat), np.radians(lon), 0.0])
        m = self.model(x, self.camera, 1e-3)
        _, vel = m.orbit.interpolate(np.array([self.t_c]))
        e, n, _ = enu_axes(np.array([lon]), np.array([lat]))
        a = np.array([vel[0] @ e[0], vel[0] @ n[0]])
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
