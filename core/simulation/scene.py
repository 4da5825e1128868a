"""Scene definitions of the simulator: presets, truth models, delivered-metadata errors.

Pure numerics on the pushbroom model. The truth models carry what the delivered metadata
lack (lens distortion with ``lens``, high-frequency attitude jitter with ``jitter``); the
delivered models differ from the truth by attitude biases worth 100-300 m on the ground
at the scene centre and by attitude drifts, as archive SPOT metadata do.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace

import numpy as np
from numpy.typing import NDArray

from core.errors import InputError
from core.geodesy import geodetic_to_ecef
from core.sensors.linear_array import LensDistortion
from core.sensors.pushbroom import PushbroomModel

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class ImageSpec:
    """One image of a stereo pair: viewing angles and the sun of its date."""

    name: str
    incidence_deg: float  # across-track, + = satellite west of the scene, looking east
    pitch_deg: float  # along-track tilt, + = forward
    date: str
    sun_azimuth_deg: float
    sun_elevation_deg: float


@dataclass(frozen=True)
class Preset:
    """Image size, sampling and the pair's geometry."""

    name: str
    n_cols: int
    n_rows: int
    gsd_m: float
    truth_res_m: float  # spacing of the truth DSM/DTM grid
    images: tuple[ImageSpec, ImageSpec]
    lidar_strip_m: tuple[float, float] | None  # (across, along) size; None = whole scene
    lidar_spacing_m: float = 3.0

    def __post_init__(self) -> None:
        if self.n_cols < 16 or self.n_rows < 16 or self.gsd_m <= 0 or self.truth_res_m <= 0:
            raise InputError(f"preset {self.name!r}: image must be >= 16x16 px with positive GSD")


_ACROSS = (
    ImageSpec("left", 25.5, 0.0, "2023-07-12", 140.0, 63.0),
    ImageSpec("right", -20.0, 0.0, "2023-08-29", 158.0, 50.0),
)
PRESETS: dict[str, Preset] = {
    # SPOT 1-4 HRV across-track pair from two dates, 10 m panchromatic
    "spot": Preset("spot", 6000, 6000, 10.0, 10.0, _ACROSS, (5_000.0, 13_000.0)),
    # SPOT 5 HRS-like along-track pair, same pass (B/H about 0.8)
    "hrs": Preset(
        "hrs", 6000, 6000, 10.0, 10.0,
        (ImageSpec("left", 0.0, 20.0, "2023-07-12", 140.0, 63.0),
         ImageSpec("right", 0.0, -20.0, "2023-07-12", 140.0, 63.0)),
        (5_000.0, 13_000.0),
    ),
    # the same physics at 600x600 px and 40 m, for CI
    # (lidar over the whole scene, its spacing scaled with the GSD to stay CI-sized)
    "tiny": Preset("tiny", 600, 600, 40.0, 20.0, _ACROSS, None, lidar_spacing_m=20.0),
}


@dataclass(frozen=True)
class ErrorConfig:
    """Errors of the delivered metadata and of the truth that the metadata ignore."""

    centre_error_m: tuple[float, float] = (100.0, 300.0)  # attitude bias effect at the centre
    drift_m: float = 20.0  # typical ground drift over the scene from attitude rates (1 sigma)
    lens: bool = False  # truth camera has radial + decentering distortion the metadata lack
    lens_edge_px: float = 1.5  # distortion at the image edge, pixels
    jitter: bool = False  # truth attitude has high-frequency jitter
    jitter_rms_px: float = 0.3  # jitter amplitude as ground displacement, pixels RMS

    def __post_init__(self) -> None:
        lo, hi = self.centre_error_m
        if not 0 <= lo <= hi:
            raise InputError(f"centre_error_m must be (min, max) with 0 <= min <= max, got {lo, hi}")
        if self.drift_m < 0 or self.lens_edge_px < 0 or self.jitter_rms_px < 0:
            raise InputError("drift, lens and jitter magnitudes must be >= 0")


@dataclass(frozen=True)
class InjectedErrors:
    """What the simulator did to one image's metadata (for the truth record)."""

    roll_bias_rad: float
    pitch_bias_rad: float
    yaw_bias_rad: float
    roll_rate_rad_s: float
    pitch_rate_rad_s: float
    yaw_rate_rad_s: float
    centre_error_m: float
    jitter: tuple[tuple[int, float, float, float], ...]
    distortion: dict

    def to_dict(self) -> dict:
        return asdict(self)


def truth_model(
    spec: ImageSpec, preset: Preset, centre: tuple[float, float, float], cfg: ErrorConfig,
    rng: np.random.Generator,
) -> PushbroomModel:
    """The true geometry of one image (with the lens distortion and jitter the metadata lack)."""
    lon, lat, h = centre
    model = PushbroomModel.synthetic(
        lon, lat, center_h_m=h, n_cols=preset.n_cols, n_rows=preset.n_rows, gsd_m=preset.gsd_m,
        incidence_deg=spec.incidence_deg, pitch_deg=spec.pitch_deg,
        epoch_utc=f"{spec.date}T10:00:00Z",
    )
    if cfg.lens:
        # radial k3 r^3 worth lens_edge_px at the edge of the detector line (r in normalised
        # focal-plane units, measured on this camera), decentering a tenth of it
        ex, ey = model.camera.detector_xy(np.array([0.0]))
        r_edge = float(np.hypot(ex[0], ey[0]))
        px = r_edge / (0.5 * (preset.n_cols - 1))  # one pixel in normalised units
        k3 = cfg.lens_edge_px * px / r_edge**3 * float(rng.choice([-1.0, 1.0]))
        p = 0.1 * cfg.lens_edge_px * px / r_edge**2
        model = replace(model, distortion=LensDistortion(
            k1=0.0, k3=k3, p1=p * rng.uniform(-1, 1), p2=p * rng.uniform(-1, 1)))
    if cfg.jitter:
        model = with_jitter(model, preset, cfg.jitter_rms_px, rng)
    return model


def with_jitter(
    model: PushbroomModel, preset: Preset, rms_px: float, rng: np.random.Generator
) -> PushbroomModel:
    """Add roll and pitch jitter: two tones per axis, periods of 30-600 lines (about 1-20 Hz
    for SPOT), each axis ``rms_px`` RMS as ground displacement (two tones of amplitude a
    have an RMS of a)."""
    amp_rad = rms_px * preset.gsd_m / _slant_range_m(model)
    terms = []
    for axis in (0, 1):  # roll moves the ground across track, pitch along track
        for _ in range(2):
            freq = 1.0 / (rng.uniform(30.0, 600.0) * model.line_period_s)
            terms.append((axis, float(amp_rad), float(freq), float(rng.uniform(0, 2 * np.pi))))
    return replace(model, attitude=replace(model.attitude, jitter=tuple(terms)))


def _slant_range_m(model: PushbroomModel) -> float:
    c, r = 0.5 * (model.n_cols - 1), 0.5 * (model.n_rows - 1)
    lon, lat = model.localize(c, r, 0.0)
    g = np.array(geodetic_to_ecef(lon, lat, 0.0)).ravel()
    pos, _ = model.orbit.interpolate(np.atleast_1d(model.line_time_s(r)))
    return float(np.linalg.norm(pos[0] - g))


def centre_displacement_m(a: PushbroomModel, b: PushbroomModel, h_m: float) -> float:
    """Ground distance between what two models localise for the centre pixel at height h."""
    c, r = 0.5 * (a.n_cols - 1), 0.5 * (a.n_rows - 1)
    pa = np.array(geodetic_to_ecef(*a.localize(c, r, h_m), h_m)).ravel()
    pb = np.array(geodetic_to_ecef(*b.localize(c, r, h_m), h_m)).ravel()
    return float(np.linalg.norm(pa - pb))


def delivered_model(
    truth: PushbroomModel, preset: Preset, cfg: ErrorConfig, rng: np.random.Generator,
    h_centre_m: float,
) -> tuple[PushbroomModel, InjectedErrors]:
    """The metadata as an archive delivers them: biased, drifting, no jitter, no distortion."""
    att = truth.attitude
    base = replace(truth, attitude=replace(att, jitter=()), distortion=LensDistortion())
    target = rng.uniform(*cfg.centre_error_m)
    direction = rng.normal(size=3)
    direction /= np.linalg.norm(direction)
    range_m = _slant_range_m(truth)
    duration = truth.n_rows * truth.line_period_s
    rates = rng.normal(size=3) * cfg.drift_m / (range_m * duration)

    def make(bias: FloatArray) -> PushbroomModel:
        def poly(c: tuple[float, ...], b: float, r: float) -> tuple[float, ...]:
            c = list(c) + [0.0] * max(0, 2 - len(c))
            c[0] += b
            c[1] += r
            return tuple(c)
        new_att = replace(
            base.attitude,
            roll_rad=poly(att.roll_rad, bias[0], rates[0]),
            pitch_rad=poly(att.pitch_rad, bias[1], rates[1]),
            yaw_rad=poly(att.yaw_rad, bias[2], rates[2]),
        )
        return replace(base, attitude=new_att)

    # scale the bias so the centre moves by the target distance (rates vanish at t_ref,
    # close to the centre line; two secant passes absorb the non-linearity)
    scale = target / range_m
    for _ in range(3):
        d = centre_displacement_m(truth, make(direction * scale), h_centre_m)
        if d <= 0:
            raise InputError("the injected attitude bias does not move the scene; check the preset")
        scale *= target / d
    delivered = make(direction * scale)
    err = centre_displacement_m(truth, delivered, h_centre_m)
    b = direction * scale
    return delivered, InjectedErrors(
        float(b[0]), float(b[1]), float(b[2]), float(rates[0]), float(rates[1]), float(rates[2]),
        err, tuple(getattr(att, "jitter", ())), asdict(truth.distortion),
    )
