"""SPOT 1-5 Level 1A geometry (DIMAP ``SPOTSCENE_1A``) -> the rigorous pushbroom model, and back.

:class:`SpotScene` holds what a ``METADATA.DIM`` says about the geometry, as plain numbers
(``tasks.io.dimap`` parses and writes the XML); :func:`spot_pushbroom` builds the
:class:`~core.sensors.pushbroom.PushbroomModel`; :func:`spot_scene_from_model` expresses a
model the other way, as a SPOT product states it (the simulator writes it).

Conventions, each measured on real SPOT 2 HRV and SPOT 5 HRG files (the stated corners are
reproduced to 0.4 m and 0.05 m; the wrong choice costs what is said in brackets):

- Time of file line L (1-based): ``SCENE_CENTER_TIME + (L - SCENE_CENTER_LINE) * LINE_PERIOD``;
  our row is ``L - 1`` and our column ``DETECTOR_ID - 1`` = ``FRAME_COL - 1`` (half a pixel:
  2.5-5 m). All times are UTC (attitudes too: TAI would cost 3-4 m).
- The local orbital frame is built from the ``<Velocity>`` as delivered: SPOT 1-4 give the
  inertial velocity in ECEF axes, SPOT 5 the Earth-relative dP/dt (the other one: 0.6-4 km).
  SPOT's frame (X2 = V x Z2, Y2 = Z2 x X2, Z2 = P/|P|) is ours with axes permuted.
- Look angles: the look direction in our camera frame (x forward, y right, z down) is
  ``(tan PSI_X, -tan PSI_Y, 1)``: PSI_X is the along-track angle, PSI_Y the across-track one
  (signs or swap: 15-160 km); they include the steering mirror. SPOT 5 gives every detector;
  SPOT 1-4 give the first and the last, and the detectors between lie on the straight line
  between the two unit look vectors (interpolating tan(psi) instead: up to 64 m).
- Attitude: SPOT's ``Rx(-PITCH) Ry(-ROLL) Rz(YAW)`` (SPOT axes) is ``Ry(-P) Rx(-R) Rz(-Y)`` in
  ours, converted exactly sample by sample into our roll/pitch/yaw (the first-order
  ``(-R, -P, -Y)``: 0.6 m on SPOT 5). Radians and rad/s. SPOT 5: ``Corrected_Attitudes`` (the
  raw AOCS angles: 600 m). SPOT 1-4: the absolute AOCS angle at the first time plus the
  integral of the angular speeds (rectangle rule), interpolated linearly.
- The stated corners (``Dataset_Frame``) are at ellipsoidal height 0; SPOT 1-4 producers
  computed them without attitude (the measured attitude moves them by 2-24 m), SPOT 5 with its
  corrected attitude.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.errors import InputError
from core.geodesy import geodetic_to_ecef
from core.sensors.linear_array import LookAngleTable, ideal_from_detector
from core.sensors.orbit import (
    OMEGA_EARTH_RAD_S,
    Orbit,
    SampledAttitude,
    orbital_frame,
    rotation_rpy,
)
from core.sensors.pushbroom import PushbroomModel

FloatArray = NDArray[np.float64]
AttitudeChoice = Literal["measured", "none", "producer"]
ATTITUDE_STEP_S = 0.125  # SPOT's attitude sampling


@dataclass(frozen=True, eq=False)
class SpotAngles:
    """Attitude samples in SPOT's convention (radians, or rad/s for angular speeds)."""

    times_s: FloatArray
    roll: FloatArray
    pitch: FloatArray
    yaw: FloatArray
    out_of_range: NDArray[np.bool_]

    def __post_init__(self) -> None:
        t = np.asarray(self.times_s, dtype=np.float64)
        arrays = [np.asarray(getattr(self, k), dtype=np.float64) for k in ("roll", "pitch", "yaw")]
        oor = np.asarray(self.out_of_range, dtype=bool)
        if t.ndim != 1 or t.size == 0 or any(a.shape != t.shape for a in arrays) or \
                oor.shape != t.shape:
            raise InputError("attitude records must each give a time, roll, pitch, yaw and "
                             "out-of-range flag; the file's attitude lists are inconsistent")
        if np.any(np.diff(t) <= 0):
            raise InputError("attitude times are not increasing; the DIMAP file is corrupt")
        for name, a in zip(("times_s", "roll", "pitch", "yaw"), [t, *arrays], strict=True):
            object.__setattr__(self, name, a)
        object.__setattr__(self, "out_of_range", oor)


@dataclass(frozen=True, eq=False)
class SpotLookAngles:
    """The look angles of one band: detectors (1-based ids) and their PSI_X, PSI_Y (radians)."""

    band_index: int
    detector_ids: NDArray[np.int64]
    psi_x_rad: FloatArray
    psi_y_rad: FloatArray

    def __post_init__(self) -> None:
        ids = np.asarray(self.detector_ids, dtype=np.int64)
        px = np.asarray(self.psi_x_rad, dtype=np.float64)
        py = np.asarray(self.psi_y_rad, dtype=np.float64)
        if ids.ndim != 1 or ids.size < 2 or px.shape != ids.shape or py.shape != ids.shape:
            raise InputError(f"band {self.band_index}: look angles need >= 2 detectors with a "
                             "PSI_X and a PSI_Y each")
        if np.any(np.diff(ids) <= 0) or not (np.all(np.isfinite(px)) and np.all(np.isfinite(py))):
            raise InputError(f"band {self.band_index}: look-angle detector ids must increase and "
                             "the angles be finite; the DIMAP file is corrupt")
        object.__setattr__(self, "detector_ids", ids)
        object.__setattr__(self, "psi_x_rad", px)
        object.__setattr__(self, "psi_y_rad", py)


@dataclass(frozen=True)
class FramePoint:
    """A corner or the centre as the product states it: 1-based FRAME_ROW/COL, WGS84 at h = 0."""

    row: float
    col: float
    lon_deg: float
    lat_deg: float


@dataclass(frozen=True, eq=False)
class SpotScene:
    """The geometry a SPOT 1-5 Level 1A ``METADATA.DIM`` states (times: s since ``epoch_utc``,
    the first ephemeris point, UTC)."""

    mission_index: int
    instrument: str
    instrument_index: int
    sensor_code: str
    n_cols: int
    n_rows: int
    epoch_utc: str
    line_period_s: float
    centre_time_s: float
    centre_line: float  # 1-based file line acquired at centre_time_s
    orbit: Orbit
    look_angles: tuple[SpotLookAngles, ...]  # one per band
    aocs_angles: SpotAngles | None = None
    aocs_speeds: SpotAngles | None = None
    corrected_attitude: SpotAngles | None = None
    frame: tuple[FramePoint, ...] = ()  # the 4 vertices, then the centre
    incidence_deg: float | None = None
    viewing_angle_deg: float | None = None
    sun_azimuth_deg: float | None = None
    sun_elevation_deg: float | None = None
    dataset_name: str = ""

    def __post_init__(self) -> None:
        if not 1 <= self.mission_index <= 5:
            raise InputError(f"MISSION_INDEX {self.mission_index}: only SPOT 1 to 5 Level 1A "
                             "scenes are read here")
        if self.n_cols < 2 or self.n_rows < 2:
            raise InputError(f"raster size {self.n_cols}x{self.n_rows} is too small")
        if not (np.isfinite(self.line_period_s) and self.line_period_s > 0):
            raise InputError(f"LINE_PERIOD {self.line_period_s} must be a positive time")
        if not self.look_angles:
            raise InputError("the file holds no Instrument_Look_Angles; it cannot be modelled")
        for la in self.look_angles:
            ids = la.detector_ids
            if self.mission_index == 5 and ids.size != self.n_cols:
                raise InputError(
                    f"band {la.band_index}: {ids.size} look angles for {self.n_cols} columns; a "
                    "SPOT 5 file gives one per detector: the file is truncated or inconsistent")
            if ids[0] < 1 or ids[-1] > self.n_cols:
                raise InputError(f"band {la.band_index}: detector ids {ids[0]}..{ids[-1]} fall "
                                 f"outside the {self.n_cols} columns")
        t0 = self.centre_time_s - (self.centre_line - 1) * self.line_period_s
        t1 = t0 + (self.n_rows - 1) * self.line_period_s
        times = self.orbit.times_s
        if t0 < times[0] or t1 > times[-1]:
            raise InputError(
                f"the ephemeris ({times[0]:.1f}..{times[-1]:.1f} s) does not cover the scene "
                f"({t0:.1f}..{t1:.1f} s); the file's Ephemeris is truncated")

    @property
    def bands(self) -> tuple[int, ...]:
        return tuple(la.band_index for la in self.look_angles)

    @property
    def t0_s(self) -> float:
        """Time of our row 0 (file line 1)."""
        return self.centre_time_s - (self.centre_line - 1) * self.line_period_s

    def look(self, band: int | None = None) -> SpotLookAngles:
        """The look angles of ``band`` (BAND_INDEX, 1-based); None: the first band's."""
        if band is None:
            return self.look_angles[0]
        for la in self.look_angles:
            if la.band_index == band:
                return la
        raise InputError(f"band {band} is not in this product; its bands are {list(self.bands)}")


# ------------------------------------------------------------------------- rotations


def _rot(a: FloatArray, axis: int) -> FloatArray:
    """Right-handed rotations by angles ``a`` (rad) about the x (0), y (1) or z (2) axis,
    shape ``a.shape + (3, 3)``."""
    c, s = np.cos(a), np.sin(a)
    i, j = (axis + 1) % 3, (axis + 2) % 3
    r = np.zeros(np.shape(a) + (3, 3))
    r[..., axis, axis] = 1.0
    r[..., i, i], r[..., i, j], r[..., j, i], r[..., j, j] = c, -s, s, c
    return r


def spot_rotation(roll: ArrayLike, pitch: ArrayLike, yaw: ArrayLike) -> FloatArray:
    """Camera -> orbital rotation (..., 3, 3) in our frames from SPOT ROLL, PITCH, YAW (rad)."""
    roll, pitch, yaw = (np.asarray(a, dtype=np.float64) for a in (roll, pitch, yaw))
    return _rot(-pitch, 1) @ _rot(-roll, 0) @ _rot(-yaw, 2)


def rotation_to_rpy(r: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Our (roll, pitch, yaw) with ``rotation_rpy(roll, pitch, yaw) == r``."""
    return (np.arctan2(r[..., 2, 1], r[..., 2, 2]), -np.arcsin(np.clip(r[..., 2, 0], -1, 1)),
            np.arctan2(r[..., 1, 0], r[..., 0, 0]))


def rotation_to_spot(r: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """SPOT (ROLL, PITCH, YAW) with ``spot_rotation(ROLL, PITCH, YAW) == r``."""
    b = -np.arcsin(np.clip(r[..., 1, 2], -1, 1))  # -ROLL
    c = np.arctan2(r[..., 1, 0], r[..., 1, 1])  # -YAW
    a = np.arctan2(r[..., 0, 2], r[..., 2, 2])  # -PITCH
    return -b, -a, -c


# ------------------------------------------------------------------------- file -> model


def integrated_attitude(angles: SpotAngles, speeds: SpotAngles) -> SpotAngles:
    """SPOT 1-4 attitude: the first valid absolute angle plus the integral of the angular speeds
    (rectangle rule: each speed over the interval ending at its time). Speeds flagged out of
    range are replaced by the interpolation of their valid neighbours."""
    ok = ~speeds.out_of_range
    if not ok.any():
        raise InputError("every angular speed is flagged out of range; the attitude is unknown "
                         "(build the model without attitude)")
    first = int(np.argmax(~angles.out_of_range)) if (~angles.out_of_range).any() else None
    t_start = angles.times_s[0] if first is None else angles.times_s[first]
    keep = speeds.times_s > t_start
    t = np.concatenate([[t_start], speeds.times_s[keep]])
    out = {}
    for k in ("roll", "pitch", "yaw"):
        w = np.interp(speeds.times_s[keep], speeds.times_s[ok], getattr(speeds, k)[ok])
        a0 = 0.0 if first is None else float(getattr(angles, k)[first])
        out[k] = a0 + np.concatenate([[0.0], np.cumsum(w * np.diff(t))])
    return SpotAngles(t, out["roll"], out["pitch"], out["yaw"], np.zeros(t.size, dtype=bool))


def measured_attitude(scene: SpotScene) -> SpotAngles:
    """The attitude samples the model should use: SPOT 5 corrected attitudes, SPOT 1-4 the
    integrated AOCS angles (the absolute angles alone when no speed is given)."""
    if scene.corrected_attitude is not None:
        return scene.corrected_attitude
    if scene.aocs_angles is not None and scene.aocs_speeds is not None:
        return integrated_attitude(scene.aocs_angles, scene.aocs_speeds)
    if scene.aocs_angles is not None and scene.aocs_angles.times_s.size >= 2:
        return scene.aocs_angles
    raise InputError("the file gives no usable attitude (no Corrected_Attitudes, no AOCS "
                     "angles and speeds); build the model without attitude (attitude='none')")


def look_table(look: SpotLookAngles, n_cols: int) -> LookAngleTable:
    """One look direction per column: the file's own when it gives every detector, else the
    straight line between the unit look vectors of the first and last detectors given."""
    ids = look.detector_ids
    cols = np.arange(1, n_cols + 1, dtype=np.float64)  # the detector id of each column
    if ids.size == n_cols and np.array_equal(ids, cols.astype(np.int64)):
        return LookAngleTable(psi_x_rad=look.psi_y_rad, psi_y_rad=look.psi_x_rad)
    u = np.stack([np.tan(look.psi_x_rad), -np.tan(look.psi_y_rad), np.ones(ids.size)], axis=-1)
    u /= np.linalg.norm(u, axis=-1, keepdims=True)
    s = (cols - ids[0]) / (ids[-1] - ids[0])
    v = (1.0 - s)[:, None] * u[0] + s[:, None] * u[-1]
    return LookAngleTable(psi_x_rad=np.arctan(-v[:, 1] / v[:, 2]),
                          psi_y_rad=np.arctan(v[:, 0] / v[:, 2]))


def spot_pushbroom(scene: SpotScene, band: int | None = None,
                   attitude: AttitudeChoice = "measured") -> PushbroomModel:
    """The rigorous model of a SPOT scene.

    ``attitude``: ``"measured"`` (what the chain uses: SPOT 5 corrected attitudes, SPOT 1-4
    integrated AOCS angles), ``"none"`` (the orbit and look angles alone), or ``"producer"``
    (how the producer computed the stated corners: none for SPOT 1-4, measured for SPOT 5).
    The attitude is sampled (:class:`~core.sensors.orbit.SampledAttitude`), referred to the scene
    centre time; the adjustment's corrections apply on top of it.
    """
    if attitude == "producer":
        attitude = "measured" if scene.mission_index == 5 else "none"
    if attitude == "measured":
        a = measured_attitude(scene)
        t = a.times_s
        ours = rotation_to_rpy(spot_rotation(a.roll, a.pitch, a.yaw))
    elif attitude == "none":
        t = np.array([scene.orbit.times_s[0], scene.orbit.times_s[-1]])
        ours = (np.zeros(2), np.zeros(2), np.zeros(2))
    else:
        raise InputError(f"attitude must be 'measured', 'none' or 'producer', got {attitude!r}")
    return PushbroomModel(
        orbit=scene.orbit,
        attitude=SampledAttitude(t, *ours, t_ref_s=scene.centre_time_s),
        camera=look_table(scene.look(band), scene.n_cols),
        n_rows=scene.n_rows, t0_s=scene.t0_s, line_period_s=scene.line_period_s,
    )


def frame_errors_m(scene: SpotScene, band: int | None = None) -> FloatArray:
    """Distances (m) between the stated corners/centre and the model's, computed as the producer
    did (at h = 0; SPOT 1-4 without attitude): the self-check of a loaded scene."""
    if not scene.frame:
        raise InputError("the file states no corner coordinates (Dataset_Frame)")
    model = spot_pushbroom(scene, band, attitude="producer")
    col = np.array([p.col - 1.0 for p in scene.frame])
    row = np.array([p.row - 1.0 for p in scene.frame])
    lon, lat = model.localize(col, row, np.zeros(col.size))
    a = np.stack(geodetic_to_ecef(lon, lat, 0.0), axis=-1)
    b = np.stack(geodetic_to_ecef([p.lon_deg for p in scene.frame],
                                  [p.lat_deg for p in scene.frame], 0.0), axis=-1)
    return np.linalg.norm(a - b, axis=-1)


# ------------------------------------------------------------------------- model -> file


def _pointing(model: PushbroomModel, t: FloatArray, inertial: bool) -> FloatArray:
    """(m, 3, 3): the model's camera -> orbital rotation re-expressed in the orbital frame built
    from the velocity a SPOT 1-4 file states (inertial when ``inertial``)."""
    pos, vel = model.orbit.interpolate(t)
    att = rotation_rpy(*model.attitude_angles(t))
    stated = vel + np.cross([0.0, 0.0, OMEGA_EARTH_RAD_S], pos) if inertial else vel
    rel = np.einsum("mji,mjk->mik", orbital_frame(pos, stated), orbital_frame(pos, vel))
    return rel @ att


def spot_scene_from_model(
    model: PushbroomModel, *, mission_index: int = 2, instrument: str = "HRV",
    instrument_index: int = 1, sensor_code: str = "P", dataset_name: str = "",
    sun_azimuth_deg: float | None = None, sun_elevation_deg: float | None = None,
) -> SpotScene:
    """The model as a SPOT product of ``mission_index`` states it, so that
    :func:`spot_pushbroom` reads it back.

    The constant part of the pointing (mirror or fore/aft tilt, mean attitude and, for SPOT
    1-4, the turn of the orbital frame between Earth-relative and inertial velocity) is folded
    into the look angles; the rest becomes attitude samples every 0.125 s. SPOT 1-4 style:
    inertial velocities, the look angles of the first and last detectors, absolute AOCS angles
    at the ends plus angular speeds. SPOT 5 style: Earth-relative velocities, every detector's
    look angles, corrected attitudes. The corners are computed as the producer does (h = 0; SPOT
    1-4 without attitude) and the incidence is stated as SPOT does (the incidence at the scene
    centre, negative when the satellite is east of it). Needs a model without lens distortion
    or orbit corrections (the metadata cannot state them); times fall on the file's microsecond
    grid, which moves the centre time by 0.5 us at most.
    """
    c = model.corrections
    if model.distortion.to_dict() != {"k1": 0.0, "k3": 0.0, "p1": 0.0, "p2": 0.0} or any(
            getattr(c, n) for n in ("k1", "k3", "p1", "p2", "focal_scale", "orbit_along_m",
                                    "orbit_across_m", "orbit_radial_m")):
        raise InputError("SPOT metadata cannot state lens distortion or orbit corrections; "
                         "write the model as JSON instead")
    if not model.orbit.epoch_utc:
        raise InputError("the model's orbit has no epoch_utc; DIMAP times are absolute UTC")
    spot5 = mission_index == 5
    orbit = model.orbit
    inertial = not spot5 and orbit.velocity_frame == "ecef"  # SPOT 1-4 state inertial velocity
    if inertial:
        w = np.array([0.0, 0.0, OMEGA_EARTH_RAD_S])
        orbit = Orbit(orbit.times_s, orbit.positions_m,
                      orbit.velocities_m_s + np.cross(w, orbit.positions_m),
                      epoch_utc=orbit.epoch_utc, velocity_frame="inertial")
    n_rows, n_cols, period = model.n_rows, model.n_cols, model.line_period_s
    centre_line = float(max(n_rows // 2, 1))
    t_c = round((model.t0_s + (centre_line - 1) * period) * 1e6) / 1e6
    t_first, t_last = model.t0_s, model.t0_s + (n_rows - 1) * period
    mirror = _pointing(model, np.array([t_c]), inertial)[0]  # constant: into the look angles
    cols = np.arange(n_cols, dtype=np.float64) if spot5 else np.array([0.0, n_cols - 1.0])
    xi, yi = ideal_from_detector(*model.camera.detector_xy(cols), 0.0, 0.0, 0.0, 0.0, 0.0)
    v = np.einsum("ij,mj->mi", mirror, np.stack([xi, yi, np.ones(cols.size)], axis=1))
    look = SpotLookAngles(1, cols.astype(np.int64) + 1, np.arctan(v[:, 0] / v[:, 2]),
                          np.arctan(-v[:, 1] / v[:, 2]))
    t_start = round((t_first - 0.09) * 1e6) / 1e6
    n_steps = int(np.ceil((t_last + 0.01 - t_start) / ATTITUDE_STEP_S))
    t_att = t_start + ATTITUDE_STEP_S * np.arange(n_steps + 1)
    roll, pitch, yaw = rotation_to_spot(_pointing(model, t_att, inertial) @ mirror.T)
    no = np.zeros(t_att.size, dtype=bool)
    if spot5:
        attitude = {"corrected_attitude": SpotAngles(t_att, roll, pitch, yaw, no)}
    else:
        ends = [0, t_att.size - 1]
        attitude = {
            "aocs_angles": SpotAngles(t_att[ends], roll[ends], pitch[ends], yaw[ends], no[ends]),
            "aocs_speeds": SpotAngles(t_att[1:], *(np.diff(a) / np.diff(t_att)
                                                   for a in (roll, pitch, yaw)), no[1:]),
        }
    fc = np.array([1.0, n_cols, n_cols, 1.0, float(round(0.5 * (n_cols + 1)))])
    fr = np.array([1.0, 1.0, n_rows, n_rows, centre_line])
    inc, across, _ = model.viewing_geometry(fc[4] - 1.0, fr[4] - 1.0, 0.0)
    scene = SpotScene(
        mission_index=mission_index, instrument=instrument, instrument_index=instrument_index,
        sensor_code=sensor_code, n_cols=n_cols, n_rows=n_rows, epoch_utc=orbit.epoch_utc,
        line_period_s=period, centre_time_s=t_c, centre_line=centre_line, orbit=orbit,
        look_angles=(look,), incidence_deg=float(np.copysign(inc, across)),
        sun_azimuth_deg=sun_azimuth_deg, sun_elevation_deg=sun_elevation_deg,
        dataset_name=dataset_name, **attitude,
    )
    lon, lat = spot_pushbroom(scene, attitude="producer").localize(fc - 1.0, fr - 1.0,
                                                                   np.zeros(5))
    frame = tuple(FramePoint(float(r), float(c_), float(lo), float(la))
                  for r, c_, lo, la in zip(fr, fc, lon, lat, strict=True))
    return replace(scene, frame=frame)
