"""The corrections a pushbroom model adjusts (:class:`core.sensors.pushbroom.PushbroomModel`):
their names, units, how each enters the model, and their values (:class:`Corrections`); see
that module's docstring for their meaning."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace

import numpy as np
from numpy.typing import NDArray

from core.errors import InputError

FloatArray = NDArray[np.float64]

ATTITUDE_BIASES = ("roll_bias", "pitch_bias", "yaw_bias")
ATTITUDE_RATES = ("roll_rate", "pitch_rate", "yaw_rate")
ATTITUDE_QUADS = ("roll_quad", "pitch_quad", "yaw_quad")
ORBIT_OFFSETS = ("orbit_along_m", "orbit_across_m", "orbit_radial_m")
LENS = ("focal_scale", "k1", "k3", "p1", "p2")
DEFAULT_ADJUST = ATTITUDE_BIASES + ATTITUDE_RATES
# the attitude's along-track profile: cos(pi k u) on each axis, u = 0..1 over the image's time
# span (``harmonic_span``), k = 1..N_HARMONICS
N_HARMONICS = 8
ATTITUDE_HARMONICS: dict[str, tuple[int, int]] = {
    f"{axis}_h{k}": (a, k) for a, axis in enumerate(("roll", "pitch", "yaw"))
    for k in range(1, N_HARMONICS + 1)
}
# how each attitude correction enters the polynomials: (axis: 0 roll, 1 pitch, 2 yaw; power of
# t - t_ref: 0 bias, 1 rate, 2 quad)
ATTITUDE_TERMS: dict[str, tuple[int, int]] = {
    name: (axis, power)
    for power, group in enumerate((ATTITUDE_BIASES, ATTITUDE_RATES, ATTITUDE_QUADS))
    for axis, name in enumerate(group)
}
# orbit offsets: (axis of the orbital frame X, Y, Z; sign of the offset along it)
ORBIT_TERMS: dict[str, tuple[int, float]] = {
    "orbit_along_m": (0, 1.0), "orbit_across_m": (1, 1.0), "orbit_radial_m": (2, -1.0),
}


@dataclass(frozen=True, eq=False)
class Corrections:
    """Corrections to the delivered model, one per adjustable parameter (units: module doc).

    The polynomial, orbit and lens corrections are fields; the along-track harmonics are one
    (3, :data:`N_HARMONICS`) array ``harmonic_rad`` ([roll, pitch, yaw] x k = 1..N), whose
    entries the adjustment and the model files name ``roll_h1 ... yaw_h8``
    (:data:`ATTITUDE_HARMONICS`): :meth:`value` and :meth:`with_values` take every name of
    :data:`PARAM_NAMES`.
    """

    roll_bias: float = 0.0
    pitch_bias: float = 0.0
    yaw_bias: float = 0.0
    roll_rate: float = 0.0
    pitch_rate: float = 0.0
    yaw_rate: float = 0.0
    roll_quad: float = 0.0
    pitch_quad: float = 0.0
    yaw_quad: float = 0.0
    orbit_along_m: float = 0.0
    orbit_across_m: float = 0.0
    orbit_radial_m: float = 0.0
    focal_scale: float = 0.0
    k1: float = 0.0
    k3: float = 0.0
    p1: float = 0.0
    p2: float = 0.0
    harmonic_rad: FloatArray = field(default_factory=lambda: np.zeros((3, N_HARMONICS)))

    def __post_init__(self) -> None:
        h = np.array(self.harmonic_rad, dtype=np.float64)
        if h.shape != (3, N_HARMONICS):
            raise InputError(f"the along-track harmonics must be (3, {N_HARMONICS}) angles "
                             f"(roll, pitch, yaw x 1..{N_HARMONICS}), got shape {h.shape}")
        h.setflags(write=False)
        object.__setattr__(self, "harmonic_rad", h)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Corrections):
            return NotImplemented
        return all(self.value(n) == other.value(n) for n in PARAM_NAMES)

    __hash__ = None  # type: ignore[assignment]

    @classmethod
    def from_values(cls, values: Mapping[str, float]) -> Corrections:
        """Corrections from a mapping of names of :data:`PARAM_NAMES` (absent: 0)."""
        return cls().with_values(values)

    def value(self, name: str) -> float:
        """The correction called ``name`` (any of :data:`PARAM_NAMES`)."""
        if name in ATTITUDE_HARMONICS:
            axis, k = ATTITUDE_HARMONICS[name]
            return float(self.harmonic_rad[axis, k - 1])
        return float(getattr(self, name))

    def values(self, names: tuple[str, ...]) -> FloatArray:
        return np.array([self.value(n) for n in names], dtype=np.float64)

    def with_values(self, values: Mapping[str, float]) -> Corrections:
        """These corrections with those named in ``values`` replaced."""
        h = self.harmonic_rad.copy()
        plain = {}
        for name, v in values.items():
            if name in ATTITUDE_HARMONICS:
                axis, k = ATTITUDE_HARMONICS[name]
                h[axis, k - 1] = v
            else:
                plain[name] = float(v)
        return replace(self, **plain, harmonic_rad=h)

    def attitude_delta(self) -> FloatArray:
        """(3, 3): [roll, pitch, yaw] x [bias, rate, quad]."""
        delta = np.zeros((3, 3))
        for name, (axis, power) in ATTITUDE_TERMS.items():
            delta[axis, power] = getattr(self, name)
        return delta

    def harmonics(self) -> FloatArray:
        """(3, N_HARMONICS): [roll, pitch, yaw] x the along-track harmonics 1..N."""
        return self.harmonic_rad


PARAM_NAMES: tuple[str, ...] = (
    tuple(f.name for f in fields(Corrections) if f.name != "harmonic_rad")
    + tuple(ATTITUDE_HARMONICS))
PARAM_UNITS: dict[str, str] = {
    **{n: ("rad", "rad/s", "rad/s^2")[power] for n, (_, power) in ATTITUDE_TERMS.items()},
    **{n: "m" for n in ORBIT_TERMS}, **{n: "1" for n in LENS},
    **{n: "rad" for n in ATTITUDE_HARMONICS},
}


def correction_centre_of(d: object) -> tuple[float, float]:
    v = d.get("correction_centre", [0.0, 0.0])  # type: ignore[union-attr]
    if (not isinstance(v, list) or len(v) != 2
            or not all(isinstance(x, (int, float)) and np.isfinite(x) for x in v)):
        raise InputError(f"key 'correction_centre' must be two numbers (x, y), got {v!r:.80}")
    return float(v[0]), float(v[1])


def harmonic_span_of(d: object) -> tuple[float, float] | None:
    v = d.get("harmonic_span_s")  # type: ignore[union-attr]
    if v is None:
        return None
    if (not isinstance(v, list) or len(v) != 2
            or not all(isinstance(x, (int, float)) and np.isfinite(x) for x in v) or v[1] <= 0):
        raise InputError(f"key 'harmonic_span_s' must be (start s, duration s > 0), got {v!r:.80}")
    return float(v[0]), float(v[1])


def check_adjust(names: tuple[str, ...]) -> tuple[str, ...]:
    names = tuple(names)
    bad = [n for n in names if n not in PARAM_NAMES]
    if bad or len(set(names)) != len(names):
        raise InputError(
            f"adjust names {bad or names} are unknown or repeated; choose distinct names "
            f"among {PARAM_NAMES}"
        )
    return names
