"""gcpfree's model files (the JSON of each sensor model of core/sensors/) on
:mod:`tasks.io.documents`: a pushbroom model (``gcpfree.pushbroom``), a SAR model
(``gcpfree.sar``) and an RPC (``"type": "rpc"``), each with its documented layout (see the
docstrings of :mod:`core.sensors.pushbroom`, :mod:`core.sensors.sar`,
:mod:`core.sensors.rpc`). A pushbroom or SAR file groups some fields (``image``, ``timing``,
``grd``, ``tops``, ``corrections``) where the model holds them flat: its dataclass here is the
file's layout, with the conversion to and from the model. An oriented model carries the sun
of its metadata (``sun``, :data:`SUN_KEY`).

:func:`model_document` and :func:`read_model_document` are the one writer and reader of the
three; the files they write are byte for byte those of the models' own ``to_dict``
(``tests/tasks/test_documents.py``), which stay until their last callers move here.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from core.errors import InputError
from core.sensors.corrections import ATTITUDE_HARMONICS, PARAM_NAMES, Corrections
from core.sensors.linear_array import LensDistortion, LookAngleTable, ParametricCamera
from core.sensors.orbit import Attitude, AttitudeModel, Orbit, SampledAttitude
from core.sensors.pushbroom import FORMAT as PUSHBROOM_FORMAT
from core.sensors.pushbroom import PushbroomModel
from core.sensors.rpc import RPCModel
from core.sensors.sar import FORMAT as SAR_FORMAT
from core.sensors.sar import PARAM_NAMES as SAR_PARAM_NAMES
from core.sensors.sar import SarModel
from tasks.io.documents import Document, layout

FloatArray = NDArray[np.float64]

#: the key of a model file that carries the sun of the metadata it was made from
SUN_KEY = "sun"

layout(Orbit, omit_default=("velocity_frame",), finite=True,
       order=("epoch_utc", "times_s", "positions_m", "velocities_m_s", "velocity_frame"))
layout(Attitude, omit_default=("jitter",), tag=("type", "polynomial"), tag_default=True,
       tag_written=False, finite=True)
layout(SampledAttitude, tag=("type", "sampled"), finite=True,
       order=("type", "t_ref_s", "times_s", "roll_rad", "pitch_rad", "yaw_rad"))
layout(ParametricCamera, tag=("type", "parametric"), finite=True)
layout(LookAngleTable, tag=("type", "table"), finite=True)
layout(LensDistortion, finite=True)
layout(RPCModel, finite=True, tag=("type", "rpc"), computed={"version": lambda m: 1},
       order=("type", "version"))


@dataclass(frozen=True)
class Sun:
    """The sun at imaging, degrees."""

    azimuth_deg: float
    elevation_deg: float

    def __post_init__(self) -> None:
        if not -90.0 <= self.elevation_deg <= 90.0:
            raise InputError(f"key '{SUN_KEY}' has azimuth {self.azimuth_deg} and elevation "
                             f"{self.elevation_deg} deg (need a finite azimuth and an elevation "
                             "within -90..90)")


layout(Sun, finite=True)

# ------------------------------------------------------------------------------ pushbroom


@dataclass(frozen=True)
class ImageSize:
    """``image``: the image's size, pixels (n_cols is the camera's)."""

    n_cols: int
    n_rows: int


@dataclass(frozen=True)
class PushbroomTiming:
    """``timing``: the first line's time (s since the orbit's epoch) and the line period (s)."""

    t0_s: float
    line_period_s: float


@dataclass(frozen=True, kw_only=True)
class PushbroomFile:
    """A ``gcpfree.pushbroom`` model file (format: :mod:`core.sensors.pushbroom`)."""

    format: str = PUSHBROOM_FORMAT
    version: int = 1
    image: ImageSize
    timing: PushbroomTiming
    orbit: Orbit
    attitude: AttitudeModel
    camera: ParametricCamera | LookAngleTable
    distortion: LensDistortion
    adjust: tuple[str, ...]
    corrections: Mapping[str, float] = field(default_factory=dict)
    correction_centre: tuple[float, float] = (0.0, 0.0)  # files before it: about the axis
    harmonic_span_s: tuple[float, float] | None = None
    sun: Sun | None = None

    @classmethod
    def of(cls, m: PushbroomModel, sun: Sun | None = None) -> PushbroomFile:
        c = m.corrections
        return cls(image=ImageSize(m.n_cols, m.n_rows),
                   timing=PushbroomTiming(m.t0_s, m.line_period_s), orbit=m.orbit,
                   attitude=m.attitude, camera=m.camera, distortion=m.distortion,
                   adjust=m.adjust,
                   corrections={n: c.value(n) for n in PARAM_NAMES
                                if n not in ATTITUDE_HARMONICS or c.value(n)},
                   correction_centre=m.correction_centre,  # type: ignore[arg-type]
                   harmonic_span_s=m.harmonic_span, sun=sun)

    def model(self) -> PushbroomModel:
        if self.image.n_cols != self.camera.n_cols:
            raise InputError(f"key 'image.n_cols' ({self.image.n_cols}) differs from the "
                             f"camera's {self.camera.n_cols} columns")
        if any(k not in PARAM_NAMES for k in self.corrections):
            raise InputError(f"key 'corrections' must map names among {PARAM_NAMES} to "
                             f"numbers, got {dict(self.corrections)!r:.80}")
        return PushbroomModel(
            orbit=self.orbit, attitude=self.attitude, camera=self.camera,
            n_rows=self.image.n_rows, t0_s=self.timing.t0_s,
            line_period_s=self.timing.line_period_s, distortion=self.distortion,
            adjust=self.adjust, corrections=Corrections.from_values(self.corrections),
            correction_centre=self.correction_centre, harmonic_span=self.harmonic_span_s)


layout(ImageSize, finite=True)
layout(PushbroomTiming, finite=True)
layout(PushbroomFile, finite=True, omit_default=("sun",))
PUSHBROOM: Document[PushbroomFile] = Document(
    "pushbroom model", PushbroomFile, format=PUSHBROOM_FORMAT,
    hint="give the model file gcpfree wrote (format: core/sensors/pushbroom.py)")

# ------------------------------------------------------------------------------ SAR


@dataclass(frozen=True)
class SarImage:
    """``image``: the size and, for a crop, its first pixel in the product's (pixels)."""

    n_cols: int
    n_rows: int
    col0_px: float = 0.0
    row0_px: float = 0.0


@dataclass(frozen=True)
class SarTiming:
    """``timing``: azimuth and two-way slant-range times, sampling (seconds, hertz, metres)."""

    first_line_time_s: float
    line_interval_s: float
    slant_range_time_s: float
    range_sampling_rate_hz: float
    range_pixel_spacing_m: float = 0.0


@dataclass(frozen=True)
class SarGrd:
    """``grd``: the slant-to-ground-range polynomials (times, sr0 and coefficients)."""

    srgr_times_s: FloatArray
    srgr_sr0_m: FloatArray
    srgr_coeffs: FloatArray


@dataclass(frozen=True)
class SarTops:
    """``tops``: the bursts' first times (s) and lines per burst."""

    burst_times_s: FloatArray
    lines_per_burst: int


@dataclass(frozen=True, kw_only=True)
class SarFile:
    """A ``gcpfree.sar`` model file (format: :mod:`core.sensors.sar`)."""

    format: str = SAR_FORMAT
    version: int = 1
    kind: str
    look_side: str = "right"
    mission: str = ""
    mode: str = ""
    image: SarImage
    timing: SarTiming
    orbit: Orbit
    grd: SarGrd | None = None
    tops: SarTops | None = None
    corrections: Mapping[str, float] = field(default_factory=dict)
    sun: Sun | None = None

    @classmethod
    def of(cls, m: SarModel, sun: Sun | None = None) -> SarFile:
        return cls(
            kind=m.kind, look_side=m.look_side, mission=m.mission, mode=m.mode,
            image=SarImage(m.n_cols, m.n_rows, float(m.col0_px), float(m.row0_px)),
            timing=SarTiming(float(m.first_line_time_s), float(m.line_interval_s),
                             float(m.slant_range_time_s), float(m.range_sampling_rate_hz),
                             float(m.range_pixel_spacing_m)),
            orbit=m.orbit,
            grd=SarGrd(m.srgr_times_s, m.srgr_sr0_m, m.srgr_coeffs) if m.kind == "grd" else None,
            tops=SarTops(m.burst_times_s, m.lines_per_burst) if m.kind == "tops" else None,
            corrections={n: float(getattr(m, n)) for n in SAR_PARAM_NAMES}, sun=sun)

    def model(self) -> SarModel:
        if any(k not in SAR_PARAM_NAMES for k in self.corrections):
            raise InputError(f"key 'corrections' must map names among {SAR_PARAM_NAMES} to "
                             f"numbers, got {dict(self.corrections)!r:.80}")
        for kind in ("grd", "tops"):
            if self.kind == kind and getattr(self, kind) is None:
                raise InputError(f"key '{kind}' is missing; add it (see the format in "
                                 "core/sensors/sar.py)")
        i, t = self.image, self.timing
        extra: dict[str, Any] = {}
        if self.kind == "grd" and self.grd is not None:
            extra = {"srgr_times_s": self.grd.srgr_times_s, "srgr_sr0_m": self.grd.srgr_sr0_m,
                     "srgr_coeffs": self.grd.srgr_coeffs}
        if self.kind == "tops" and self.tops is not None:
            extra = {"burst_times_s": self.tops.burst_times_s,
                     "lines_per_burst": self.tops.lines_per_burst}
        return SarModel(
            orbit=self.orbit, kind=self.kind, n_cols=i.n_cols, n_rows=i.n_rows,
            col0_px=i.col0_px, row0_px=i.row0_px, first_line_time_s=t.first_line_time_s,
            line_interval_s=t.line_interval_s, slant_range_time_s=t.slant_range_time_s,
            range_sampling_rate_hz=t.range_sampling_rate_hz,
            range_pixel_spacing_m=t.range_pixel_spacing_m, look_side=self.look_side,
            mission=self.mission, mode=self.mode,
            **{n: float(self.corrections.get(n, 0.0)) for n in SAR_PARAM_NAMES}, **extra)


for cls in (SarImage, SarTiming, SarGrd, SarTops):
    layout(cls, finite=True)
layout(SarFile, finite=True, omit_default=("grd", "tops", "sun"),
       order=("format", "version", "kind", "look_side", "mission", "mode", "image", "timing",
              "orbit", "grd", "tops", "corrections", "sun"))
SAR: Document[SarFile] = Document(
    "SAR model", SarFile, format=SAR_FORMAT,
    hint="give the model file gcpfree wrote (format: core/sensors/sar.py)")

# ------------------------------------------------------------------------------ RPC

RPC: Document[RPCModel] = Document("RPC model", RPCModel,
                                   hint="give the RPC file gcpfree wrote")

# ------------------------------------------------------------------------------ all three


def model_document(model: PushbroomModel | SarModel | RPCModel,
                   sun: tuple[float, float] | None = None) -> dict[str, Any]:
    """The model file of ``model`` (with the sun of its metadata, azimuth and elevation in
    degrees, for a pushbroom or SAR model), JSON-ready."""
    s = Sun(float(sun[0]), float(sun[1])) if sun is not None else None
    if isinstance(model, PushbroomModel):
        return PUSHBROOM.dump(PushbroomFile.of(model, s))
    if isinstance(model, SarModel):
        return SAR.dump(SarFile.of(model, s))
    if isinstance(model, RPCModel):
        return RPC.dump(model)
    raise InputError(f"a {type(model).__name__} has no gcpfree model file")


def family_of(doc: object) -> str:
    """``"rpc"``, ``"sar"`` or ``"pushbroom"`` (the default) of a parsed model file."""
    if isinstance(doc, dict) and doc.get("type") == "rpc":
        return "rpc"
    if isinstance(doc, dict) and doc.get("format") == SAR_FORMAT:
        return "sar"
    return "pushbroom"


def read_model_document(doc: object, what: str
                        ) -> tuple[PushbroomModel | SarModel | RPCModel, tuple[float, float] | None]:
    """The model of a parsed model file and its sun (None when it has none); InputError
    naming ``what`` (the file) and the key that is wrong."""
    family = family_of(doc)
    if family == "rpc":
        return RPC.load(doc, what), None
    document = SAR if family == "sar" else PUSHBROOM
    f = document.load(doc, f"{what}: {document.name}")
    try:
        model = f.model()
    except InputError as exc:
        raise InputError(f"{what}: {document.name}: {exc}; {document.hint}") from None
    return model, ((f.sun.azimuth_deg, f.sun.elevation_deg) if f.sun is not None else None)


__all__ = ["PUSHBROOM", "RPC", "SAR", "SUN_KEY", "PushbroomFile", "SarFile", "Sun", "family_of",
           "model_document", "read_model_document"]
