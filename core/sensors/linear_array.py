"""Linear-array (CCD line) cameras and lens distortion for the pushbroom model.

A camera maps a detector column to its *normalised focal-plane position* ``(x, y)``: focal-plane
metres divided by the focal length, i.e. the tangents of the look angles. ``x`` is along track
(positive looks forward), ``y`` across track (positive looks right of the track; columns grow
towards -y, to the left, so a descending SPOT pass is not mirrored). The look vector in the camera
frame is ``(x_i, y_i, 1)`` where ``(x_i, y_i)`` is the ideal (undistorted) position::

    r^2 = x^2 + y^2                                   (normalised, from the principal point)
    dx  = x (k1 + k3 r^2) + p1 (r^2 + 2 x^2) + 2 p2 x y
    dy  = y (k1 + k3 r^2) + p2 (r^2 + 2 y^2) + 2 p1 x y
    x_i = (x + dx) / (1 + focal_scale),   y_i = (y + dy) / (1 + focal_scale)

so the radial term is ``dr = k1 r + k3 r^3`` (``k1 r`` is a pure scale, nearly the same thing as
``focal_scale``: do not adjust both), ``p1, p2`` are Brown's decentering terms. All
coefficients are dimensionless because r is normalised.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from core.errors import InputError
from core.sensors._dictio import float_lists, get_float, get_float_arrays, get_int, get_str

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class LensDistortion:
    """Radial ``k1 r + k3 r^3`` and decentering ``p1, p2`` terms on normalised coordinates."""

    k1: float = 0.0
    k3: float = 0.0
    p1: float = 0.0
    p2: float = 0.0

    def to_dict(self) -> dict:
        return {"k1": self.k1, "k3": self.k3, "p1": self.p1, "p2": self.p2}

    @classmethod
    def from_dict(cls, d: object, path: str = "distortion") -> LensDistortion:
        return cls(*(get_float(d, k, path) for k in ("k1", "k3", "p1", "p2")))


def ideal_from_detector(
    x: FloatArray, y: FloatArray, k1: float, k3: float, p1: float, p2: float, focal_scale: float
) -> tuple[FloatArray, FloatArray]:
    """Ideal (pinhole) normalised coordinates of detectors at normalised positions (x, y)."""
    r2 = x * x + y * y
    rad = k1 + k3 * r2
    dx = x * rad + p1 * (r2 + 2 * x * x) + 2 * p2 * x * y
    dy = y * rad + p2 * (r2 + 2 * y * y) + 2 * p1 * x * y
    s = 1.0 + focal_scale
    return (x + dx) / s, (y + dy) / s


def ideal_dxy(
    x: FloatArray, y: FloatArray, k1: float, k3: float, p1: float, p2: float, focal_scale: float
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Partials of the ideal position by the detector position: (dxi/dx, dxi/dy, dyi/dx, dyi/dy)."""
    s = 1.0 + focal_scale
    rad = k1 + k3 * (x * x + y * y)
    cross = 2 * k3 * x * y + 2 * p1 * y + 2 * p2 * x
    return (
        (1 + rad + 2 * k3 * x * x + 6 * p1 * x + 2 * p2 * y) / s,
        cross / s,
        cross / s,
        (1 + rad + 2 * k3 * y * y + 6 * p2 * y + 2 * p1 * x) / s,
    )


def ideal_partials(
    x: FloatArray, y: FloatArray, xi: FloatArray, yi: FloatArray, focal_scale: float
) -> dict[str, tuple[FloatArray, FloatArray]]:
    """d(x_i, y_i)/d(focal_scale, k1, k3, p1, p2) at detector positions (x, y)."""
    s = 1.0 + focal_scale
    r2 = x * x + y * y
    return {
        "focal_scale": (-xi / s, -yi / s),
        "k1": (x / s, y / s),
        "k3": (x * r2 / s, y * r2 / s),
        "p1": ((r2 + 2 * x * x) / s, 2 * x * y / s),
        "p2": (2 * x * y / s, (r2 + 2 * y * y) / s),
    }


@dataclass(frozen=True)
class ParametricCamera:
    """A straight CCD line in the focal plane.

    Detector ``col`` lies at focal-plane metres
    ``x = along_track_offset_m + s sin(rotation_rad)``, ``y = -s cos(rotation_rad)`` with
    ``s = (col - principal_col) * detector_pitch_m``; both are divided by ``focal_length_m``.
    ``principal_col`` (default the middle column) is the column nearest the optical axis across
    track; a positive ``rotation_rad`` (in-plane rotation of the line) makes higher columns look
    further forward; ``along_track_offset_m`` shifts the whole line forward.
    """

    focal_length_m: float
    detector_pitch_m: float
    n_cols: int
    principal_col: float | None = None
    along_track_offset_m: float = 0.0
    rotation_rad: float = 0.0

    def __post_init__(self) -> None:
        if not (self.focal_length_m > 0 and self.detector_pitch_m > 0):
            raise InputError(
                f"camera focal_length_m ({self.focal_length_m}) and detector_pitch_m "
                f"({self.detector_pitch_m}) must be > 0"
            )
        if int(self.n_cols) < 2:
            raise InputError(f"camera n_cols must be >= 2, got {self.n_cols}")
        object.__setattr__(self, "n_cols", int(self.n_cols))
        pc = 0.5 * (self.n_cols - 1) if self.principal_col is None else float(self.principal_col)
        object.__setattr__(self, "principal_col", pc)

    @property
    def ifov_rad(self) -> float:
        """Instantaneous field of view of one detector at the principal point, radians."""
        return self.detector_pitch_m / self.focal_length_m

    def detector_xy(self, col: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Normalised focal-plane position (x, y) of (fractional) columns."""
        s = (np.asarray(col, dtype=np.float64) - self.principal_col) * self.detector_pitch_m
        f = self.focal_length_m
        return (self.along_track_offset_m + s * np.sin(self.rotation_rad)) / f, (
            -s * np.cos(self.rotation_rad) / f
        )

    def detector_xy_dcol(self, col: FloatArray) -> tuple[FloatArray, FloatArray]:
        """d(x, y)/d col (per pixel) of the normalised position."""
        k = self.detector_pitch_m / self.focal_length_m
        one = np.ones(np.shape(col))
        return one * k * np.sin(self.rotation_rad), -one * k * np.cos(self.rotation_rad)

    def cropped(self, col0: float, n_cols: int) -> ParametricCamera:
        """The camera of ``n_cols`` columns whose column 0 is this camera's column ``col0``
        (an image crop): the same detectors, numbered from the crop's first column."""
        return replace(self, n_cols=int(n_cols),
                       principal_col=float(self.principal_col) - float(col0))

    def to_dict(self) -> dict:
        return {
            "type": "parametric",
            "focal_length_m": self.focal_length_m,
            "detector_pitch_m": self.detector_pitch_m,
            "n_cols": self.n_cols,
            "principal_col": self.principal_col,
            "along_track_offset_m": self.along_track_offset_m,
            "rotation_rad": self.rotation_rad,
        }

    @classmethod
    def from_dict(cls, d: object, path: str = "camera") -> ParametricCamera:
        return cls(
            focal_length_m=get_float(d, "focal_length_m", path),
            detector_pitch_m=get_float(d, "detector_pitch_m", path),
            n_cols=get_int(d, "n_cols", path, minimum=2),
            principal_col=get_float(d, "principal_col", path),
            along_track_offset_m=get_float(d, "along_track_offset_m", path),
            rotation_rad=get_float(d, "rotation_rad", path),
        )


@dataclass(frozen=True, eq=False)
class LookAngleTable:
    """Measured look angles per detector (SPOT ``Psi_X``/``Psi_Y`` style), radians.

    ``psi_x_rad[col]`` is the across-track angle, a right-handed rotation about the along-track
    axis (like roll: increasing towards the left of the track, i.e. with the column);
    ``psi_y_rad[col]`` the along-track angle (like pitch: positive forward). The normalised
    position is ``x = tan(psi_y)``, ``y = -tan(psi_x)``, linearly interpolated between columns and
    extrapolated from the end segments.
    """

    psi_x_rad: FloatArray
    psi_y_rad: FloatArray

    def __post_init__(self) -> None:
        px = np.array(self.psi_x_rad, dtype=np.float64)
        py = np.array(self.psi_y_rad, dtype=np.float64)
        if px.ndim != 1 or px.shape != py.shape or px.size < 2:
            raise InputError(
                f"look-angle tables psi_x_rad {px.shape} and psi_y_rad {py.shape} must be 1-D, "
                "of equal length >= 2 (one entry per column)"
            )
        if not (np.all(np.isfinite(px)) and np.all(np.isfinite(py))):
            raise InputError("look-angle tables hold NaN or inf; fix the camera metadata")
        for name, a in (("psi_x_rad", px), ("psi_y_rad", py)):
            a.setflags(write=False)
            object.__setattr__(self, name, a)

    @property
    def n_cols(self) -> int:
        return int(self.psi_x_rad.size)

    @property
    def ifov_rad(self) -> float:
        return float(np.median(np.abs(np.diff(self.psi_x_rad))))

    def _interp(self, a: FloatArray, col: FloatArray) -> tuple[FloatArray, FloatArray]:
        c = np.asarray(col, dtype=np.float64)
        i = np.clip(np.floor(c).astype(np.int64), 0, a.size - 2)
        slope = a[i + 1] - a[i]
        return a[i] + (c - i) * slope, slope

    def detector_xy(self, col: FloatArray) -> tuple[FloatArray, FloatArray]:
        x, _ = self._interp(np.tan(self.psi_y_rad), col)
        y, _ = self._interp(-np.tan(self.psi_x_rad), col)
        return x, y

    def detector_xy_dcol(self, col: FloatArray) -> tuple[FloatArray, FloatArray]:
        _, dx = self._interp(np.tan(self.psi_y_rad), col)
        _, dy = self._interp(-np.tan(self.psi_x_rad), col)
        return dx, dy

    def cropped(self, col0: float, n_cols: int) -> LookAngleTable:
        """The table of ``n_cols`` columns whose column 0 is this table's column ``col0``
        (an image crop; whole columns only: the table interpolates between its columns, so a
        fractional start would move its nodes)."""
        start = int(round(col0))
        if start != col0 or start < 0 or start + int(n_cols) > self.n_cols:
            raise InputError(
                f"a crop of {n_cols} columns from column {col0} does not fit the "
                f"{self.n_cols}-column look-angle table in whole columns; crop on whole pixels "
                "inside the image")
        end = start + int(n_cols)
        return LookAngleTable(self.psi_x_rad[start:end].copy(), self.psi_y_rad[start:end].copy())

    def to_dict(self) -> dict:
        return {
            "type": "table",
            **float_lists(self, "psi_x_rad", "psi_y_rad"),
        }

    @classmethod
    def from_dict(cls, d: object, path: str = "camera") -> LookAngleTable:
        return cls(
            **get_float_arrays(d, path, psi_x_rad=1, psi_y_rad=1),
        )

    @classmethod
    def from_camera(cls, camera: ParametricCamera) -> LookAngleTable:
        """The table of a parametric camera sampled at its integer columns."""
        x, y = camera.detector_xy(np.arange(camera.n_cols, dtype=np.float64))
        return cls(psi_x_rad=np.arctan(-y), psi_y_rad=np.arctan(x))


Camera = ParametricCamera | LookAngleTable


def camera_from_dict(d: object, path: str = "camera") -> Camera:
    """A camera from its dict: ``type`` is ``"parametric"`` or ``"table"``."""
    kind = get_str(d, "type", path)
    if kind == "parametric":
        return ParametricCamera.from_dict(d, path)
    if kind == "table":
        return LookAngleTable.from_dict(d, path)
    raise InputError(
        f"pushbroom model: key '{path}.type' must be 'parametric' or 'table', got {kind!r}"
    )
