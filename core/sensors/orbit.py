"""Orbit (ECEF state vectors) and attitude (roll/pitch/yaw polynomials) of a pushbroom satellite.

Times are seconds (``_s``) since the epoch the metadata names (``Orbit.epoch_utc``); keep them
small (seconds since the first state vector, say) so float64 keeps microsecond resolution.

Frames (all right-handed):

- ECEF: WGS84 Earth-centred, Earth-fixed, metres.
- Local orbital frame at time t, built from the ECEF position P and velocity V of the delivered
  orbit: ``Z = -P/|P|`` (towards the Earth centre), ``Y = Z x V / |Z x V|`` (the negative orbit
  normal: to the right of the track), ``X = Y x Z`` (along track, within a few degrees of V).
  ECEF velocity is used, so the frame follows the ground track (no yaw steering needed).
- Camera (body) frame: x forward, y right, z down along the boresight. The attitude rotates it
  into the orbital frame: ``u_orbital = Rz(yaw) Ry(pitch) Rx(roll) u_camera`` with active
  right-handed rotations. A positive roll turns the boresight to -Y (left of the track: east on a
  descending pass), a positive pitch turns it forward (+X), a positive yaw turns +X towards +Y.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.errors import InputError
from core.sensors._dictio import (
    float_lists,
    get_float,
    get_float_arrays,
    get_float_tuple,
    get_str,
)

FloatArray = NDArray[np.float64]

GM_EARTH_M3_S2 = 3.986004418e14
OMEGA_EARTH_RAD_S = 7.2921150e-5
LAGRANGE_POINTS = 8
VELOCITY_FRAMES = ("ecef", "inertial")


def _readonly(a: ArrayLike) -> FloatArray:
    out = np.array(a, dtype=np.float64)
    out.setflags(write=False)
    return out


@dataclass(frozen=True, eq=False)
class Orbit:
    """ECEF state vectors, interpolated by Lagrange polynomials over 8 neighbouring samples.

    ``times_s`` (n,) strictly increasing seconds since ``epoch_utc``; ``positions_m`` (n, 3) and
    ``velocities_m_s`` (n, 3) ECEF. Positions and velocities are interpolated separately (the
    SPOT practice). At least 2 vectors are needed; fewer than 8 lower the polynomial degree.
    Times outside the sampled span are extrapolated, which loses accuracy quickly beyond one
    sample spacing: deliver vectors that cover the acquisition with a few samples of margin.

    ``velocity_frame`` says what the velocities are, both in ECEF axes: ``"ecef"``, the
    Earth-relative dP/dt (SPOT 5, the simulator), or ``"inertial"``, dP/dt + w x P (SPOT 1-4
    ephemeris). The local orbital frame is built from the velocity as delivered, as the
    producer defines it; :meth:`ground_velocity` gives dP/dt either way.
    """

    times_s: FloatArray
    positions_m: FloatArray
    velocities_m_s: FloatArray
    epoch_utc: str = ""
    velocity_frame: str = "ecef"

    def __post_init__(self) -> None:
        t = _readonly(self.times_s)
        p = _readonly(self.positions_m)
        v = _readonly(self.velocities_m_s)
        if t.ndim != 1 or t.size < 2:
            raise InputError(f"orbit times_s must be a 1-D array of >= 2 times, got shape {t.shape}")
        if p.shape != (t.size, 3) or v.shape != (t.size, 3):
            raise InputError(
                f"orbit positions_m {p.shape} and velocities_m_s {v.shape} must both be "
                f"({t.size}, 3), one ECEF vector per time"
            )
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(p)) and np.all(np.isfinite(v))):
            raise InputError("orbit state vectors hold NaN or inf; remove the bad records")
        if np.any(np.diff(t) <= 0):
            raise InputError("orbit times_s must be strictly increasing; sort and deduplicate them")
        if self.velocity_frame not in VELOCITY_FRAMES:
            raise InputError(f"orbit velocity_frame {self.velocity_frame!r} unknown; use one of "
                             f"{VELOCITY_FRAMES}")
        object.__setattr__(self, "times_s", t)
        object.__setattr__(self, "positions_m", p)
        object.__setattr__(self, "velocities_m_s", v)

    def interpolate(self, t_s: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """ECEF position (m, 3) metres and velocity (m, 3) m/s at times ``t_s`` (m,) seconds."""
        # imports Numba: only when interpolating
        from core.sensors.orbit_kernels import orbit_states

        t = np.atleast_1d(np.asarray(t_s, dtype=np.float64)).ravel()
        k = min(LAGRANGE_POINTS, self.times_s.size)
        return orbit_states(self.times_s, self.positions_m, self.velocities_m_s, k, t)

    def platform(self, t_s: FloatArray, angles_rad: FloatArray
                 ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """At times ``t_s`` (m,) with attitude ``angles_rad`` (3, m) (roll, pitch, yaw): the
        position (m, 3) as :meth:`interpolate`, the local orbital frame (m, 3, 3) as
        :func:`orbital_frame`, the attitude's rotation (m, 3, 3) as :func:`rotation_rpy` and
        camera -> ECEF, their product; in one compiled pass."""
        from core.sensors.orbit_kernels import platform_frames

        t = np.atleast_1d(np.asarray(t_s, dtype=np.float64)).ravel()
        k = min(LAGRANGE_POINTS, self.times_s.size)
        return platform_frames(self.times_s, self.positions_m, self.velocities_m_s, k, t,
                               angles_rad)

    def ground_velocity(self, pos_m: FloatArray, vel_m_s: FloatArray) -> FloatArray:
        """Earth-relative dP/dt (m, 3) from interpolated positions and delivered velocities."""
        if self.velocity_frame == "inertial":
            return vel_m_s - np.cross(np.array([0.0, 0.0, OMEGA_EARTH_RAD_S]), pos_m)
        return vel_m_s

    def to_dict(self) -> dict:
        return {
            "epoch_utc": self.epoch_utc,
            **float_lists(self, "times_s", "positions_m", "velocities_m_s"),
            **({"velocity_frame": self.velocity_frame} if self.velocity_frame != "ecef" else {}),
        }

    @classmethod
    def from_dict(cls, d: object, path: str = "orbit") -> Orbit:
        return cls(
            **get_float_arrays(d, path, times_s=1, positions_m=2, velocities_m_s=2),
            epoch_utc=get_str(d, "epoch_utc", path, default=""),
            velocity_frame=get_str(d, "velocity_frame", path, default="ecef"),
        )


def orbital_frame(pos_m: FloatArray, vel_m_s: FloatArray) -> FloatArray:
    """Local orbital frame (m, 3, 3): columns X (along track), Y (right), Z (to Earth centre)."""
    from core.sensors.orbit_kernels import orbital_frames

    return orbital_frames(pos_m, vel_m_s)


def rotation_rpy(roll_rad: FloatArray, pitch_rad: FloatArray, yaw_rad: FloatArray) -> FloatArray:
    """``Rz(yaw) Ry(pitch) Rx(roll)``, shape (m, 3, 3): camera frame -> local orbital frame."""
    from core.sensors.orbit_kernels import rotations_rpy

    return rotations_rpy(roll_rad, pitch_rad, yaw_rad)


@dataclass(frozen=True)
class Attitude:
    """Roll, pitch, yaw (radians) as polynomials of ``t - t_ref_s``.

    ``roll_rad = (c0, c1, c2, ...)`` means ``roll(t) = c0 + c1 (t - t_ref) + c2 (t - t_ref)^2 ...``
    in rad, rad/s, rad/s^2... Angles rotate the camera frame into the local orbital frame (see the
    module docstring). A side-looking SPOT scene carries its mirror angle in ``roll_rad[0]``, a
    fore/aft stereo instrument its tilt in ``pitch_rad[0]``.

    ``jitter`` adds high-frequency terms that no low-order polynomial absorbs: each
    ``(axis, amplitude_rad, frequency_hz, phase_rad)`` adds
    ``amplitude * sin(2 pi frequency (t - t_ref) + phase)`` to roll (axis 0), pitch (1) or
    yaw (2). Delivered metadata have none; the scene simulator's truth models may.
    """

    t_ref_s: float
    roll_rad: tuple[float, ...] = (0.0,)
    pitch_rad: tuple[float, ...] = (0.0,)
    yaw_rad: tuple[float, ...] = (0.0,)
    jitter: tuple[tuple[int, float, float, float], ...] = ()
    _coeffs: FloatArray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "t_ref_s", float(self.t_ref_s))
        polys = []
        for name in ("roll_rad", "pitch_rad", "yaw_rad"):
            c = tuple(float(v) for v in np.atleast_1d(getattr(self, name)))
            if not c or not all(np.isfinite(c)):
                raise InputError(f"attitude {name} needs >= 1 finite coefficient, got {c}")
            object.__setattr__(self, name, c)
            polys.append(c)
        deg = max(3, *(len(c) for c in polys))
        coeffs = np.zeros((3, deg))
        for i, c in enumerate(polys):
            coeffs[i, : len(c)] = c
        coeffs.setflags(write=False)
        object.__setattr__(self, "_coeffs", coeffs)
        terms = []
        for term in self.jitter:
            if len(term) != 4:
                raise InputError(
                    f"attitude jitter term {term!r} must be (axis, amplitude_rad, frequency_hz, "
                    "phase_rad)"
                )
            axis, amp, freq, phase = int(term[0]), float(term[1]), float(term[2]), float(term[3])
            if axis not in (0, 1, 2) or not all(np.isfinite((amp, freq, phase))) or freq < 0:
                raise InputError(
                    f"attitude jitter term {term!r}: axis must be 0, 1 or 2 and amplitude, "
                    "frequency (>= 0) and phase finite"
                )
            terms.append((axis, amp, freq, phase))
        object.__setattr__(self, "jitter", tuple(terms))

    def _coeffs_at(self, t_s: FloatArray, delta: FloatArray | None
                   ) -> tuple[FloatArray, FloatArray]:
        """The polynomial coefficients (3, k), ``delta`` (3, 3) added to c0..c2, and the times
        from ``t_ref_s``, s."""
        c = self._coeffs if delta is None else self._coeffs.copy()
        if delta is not None:
            c[:, :3] += delta
        return c, np.asarray(t_s, dtype=np.float64) - self.t_ref_s

    def angles(self, t_s: FloatArray, delta: FloatArray | None = None) -> FloatArray:
        """(3, m) roll, pitch, yaw radians at times t (m,), with ``delta`` (3, 3) added to c0..c2."""
        c, dt = self._coeffs_at(t_s, delta)
        out = np.zeros((3,) + dt.shape)
        for k in range(c.shape[1] - 1, -1, -1):  # Horner
            out = out * dt + c[:, k].reshape((3,) + (1,) * dt.ndim)
        for axis, amp, freq, phase in self.jitter:
            out[axis] = out[axis] + amp * np.sin(2.0 * np.pi * freq * dt + phase)
        return out

    def rates(self, t_s: FloatArray, delta: FloatArray | None = None) -> FloatArray:
        """(3, m) time derivatives (rad/s) of :meth:`angles` at times t (m,)."""
        c, dt = self._coeffs_at(t_s, delta)
        out = np.zeros((3,) + dt.shape)
        for k in range(c.shape[1] - 1, 0, -1):  # Horner on the derivative
            out = out * dt + k * c[:, k].reshape((3,) + (1,) * dt.ndim)
        for axis, amp, freq, phase in self.jitter:
            w = 2.0 * np.pi * freq
            out[axis] = out[axis] + amp * w * np.cos(w * dt + phase)
        return out

    def to_dict(self) -> dict:
        return {
            "t_ref_s": self.t_ref_s,
            "roll_rad": list(self.roll_rad),
            "pitch_rad": list(self.pitch_rad),
            "yaw_rad": list(self.yaw_rad),
            **({"jitter": [list(t) for t in self.jitter]} if self.jitter else {}),
        }

    @classmethod
    def from_dict(cls, d: object, path: str = "attitude") -> Attitude:
        return cls(
            t_ref_s=get_float(d, "t_ref_s", path),
            roll_rad=get_float_tuple(d, "roll_rad", path),
            pitch_rad=get_float_tuple(d, "pitch_rad", path),
            yaw_rad=get_float_tuple(d, "yaw_rad", path),
            jitter=_jitter_from(d, path),
        )


def _jitter_from(d: object, path: str) -> tuple[tuple[int, float, float, float], ...]:
    """The optional ``jitter`` list of an attitude dict."""
    raw = d.get("jitter", []) if isinstance(d, dict) else []
    if not isinstance(raw, list) or not all(
        isinstance(t, list) and len(t) == 4
        and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in t)
        for t in raw
    ):
        raise InputError(
            f"{path}.jitter must be a list of [axis, amplitude_rad, frequency_hz, phase_rad]"
        )
    return tuple((int(t[0]), float(t[1]), float(t[2]), float(t[3])) for t in raw)


@dataclass(frozen=True, eq=False)
class SampledAttitude:
    """Roll, pitch, yaw (radians, this module's convention) sampled in time, interpolated
    linearly (as the SPOT producer prescribes for its attitude samples).

    ``times_s`` (n >= 2, strictly increasing, seconds since the orbit epoch); the angle arrays
    have one value per time. Before the first and after the last sample the end values hold:
    deliver samples that cover the acquisition. ``t_ref_s`` is the time around which the
    adjustment's corrections (bias, rate, quad) are polynomials, as for :class:`Attitude`.
    """

    times_s: FloatArray
    roll_rad: FloatArray
    pitch_rad: FloatArray
    yaw_rad: FloatArray
    t_ref_s: float

    def __post_init__(self) -> None:
        t = _readonly(self.times_s)
        if t.ndim != 1 or t.size < 2 or not np.all(np.isfinite(t)):
            raise InputError(f"sampled attitude needs >= 2 finite times, got shape {t.shape}")
        if np.any(np.diff(t) <= 0):
            raise InputError("sampled attitude times must be strictly increasing; sort and "
                             "deduplicate the attitude records")
        object.__setattr__(self, "times_s", t)
        for name in ("roll_rad", "pitch_rad", "yaw_rad"):
            a = _readonly(getattr(self, name))
            if a.shape != t.shape or not np.all(np.isfinite(a)):
                raise InputError(f"sampled attitude {name} must hold {t.size} finite angles, one "
                                 f"per time; got shape {a.shape}")
            object.__setattr__(self, name, a)
        object.__setattr__(self, "t_ref_s", float(self.t_ref_s))

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, SampledAttitude):
            return NotImplemented
        return self.t_ref_s == other.t_ref_s and all(
            np.array_equal(getattr(self, k), getattr(other, k))
            for k in ("times_s", "roll_rad", "pitch_rad", "yaw_rad"))

    __hash__ = None  # type: ignore[assignment]

    def angles(self, t_s: FloatArray, delta: FloatArray | None = None) -> FloatArray:
        """(3, m) roll, pitch, yaw radians at times t (m,); ``delta`` (3, 3) adds the
        polynomials [bias, rate, quad] of t - t_ref to each axis."""
        t = np.asarray(t_s, dtype=np.float64)
        out = np.stack([np.interp(t, self.times_s, a)
                        for a in (self.roll_rad, self.pitch_rad, self.yaw_rad)])
        if delta is not None:
            dt = t - self.t_ref_s
            out = out + (delta[:, 0:1] + dt * (delta[:, 1:2] + dt * delta[:, 2:3]))
        return out

    def rates(self, t_s: FloatArray, delta: FloatArray | None = None) -> FloatArray:
        """(3, m) time derivatives (rad/s) of :meth:`angles`: the slope of the sample interval
        holding t (the later one at a sample time), 0 outside the samples."""
        t = np.asarray(t_s, dtype=np.float64)
        i = np.clip(np.searchsorted(self.times_s, t, side="right") - 1, 0, self.times_s.size - 2)
        dt_seg = np.diff(self.times_s)[i]
        inside = (t >= self.times_s[0]) & (t < self.times_s[-1])
        out = np.stack([np.where(inside, np.diff(a)[i] / dt_seg, 0.0)
                        for a in (self.roll_rad, self.pitch_rad, self.yaw_rad)])
        if delta is not None:
            out = out + (delta[:, 1:2] + 2.0 * (t - self.t_ref_s) * delta[:, 2:3])
        return out

    def to_dict(self) -> dict:
        return {
            "type": "sampled",
            "t_ref_s": self.t_ref_s,
            **float_lists(self, "times_s", "roll_rad", "pitch_rad", "yaw_rad"),
        }

    @classmethod
    def from_dict(cls, d: object, path: str = "attitude") -> SampledAttitude:
        return cls(
            **get_float_arrays(d, path, times_s=1, roll_rad=1, pitch_rad=1, yaw_rad=1),
            t_ref_s=get_float(d, "t_ref_s", path),
        )


AttitudeModel = Attitude | SampledAttitude


def attitude_from_dict(d: object, path: str = "attitude") -> AttitudeModel:
    """An attitude from its dict: ``type`` ``"sampled"``, or polynomial when absent."""
    kind = get_str(d, "type", path, default="polynomial")
    if kind == "sampled":
        return SampledAttitude.from_dict(d, path)
    if kind == "polynomial":
        return Attitude.from_dict(d, path)
    raise InputError(f"key '{path}.type' must be 'polynomial' or 'sampled', got {kind!r}")


def circular_orbit_ecef(
    t_s: ArrayLike,
    *,
    radius_m: float,
    inclination_rad: float,
    raan_rad: float,
    arg_lat0_rad: float,
    t_c_s: float,
) -> tuple[FloatArray, FloatArray]:
    """Circular Keplerian orbit in ECEF: positions (m, 3) metres and velocities (m, 3) m/s.

    The inertial frame coincides with ECEF at ``t_c_s``; ``raan_rad`` is the right ascension of
    the ascending node in that frame and ``arg_lat0_rad`` the argument of latitude at ``t_c_s``.
    The Earth turns at ``OMEGA_EARTH_RAD_S`` about ECEF Z; velocities are ECEF (Earth-relative).
    """
    t = np.atleast_1d(np.asarray(t_s, dtype=np.float64)) - t_c_s
    n = np.sqrt(GM_EARTH_M3_S2 / radius_m**3)
    u = arg_lat0_rad + n * t
    co, so = np.cos(raan_rad), np.sin(raan_rad)
    ci, si = np.cos(inclination_rad), np.sin(inclination_rad)
    cu, su = np.cos(u), np.sin(u)
    x = radius_m * np.stack([co * cu - so * su * ci, so * cu + co * su * ci, su * si], axis=1)
    v = radius_m * n * np.stack([-co * su - so * cu * ci, -so * su + co * cu * ci, cu * si], axis=1)
    th = OMEGA_EARTH_RAD_S * t
    ct, st = np.cos(th), np.sin(th)
    xe = np.stack([ct * x[:, 0] + st * x[:, 1], -st * x[:, 0] + ct * x[:, 1], x[:, 2]], axis=1)
    ve = np.stack([ct * v[:, 0] + st * v[:, 1], -st * v[:, 0] + ct * v[:, 1], v[:, 2]], axis=1)
    ve[:, 0] += OMEGA_EARTH_RAD_S * xe[:, 1]
    ve[:, 1] -= OMEGA_EARTH_RAD_S * xe[:, 0]
    return xe, ve
