"""Realistic errors of a simulated SPOT scene (``gcpfree simulate --errors realistic``): what real
Level 1A products have beyond the attitude biases and rates the adjustment solves for.

Each error is in because real products have it, with the magnitude measured on them:

- **Low-frequency attitude profile** (:func:`attitude_profile`). Integrating the
  ``Angular_Speeds`` of real SPOT 1-4 DIMAP files (``../shared/data/spot_dimap/SPOT2.DIM`` and
  others) over a 9 s scene, the attitude departs from a straight line by 4-12 microradians peak
  in pitch (0.3-1 px in rows at 10 m) and 1-3 in roll and yaw, and is not a polynomial (a
  quadratic leaves 1-14 microradians). The profile is random-phase sinusoids of 0.05-1 Hz plus a
  random walk, its straight line removed over a 9 s window centred on the scene and scaled to a
  peak drawn in those ranges. The satellite measured it: the delivered metadata carry it.
- **Measured angular speeds** (:func:`quantise_speeds`). SPOT 1-4 files state angular speeds
  every ~0.125 s (SPOT2.DIM: 72 samples over 9.1 s, intervals 0.123-0.127 s) quantised in steps
  of 2e-5 deg/s = 3.4907e-7 rad/s (every speed of SPOT2.DIM is an integer multiple of it); the
  chain integrates them (:func:`core.sensors.spot.integrated_attitude`), so the integrated
  quantisation error is the attitude's only measurement error. SPOT 5 files state corrected
  attitudes every 0.125 s, interpolated linearly.
- **Ephemeris errors** (:func:`with_ephemeris_error`): a position bias up to 30 m along track,
  15 m across and 10 m radial, and an image time-tag error up to 1 ms (archive SPOT 1-4 orbits
  without DORIS precise orbit restitution; 1 ms is 7 m along track).
- **Detector calibration** (:func:`calibrated_camera`): a look-angle scale error up to 1e-4 (0.3
  px at the ends of a 6000-detector line), a bow of the detector line up to 0.2 px along track,
  and, for SPOT 1-4 panchromatic (four CCD segments of 1500 detectors butted in the focal
  plane), sub-pixel offsets (up to 0.1 px per axis) between the segments. None of it is in the
  metadata (SPOT 1-4 state the look angles of the first and last detector only).

Pure NumPy on the sensor models; the draws come from the caller's generator, one per image and
seed, so the same seed gives the same errors.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from core.errors import InputError
from core.sensors.linear_array import LookAngleTable, ParametricCamera
from core.sensors.orbit import Attitude, Orbit, orbital_frame
from core.sensors.pushbroom import PushbroomModel
from core.sensors.spot import SpotAngles, SpotScene, spot_pushbroom, spot_scene_from_model

FloatArray = NDArray[np.float64]

PROFILE_WINDOW_S = 9.0  # a SPOT scene: 6000 lines of 1.504 ms
PROFILE_PEAK_RAD = ((1e-6, 3e-6), (4e-6, 12e-6), (1e-6, 3e-6))  # roll, pitch, yaw
PROFILE_BAND_HZ = (0.05, 1.0)
SPEED_QUANTUM_RAD_S = np.radians(2e-5)  # 3.4907e-7 rad/s, SPOT2.DIM's Angular_Speeds
ORBIT_BIAS_MAX_M = (30.0, 15.0, 10.0)  # along, across, radial
TIME_TAG_MAX_S = 1e-3
LOOK_SCALE_MAX = 1e-4
BOW_MAX_PX = 0.2
SEGMENT_OFFSET_MAX_PX = 0.1
HRV_SEGMENTS = 4  # SPOT 1-4 HRV panchromatic: 4 CCD segments of 1500 detectors

_N_SINES = 4  # sinusoids per axis
_N_WALK = 24  # Karhunen-Loeve terms of the random walk (up to 1.3 Hz over 9 s)


@dataclass(frozen=True)
class RealisticErrors:
    """What ``--errors realistic`` did to one image (the truth record in scene.json).

    ``profile``: the attitude profile's terms ``(axis, amplitude_rad, frequency_hz, phase_rad)``
    (as :class:`~core.sensors.orbit.Attitude` jitter, phase about the attitude's ``t_ref_s``) and
    ``profile_line_rad`` the straight line removed from them, ``(bias, rate)`` per axis (roll,
    pitch, yaw; rad, rad/s about ``t_ref_s``); ``profile_peak_rad`` the peak departure of the
    profile from its line over the 9 s window. ``speed_quantum_rad_s`` is 0 when the metadata
    state attitudes (SPOT 5) rather than angular speeds. ``orbit_bias_m`` (along, across, radial
    up) and ``time_tag_s`` are what the delivered ephemeris and line dating get wrong (delivered
    minus true). ``look_scale`` (across-track look angles scaled about the centre column by
    ``1 + look_scale``), ``bow_px`` (along-track bow, at the line ends relative to the centre)
    and ``segment_offsets_px`` ((across, along) per CCD segment) describe the true camera.
    """

    profile: tuple[tuple[int, float, float, float], ...]
    profile_line_rad: tuple[tuple[float, float], ...]
    profile_peak_rad: tuple[float, float, float]
    speed_quantum_rad_s: float
    orbit_bias_m: tuple[float, float, float]
    time_tag_s: float
    look_scale: float
    bow_px: float
    segment_offsets_px: tuple[tuple[float, float], ...]

    def to_dict(self) -> dict:
        return {
            "profile": [list(t) for t in self.profile],
            "profile_line_rad": [list(t) for t in self.profile_line_rad],
            "profile_peak_rad": list(self.profile_peak_rad),
            "speed_quantum_rad_s": self.speed_quantum_rad_s,
            "orbit_bias_m": list(self.orbit_bias_m), "time_tag_s": self.time_tag_s,
            "look_scale": self.look_scale, "bow_px": self.bow_px,
            "segment_offsets_px": [list(t) for t in self.segment_offsets_px],
        }

    @classmethod
    def from_dict(cls, d: dict) -> RealisticErrors:
        return cls(
            profile=tuple((int(t[0]), float(t[1]), float(t[2]), float(t[3]))
                          for t in d["profile"]),
            profile_line_rad=tuple((float(a), float(b)) for a, b in d["profile_line_rad"]),
            profile_peak_rad=tuple(float(v) for v in d["profile_peak_rad"]),  # type: ignore[arg-type]
            speed_quantum_rad_s=float(d["speed_quantum_rad_s"]),
            orbit_bias_m=tuple(float(v) for v in d["orbit_bias_m"]),  # type: ignore[arg-type]
            time_tag_s=float(d["time_tag_s"]), look_scale=float(d["look_scale"]),
            bow_px=float(d["bow_px"]),
            segment_offsets_px=tuple((float(a), float(b)) for a, b in d["segment_offsets_px"]),
        )


# ------------------------------------------------------------------------- attitude profile


def _terms_angles(terms: list[tuple[int, float, float, float]], t: FloatArray,
                  t_ref_s: float) -> FloatArray:
    """(3, m) the sum of sinusoid terms at times t, as :meth:`Attitude.angles` adds them."""
    out = np.zeros((3, t.size))
    for axis, amp, freq, phase in terms:
        out[axis] += amp * np.sin(2.0 * np.pi * freq * (t - t_ref_s) + phase)
    return out


def _detrended(a: FloatArray, t: FloatArray, t_ref_s: float) -> tuple[FloatArray, FloatArray]:
    """(residual (3, m), line (3, 2) as (bias, rate) about t_ref_s) of a least-squares line."""
    g = np.stack([np.ones(t.size), t - t_ref_s], axis=1)
    coef = np.linalg.lstsq(g, a.T, rcond=None)[0].T
    return a - coef @ g.T, coef


def attitude_profile(
    rng: np.random.Generator, t_centre_s: float, t_ref_s: float,
    window_s: float = PROFILE_WINDOW_S,
) -> tuple[tuple[tuple[int, float, float, float], ...], FloatArray, FloatArray]:
    """A low-frequency, non-polynomial attitude profile (module docstring).

    Per axis: ``_N_SINES`` sinusoids of log-uniform frequencies in 0.05-1 Hz with random phases
    and amplitudes, plus a random walk over ``window_s`` (its Karhunen-Loeve expansion, so the
    whole profile is a sum of sinusoids any block of lines evaluates alike), mixed in a random
    proportion; its least-squares line over the window centred on ``t_centre_s`` is removed and
    it is scaled so that its peak departure from that line is drawn from
    :data:`PROFILE_PEAK_RAD`.

    Returns ``(terms, line, peak)``: terms ``(axis, amplitude_rad, frequency_hz, phase_rad)``
    with phases about ``t_ref_s``, the line (3, 2) ``(bias_rad, rate_rad_s)`` about ``t_ref_s``
    that the terms contain and the profile does not, and the peak (3,) in radians.
    """
    if window_s <= 0:
        raise InputError(f"profile window must be > 0 s, got {window_s}")
    t_start = t_centre_s - 0.5 * window_s
    t = np.linspace(t_start, t_start + window_s, 901)
    lo, hi = np.log(PROFILE_BAND_HZ[0]), np.log(PROFILE_BAND_HZ[1])
    terms: list[tuple[int, float, float, float]] = []
    peaks = np.zeros(3)
    for axis in range(3):
        sines = [(axis, float(rng.uniform(0.3, 1.0)), float(np.exp(rng.uniform(lo, hi))),
                  float(rng.uniform(0.0, 2.0 * np.pi))) for _ in range(_N_SINES)]
        walk = []
        for k in range(1, _N_WALK + 1):
            f = (k - 0.5) / (2.0 * window_s)
            amp = float(rng.normal()) * np.sqrt(2.0 * window_s) / ((k - 0.5) * np.pi)
            phase = 2.0 * np.pi * f * (t_ref_s - t_start)  # sin(2 pi f (t - t_start))
            if amp < 0:
                amp, phase = -amp, phase + np.pi
            walk.append((axis, amp, f, float(np.mod(phase, 2.0 * np.pi))))
        parts = []
        for group in (sines, walk):
            r, _ = _detrended(_terms_angles(group, t, t_ref_s), t, t_ref_s)
            parts.append((group, float(np.sqrt(np.mean(r[axis] ** 2)))))
        w_sine = float(rng.uniform(0.3, 0.7))
        mixed = [(a, amp * w / rms, f, ph) for (group, rms), w in zip(parts, (w_sine, 1 - w_sine),
                                                                   strict=True)
                 for a, amp, f, ph in group]
        r, _ = _detrended(_terms_angles(mixed, t, t_ref_s), t, t_ref_s)
        peaks[axis] = float(rng.uniform(*PROFILE_PEAK_RAD[axis]))
        scale = peaks[axis] / float(np.max(np.abs(r[axis])))
        terms += [(a, amp * scale, f, ph) for a, amp, f, ph in mixed]
    _, line = _detrended(_terms_angles(terms, t, t_ref_s), t, t_ref_s)
    return tuple(terms), line, peaks


def with_profile(att: Attitude, terms: tuple[tuple[int, float, float, float], ...],
                 line: FloatArray) -> Attitude:
    """``att`` plus the profile: its terms added to the jitter, its line taken off the
    polynomial (so the attitude's bias and rate stay those of ``att``)."""
    def poly(c: tuple[float, ...], axis: int) -> tuple[float, ...]:
        c = list(c) + [0.0] * max(0, 2 - len(c))
        c[0] -= float(line[axis, 0])
        c[1] -= float(line[axis, 1])
        return tuple(c)

    return replace(att, roll_rad=poly(att.roll_rad, 0), pitch_rad=poly(att.pitch_rad, 1),
                   yaw_rad=poly(att.yaw_rad, 2), jitter=tuple(att.jitter) + tuple(terms))


# ------------------------------------------------------------------------- ephemeris


def with_ephemeris_error(model: PushbroomModel, bias_m: tuple[float, float, float],
                         time_tag_s: float) -> PushbroomModel:
    """The model with its orbit moved by ``bias_m`` (along track, across track to the right,
    radial up; metres, in the local orbital frame of each ephemeris point) and its lines dated
    ``time_tag_s`` late (the ephemeris and attitude keep their own clock)."""
    o = model.orbit
    frame = orbital_frame(o.positions_m, o.velocities_m_s)  # columns: along, right, down
    b = np.array([bias_m[0], bias_m[1], -bias_m[2]])
    orbit = Orbit(o.times_s, o.positions_m + np.einsum("mij,j->mi", frame, b), o.velocities_m_s,
                  epoch_utc=o.epoch_utc, velocity_frame=o.velocity_frame)
    return replace(model, orbit=orbit, t0_s=model.t0_s + float(time_tag_s))


# ------------------------------------------------------------------------- detector line


def calibrated_camera(camera: ParametricCamera | LookAngleTable, look_scale: float,
                      bow_px: float, segment_offsets_px: tuple[tuple[float, float], ...]
                      ) -> LookAngleTable:
    """The true camera: ``camera``'s look angles with the across-track angles scaled about the
    centre column by ``1 + look_scale``, a parabolic along-track bow worth ``bow_px`` at the line
    ends (relative to the centre), and each of the ``len(segment_offsets_px)`` equal segments of
    the line moved by its (across, along) offset in pixels (none when empty)."""
    table = camera if isinstance(camera, LookAngleTable) else LookAngleTable.from_camera(camera)
    n = table.n_cols
    ifov = table.ifov_rad
    cols = np.arange(n, dtype=np.float64)
    centre = 0.5 * (n - 1)
    u = (cols - centre) / centre
    psi_c = float(np.interp(centre, cols, table.psi_x_rad))
    psi_x = psi_c + (1.0 + look_scale) * (table.psi_x_rad - psi_c)
    psi_y = table.psi_y_rad + bow_px * ifov * u**2
    if segment_offsets_px:
        seg = np.minimum((cols * len(segment_offsets_px) / n).astype(np.int64),
                         len(segment_offsets_px) - 1)
        off = np.asarray(segment_offsets_px, dtype=np.float64)[seg]
        psi_x = psi_x + off[:, 0] * ifov
        psi_y = psi_y + off[:, 1] * ifov
    return LookAngleTable(psi_x_rad=psi_x, psi_y_rad=psi_y)


# ------------------------------------------------------------------------- metadata


def quantise_speeds(scene: SpotScene, quantum_rad_s: float = SPEED_QUANTUM_RAD_S) -> SpotScene:
    """The scene with its AOCS angular speeds rounded to multiples of ``quantum_rad_s`` (as SPOT
    1-4 files state them); a scene without speeds (SPOT 5) is returned as it is."""
    s = scene.aocs_speeds
    if s is None:
        return scene
    if not quantum_rad_s > 0:
        raise InputError(f"speed quantum must be > 0 rad/s, got {quantum_rad_s}")
    q = SpotAngles(s.times_s, *(np.round(getattr(s, k) / quantum_rad_s) * quantum_rad_s
                                for k in ("roll", "pitch", "yaw")), s.out_of_range)
    return replace(scene, aocs_speeds=q)


def metadata_scene(model: PushbroomModel, mission_index: int, instrument: str,
                   **kw: object) -> SpotScene:
    """What a SPOT product of ``mission_index`` states for ``model`` (the attitude as the
    satellite measured it): sampled every 0.125 s, SPOT 1-4 speeds quantised."""
    scene = spot_scene_from_model(model, mission_index=mission_index, instrument=instrument,
                                  **kw)  # type: ignore[arg-type]
    return quantise_speeds(scene) if mission_index < 5 else scene


def realistic_truth(
    truth: PushbroomModel, delivered: PushbroomModel, rng: np.random.Generator,
    mission_index: int,
) -> tuple[PushbroomModel, PushbroomModel, RealisticErrors]:
    """(truth, ideal metadata, record) with the realistic errors drawn from ``rng``: the truth
    with the attitude profile and the detector calibration errors, and the model the satellite's
    own measurements describe (the profile, the ephemeris and time-tag errors), before the
    product samples and quantises them (:func:`measured_model`).

    ``truth`` and ``delivered`` are the simple-mode models (polynomial attitudes that differ by
    biases and rates). A pass of several scenes is drawn whole, then cut into its scenes
    (``with_image_window``): its profile, ephemeris and clock are the pass's.
    """
    if not isinstance(truth.attitude, Attitude) or not isinstance(delivered.attitude, Attitude):
        raise InputError("realistic errors start from polynomial truth and delivered attitudes")
    t_centre = truth.t0_s + 0.5 * (truth.n_rows - 1) * truth.line_period_s
    terms, line, peaks = attitude_profile(rng, t_centre, truth.attitude.t_ref_s)
    truth = replace(truth, attitude=with_profile(truth.attitude, terms, line))
    ideal = replace(delivered, attitude=with_profile(delivered.attitude, terms, line))
    bias = tuple(float(rng.uniform(-m, m)) for m in ORBIT_BIAS_MAX_M)
    time_tag = float(rng.uniform(-TIME_TAG_MAX_S, TIME_TAG_MAX_S))
    ideal = with_ephemeris_error(ideal, bias, time_tag)  # type: ignore[arg-type]
    look_scale = float(rng.uniform(-LOOK_SCALE_MAX, LOOK_SCALE_MAX))
    bow = float(rng.uniform(-BOW_MAX_PX, BOW_MAX_PX))
    n_seg = HRV_SEGMENTS if mission_index < 5 else 0
    offsets = tuple((float(rng.uniform(-SEGMENT_OFFSET_MAX_PX, SEGMENT_OFFSET_MAX_PX)),
                     float(rng.uniform(-SEGMENT_OFFSET_MAX_PX, SEGMENT_OFFSET_MAX_PX)))
                    for _ in range(n_seg))
    truth = replace(truth, camera=calibrated_camera(truth.camera, look_scale, bow, offsets))
    record = RealisticErrors(
        profile=terms, profile_line_rad=tuple((float(a), float(b)) for a, b in line),
        profile_peak_rad=tuple(float(p) for p in peaks),  # type: ignore[arg-type]
        speed_quantum_rad_s=float(SPEED_QUANTUM_RAD_S) if mission_index < 5 else 0.0,
        orbit_bias_m=bias, time_tag_s=time_tag,  # type: ignore[arg-type]
        look_scale=look_scale, bow_px=bow, segment_offsets_px=offsets,
    )
    return truth, ideal, record


def measured_model(ideal: PushbroomModel, mission_index: int,
                   instrument: str) -> PushbroomModel:
    """What the chain reads from the metadata of a product whose satellite measured ``ideal``
    (:func:`metadata_scene` read back by :func:`~core.sensors.spot.spot_pushbroom`)."""
    return spot_pushbroom(metadata_scene(ideal, mission_index, instrument))


def realistic_models(
    truth: PushbroomModel, delivered: PushbroomModel, rng: np.random.Generator,
    mission_index: int, instrument: str,
) -> tuple[PushbroomModel, PushbroomModel, RealisticErrors]:
    """(truth, delivered, record) with the realistic errors drawn from ``rng``
    (:func:`realistic_truth`): the delivered model is what the chain reads from the metadata
    (:func:`measured_model`)."""
    truth, ideal, record = realistic_truth(truth, delivered, rng, mission_index)
    return truth, measured_model(ideal, mission_index, instrument), record
