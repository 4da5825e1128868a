"""The GCPs as an adjustment takes them: their ground, their measurements in every image, their
precisions and the frame each belongs to (:mod:`core.orientation.frames`)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.errors import InputError
from core.orientation.frames import FrameLayout, shifted_ground
from core.points import ControlPoint

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class Observations:
    """GCP measurements in the images: ``col``/``row`` (n_gcp, n_img) with NaN where a GCP is
    not measured in an image; GCP ground coordinates (n_gcp,); ground precisions (m);
    ``frame`` (n_gcp,) the index of each GCP's frame among the adjustment's (0 by default: the
    reference's)."""

    lon_deg: FloatArray
    lat_deg: FloatArray
    h_m: FloatArray
    col: FloatArray
    row: FloatArray
    sigma_xy_m: FloatArray
    sigma_h_m: FloatArray
    frame: NDArray[np.intp] | None = None

    def __post_init__(self) -> None:
        n = np.asarray(self.lon_deg).size
        frame = np.zeros(n, dtype=np.intp) if self.frame is None \
            else np.asarray(self.frame, dtype=np.intp)
        if frame.shape != (n,) or (n and frame.min() < 0):
            raise InputError(f"GCP frame indices have shape {frame.shape}, expected ({n},) "
                             "of indices >= 0")
        object.__setattr__(self, "frame", frame)
        for name in ("lat_deg", "h_m", "sigma_xy_m", "sigma_h_m"):
            if np.asarray(getattr(self, name)).shape != (n,):
                raise InputError(f"GCP {name} has shape {np.shape(getattr(self, name))}, "
                                 f"expected ({n},)")
        if np.shape(self.col) != np.shape(self.row) or np.shape(self.col)[0] != n:
            raise InputError("GCP image coordinates must be (n_gcp, n_images), cols and rows "
                             "alike")

    def subset(self, idx: ArrayLike) -> Observations:
        """The GCPs ``idx`` (indices or a boolean mask), in that order."""
        i = np.asarray(idx)
        return Observations(self.lon_deg[i], self.lat_deg[i], self.h_m[i],
                            np.asarray(self.col)[i], np.asarray(self.row)[i],
                            self.sigma_xy_m[i], self.sigma_h_m[i], np.asarray(self.frame)[i])

    def with_sigmas(self, sigma_xy_m: ArrayLike, sigma_h_m: ArrayLike) -> Observations:
        return replace(self, sigma_xy_m=np.asarray(sigma_xy_m, dtype=np.float64),
                       sigma_h_m=np.asarray(sigma_h_m, dtype=np.float64))

    def shifted(self, frames: FrameLayout, x: ArrayLike) -> Observations:
        """The GCPs' ground moved by their frames' shifts at frame parameters ``x``."""
        if frames.n == 0:
            return self
        s = frames.shifts_m(x)[np.asarray(self.frame)]
        lon, lat, h = shifted_ground(self.lon_deg, self.lat_deg, self.h_m, s)
        return replace(self, lon_deg=lon, lat_deg=lat, h_m=h)

    @classmethod
    def from_control_points(cls, points: Sequence[ControlPoint], names: Sequence[str],
                            frame: Sequence[int] | None = None) -> Observations:
        """The measurements of ``points`` in the images ``names`` (NaN where a point is not
        measured in an image); ``frame``: each point's frame index (default 0)."""
        col = np.full((len(points), len(names)), np.nan)
        row = np.full_like(col, np.nan)
        for i, p in enumerate(points):
            for j, name in enumerate(names):
                if name in p.image_points:
                    col[i, j], row[i, j] = p.image_points[name].col, p.image_points[name].row

        def arr(attr: str) -> FloatArray:
            return np.array([getattr(p, attr) for p in points], dtype=np.float64)

        return cls(arr("lon_deg"), arr("lat_deg"), arr("h_m"), col, row, arr("sigma_xy_m"),
                   arr("sigma_h_m"), None if frame is None else np.asarray(frame, np.intp))
