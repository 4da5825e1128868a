"""The frames of the ground control: each source's registration as an unknown of the adjustment.

GCPs taken from a reference DEM (surface matching against SRTM or Copernicus) carry the
reference's registration error, a shift common to all of them; GCPs from a SAR scene carry the
SAR product's geolocation error (its orbit, azimuth time and range delay), common to all of them
too. Neither shows in its own GCPs' residuals: the images' biases follow a common shift whole.
So each source is a *frame*: an unknown shift ``s`` (east, north, up; m) of its GCPs' ground,
``X_true = X_gcp + s``, estimated with everything else, held by a prior ``s ~ N(0, S)`` from what
its producer states (SRTM's registration, the SAR mission's geolocation and what its matching
leaves). One source alone: its frame and the images' biases trade exactly, so the frame is not
estimated but *considered* (``estimated=False``): held at 0 in the solution, its prior carried
into the parameters' covariance (what the reference's registration does to the check points;
a GCP signal the biases cannot follow, such as an unmodelled lens, never moves it). Two
sources: their frames' difference is observed by the images they share, both are estimated,
the better-known frame wins, and the other's shift is measured (a figure no SRTM-only
orientation can give): the SRTM's own misregistration against a precise SAR product.

A SAR scene's GCP heights come from the SAR-optical parallax calibrated on the reference's
heights (:mod:`core.orientation.sar_gcps`): their vertical is the reference's, so a SAR frame
shares the reference's up (``up_of``).

What a source states of itself is not all it may share: surface-matching windows overlap and
inherit the relative DEM's deformation, so over low relief their errors are correlated across
the scene and their mean is off by about their own precision, whatever SRTM's registration
(simulated tiny at relief x0.05: 8 windows of 18-20 m off by 32 m east in common). Where
frames meet, such a frame's prior also holds it
(:func:`core.orientation.adjust.frames_widened`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.errors import InputError
from core.geodesy import metres_per_degree

FloatArray = NDArray[np.float64]

#: the frame of GCPs made from the reference DEM (and of a GCP file in the reference's datum)
REFERENCE = "reference"
AXES = ("east", "north", "up")


@dataclass(frozen=True)
class FramePrior:
    """One control source's registration: the prior 1-sigma ``sigma_m`` (east, north, up; m) of
    the common shift of its GCPs' ground, 0 for a component known exactly (not estimated);
    ``up_of``: the frame whose vertical this one shares (its own up is not estimated);
    ``source``: where the figures come from (for the report); ``estimated``: False for a
    frame only considered (held at 0, its prior in the covariance: a frame alone)."""

    name: str
    sigma_m: tuple[float, float, float]
    up_of: str | None = None
    source: str = ""
    estimated: bool = True

    def __post_init__(self) -> None:
        s = tuple(float(v) for v in self.sigma_m)
        if len(s) != 3 or not all(np.isfinite(s)) or min(s) < 0:
            raise InputError(f"frame {self.name!r}: sigma_m is (east, north, up) >= 0 m, got "
                             f"{self.sigma_m}")
        object.__setattr__(self, "sigma_m", s)
        if self.up_of == self.name:
            raise InputError(f"frame {self.name!r} cannot share its own vertical")

    def inflated(self, extra_m: ArrayLike, why: str) -> FramePrior:
        """This prior with ``extra_m`` (east, north, up; m) added in quadrature."""
        e = np.asarray(extra_m, dtype=np.float64)
        s = np.hypot(np.asarray(self.sigma_m), e)
        return FramePrior(self.name, (float(s[0]), float(s[1]), float(s[2])), self.up_of,
                          f"{self.source}; {why}" if self.source else why, self.estimated)


@dataclass(frozen=True, eq=False)
class FrameLayout:
    """Where the frames' unknowns sit among an adjustment's frame parameters: ``index`` (n_frames,
    3) the parameter of each frame's east, north, up (-1: fixed at 0), ``sigma_m`` (n_params,)
    each parameter's prior sigma, ``estimated`` (n_params,) whether it is solved for (else
    only considered: held at 0, in the covariance)."""

    priors: tuple[FramePrior, ...]
    index: NDArray[np.intp]
    sigma_m: FloatArray
    estimated: NDArray[np.bool_]

    @classmethod
    def of(cls, priors: Sequence[FramePrior]) -> FrameLayout:
        priors = tuple(priors)
        names = [p.name for p in priors]
        if len(set(names)) != len(names):
            raise InputError(f"frame names must be unique, got {names}")
        index = np.full((len(priors), 3), -1, dtype=np.intp)
        sigma: list[float] = []
        estimated: list[bool] = []
        for f, p in enumerate(priors):
            for c in range(3):
                if c == 2 and p.up_of is not None:
                    continue
                if p.sigma_m[c] > 0:
                    index[f, c] = len(sigma)
                    sigma.append(p.sigma_m[c])
                    estimated.append(p.estimated)
        for f, p in enumerate(priors):
            if p.up_of is not None:
                if p.up_of not in names:
                    raise InputError(f"frame {p.name!r} shares the vertical of {p.up_of!r}, "
                                     f"which is not among {names}")
                index[f, 2] = index[names.index(p.up_of), 2]
        return cls(priors, index, np.asarray(sigma, dtype=np.float64),
                   np.asarray(estimated, dtype=bool))

    @property
    def n(self) -> int:
        return int(self.sigma_m.size)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.priors)

    def frame_of(self, name: str) -> int:
        if name not in self.names:
            raise InputError(f"no frame {name!r} among {', '.join(self.names)}")
        return self.names.index(name)

    def shifts_m(self, x: ArrayLike) -> FloatArray:
        """(n_frames, 3) each frame's shift (east, north, up; m) at frame parameters ``x``."""
        xx = np.concatenate([np.asarray(x, dtype=np.float64), [0.0]])
        return xx[np.where(self.index >= 0, self.index, -1)]

    def prior_rows(self) -> FloatArray:
        """Whitened prior equations (n, n): ``rows @ x`` of unit variance, target 0."""
        return np.diag(1.0 / self.sigma_m) if self.n else np.zeros((0, 0))


def shifted_ground(lon_deg: ArrayLike, lat_deg: ArrayLike, h_m: ArrayLike,
                   shift_m: ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Ground points moved by ``shift_m`` ((n, 3) or (3,): east, north, up; m)."""
    lon = np.asarray(lon_deg, dtype=np.float64)
    lat = np.asarray(lat_deg, dtype=np.float64)
    s = np.broadcast_to(np.asarray(shift_m, dtype=np.float64), lon.shape + (3,))
    m_lon, m_lat = metres_per_degree(lat)
    return lon + s[..., 0] / m_lon, lat + s[..., 1] / m_lat, np.asarray(h_m) + s[..., 2]


@dataclass(frozen=True)
class FrameEstimate:
    """One frame after the adjustment: its prior (``prior_sigma_m``, where it came from
    ``source``), the estimated shift of its GCPs' ground onto the truth ``shift_m`` (east,
    north, up; m; ``X_true = X_gcp + shift``) and its posterior 1-sigma ``sigma_m``;
    ``observed``: the other control made it known better than its prior (posterior under 0.8 of
    the prior on some axis): then the estimate is a measurement, not the prior's 0."""

    name: str
    prior_sigma_m: tuple[float, float, float]
    shift_m: tuple[float, float, float]
    sigma_m: tuple[float, float, float]
    observed: bool
    source: str = ""
    up_of: str | None = None

    def to_dict(self) -> dict[str, object]:
        return {"name": self.name, "prior_sigma_m": list(self.prior_sigma_m),
                "shift_m": list(self.shift_m), "sigma_m": list(self.sigma_m),
                "observed": self.observed, "source": self.source, "up_of": self.up_of}


def frame_estimates(layout: FrameLayout, x: ArrayLike, covariance: ArrayLike
                    ) -> tuple[FrameEstimate, ...]:
    """The frames' estimates from the frame parameters ``x`` and their covariance (n, n)."""
    c = np.asarray(covariance, dtype=np.float64)
    sd = np.concatenate([np.sqrt(np.clip(np.diag(c), 0.0, None)), [0.0]]) if layout.n \
        else np.zeros(1)
    shifts = layout.shifts_m(x)
    out = []
    for f, p in enumerate(layout.priors):
        idx = layout.index[f]
        sig = sd[np.where(idx >= 0, idx, -1)]
        prior = np.asarray(p.sigma_m)
        if p.up_of is not None:
            prior = prior.copy()
            prior[2] = layout.priors[layout.frame_of(p.up_of)].sigma_m[2]
        observed = bool(np.any((idx >= 0) & (prior > 0) & (sig < 0.8 * prior)))
        out.append(FrameEstimate(p.name, tuple(float(v) for v in prior),
                                 tuple(float(v) for v in shifts[f]),
                                 tuple(float(v) for v in sig), observed, p.source, p.up_of))
    return tuple(out)
