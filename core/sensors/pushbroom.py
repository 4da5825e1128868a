"""Rigorous SPOT-type pushbroom (linear-array) sensor model.

A line ``row`` is acquired at ``t0_s + row * line_period_s``. At that time the satellite is at the
interpolated ECEF position of :class:`~core.sensors.orbit.Orbit`, the camera is turned by the
roll/pitch/yaw of :class:`~core.sensors.orbit.Attitude` (polynomials) or
:class:`~core.sensors.orbit.SampledAttitude` (time series, as SPOT metadata give) relative to
the local orbital frame, and detector ``col`` looks along the camera-frame vector ``(x_i, y_i, 1)`` given by
:mod:`core.sensors.linear_array` (camera geometry + lens distortion). Frames and sign
conventions are written out in the docstrings of those two modules.

Adjustable parameters (:data:`PARAM_NAMES`, a selection of which is ``model.adjust``) are
*corrections* added to the delivered model, zero for a model as delivered:

- ``roll_bias, pitch_bias, yaw_bias`` (rad), ``*_rate`` (rad/s), ``*_quad`` (rad/s^2): added to
  the angles as polynomials of ``t - attitude.t_ref_s`` (for polynomial attitude: to the
  coefficients c0, c1, c2), so they apply the same way on top of sampled attitude;
- ``orbit_along_m, orbit_across_m, orbit_radial_m``: a constant position offset along the
  orbital frame axes X, Y and -Z (radial = up) of the delivered orbit (the frame itself is not
  re-rotated);
- ``focal_scale`` (focal length ``f (1 + focal_scale)``); ``k1, k3, p1, p2``: the same
  polynomial as the lens distortion (see :mod:`core.sensors.linear_array`) but about the
  detector line's centre (``correction_centre``, normalised focal-plane x, y; by default the
  middle column's position), added to the delivered distortion: over a line along y they are
  its look-angle scale (``k1``), cubic (``k3``), bow (``p1``, along track, growing with the
  square of the distance to the centre) and across-track quadratic (``p2``), whatever steering
  the look angles carry (SPOT's DIMAP look angles include the mirror's: about the optical
  axis, a cubic of the line takes a scale and a quadratic of hundreds of pixels to cancel).
  A model file without ``correction_centre`` (written before it existed) means (0, 0).

JSON format (``to_json`` / ``from_json``; also what the scene simulator writes)::

    {
      "format": "gcpfree.pushbroom", "version": 1,
      "image": {"n_cols": 6000, "n_rows": 6000},
      "timing": {"t0_s": 115.6, "line_period_s": 0.00148},
      "orbit": {"epoch_utc": "2024-06-01T10:30:00Z",  # times_s are seconds since this
                "times_s": [t, ...], "positions_m": [[x, y, z], ...],
                "velocities_m_s": [[vx, vy, vz], ...]},              # ECEF
      "attitude": {"t_ref_s": 120.0, "roll_rad": [c0, c1, ...],   # polynomials, or
                   "pitch_rad": [c0, ...], "yaw_rad": [c0, ...]},
               # {"type": "sampled", "t_ref_s": 120.0, "times_s": [...], "roll_rad": [...],
               #  "pitch_rad": [...], "yaw_rad": [...]}  (linear interpolation; SPOT metadata)
      "camera": {"type": "parametric", "focal_length_m": 1.08, "detector_pitch_m": 6.5e-6,
                 "n_cols": 6000, "principal_col": 2999.5, "along_track_offset_m": 0.0,
                 "rotation_rad": 0.0}
             or {"type": "table", "psi_x_rad": [...], "psi_y_rad": [...]},  # one per column
      "distortion": {"k1": 0.0, "k3": 0.0, "p1": 0.0, "p2": 0.0},
      "adjust": ["roll_bias", "pitch_bias", "yaw_bias", "roll_rate", "pitch_rate", "yaw_rate"],
      "corrections": {"roll_bias": 0.0, ...}   # optional; names of PARAM_NAMES, absent = 0
    }

Numbers are written with Python's shortest repr, so a round trip is exact. A missing key or a
value of the wrong type raises :class:`~core.errors.InputError` naming the key path.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.dem import GeoDEM
from core.errors import ConvergenceError, GeometryError, InputError
from core.geodesy import geodetic_to_ecef, incidence_angles, intersect_ellipsoid
from core.jsonio import parse_json, to_json
from core.sensors import base
from core.sensors._dictio import get_dict, get_float, get_int, get_str, get_str_tuple
from core.sensors.base import CORRECTION_KINDS
from core.sensors.corrections import (
    ATTITUDE_BIASES,
    ATTITUDE_HARMONICS,
    ATTITUDE_QUADS,
    ATTITUDE_RATES,
    ATTITUDE_TERMS,
    DEFAULT_ADJUST,
    LENS,
    N_HARMONICS,
    ORBIT_OFFSETS,
    ORBIT_TERMS,
    PARAM_NAMES,
    PARAM_UNITS,
    Corrections,
    check_adjust,
    correction_centre_of,
    harmonic_span_of,
)
from core.sensors.linear_array import (
    Camera,
    LensDistortion,
    LookAngleTable,
    ParametricCamera,
    camera_from_dict,
    ideal_dxy,
    ideal_from_detector,
    ideal_partials,
)
from core.sensors.orbit import Attitude, AttitudeModel, Orbit, attitude_from_dict

FloatArray = NDArray[np.float64]

FORMAT = "gcpfree.pushbroom"
_FD_TIME_S = 0.01  # time step of the finite differences in time (the motion is smooth)
_RATE_ITERATIONS = 2  # Newton steps that re-measure the rate; the later ones reuse it (chord)


def _rotation_axes(ang: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Axes (m, 3) of roll, pitch and yaw, in the camera frame, at angles ``ang`` (3, m): a change
    d of angle k turns a camera-frame vector v by ``-axis_k x v d``."""
    cr, sr, cp, sp = np.cos(ang[0]), np.sin(ang[0]), np.cos(ang[1]), np.sin(ang[1])
    zero, one = np.zeros_like(cr), np.ones_like(cr)
    return (np.stack([one, zero, zero], axis=1), np.stack([zero, cr, -sr], axis=1),
            np.stack([-sp, sr * cp, cr * cp], axis=1))


def _flat(*arrays: ArrayLike) -> tuple[tuple[int, ...], list[FloatArray]]:
    b = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in arrays))
    return b[0].shape, [np.ascontiguousarray(a).ravel() for a in b]


@dataclass(frozen=True, eq=False)
class PushbroomModel:
    """Rigorous linear-array model: (col, row) <-> (lon, lat, h); see the module docstring.

    ``n_rows`` lines starting at ``t0_s`` every ``line_period_s`` seconds; the number of columns
    is the camera's. ``adjust`` selects which :data:`PARAM_NAMES` form ``params``;
    ``corrections`` holds the current values of all of them.
    """

    orbit: Orbit
    attitude: AttitudeModel
    camera: Camera
    n_rows: int
    t0_s: float
    line_period_s: float
    distortion: LensDistortion = field(default_factory=LensDistortion)
    adjust: tuple[str, ...] = DEFAULT_ADJUST
    corrections: Corrections = field(default_factory=Corrections)
    correction_centre: tuple[float, float] | None = None
    harmonic_span: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        if int(self.n_rows) < 1:
            raise InputError(f"n_rows must be >= 1, got {self.n_rows}")
        if not (np.isfinite(self.line_period_s) and self.line_period_s > 0):
            raise InputError(f"line_period_s must be > 0 s, got {self.line_period_s}")
        object.__setattr__(self, "n_rows", int(self.n_rows))
        object.__setattr__(self, "t0_s", float(self.t0_s))
        object.__setattr__(self, "line_period_s", float(self.line_period_s))
        object.__setattr__(self, "adjust", check_adjust(self.adjust))
        span = (self.harmonic_span if self.harmonic_span is not None
                else (self.t0_s, self.n_rows * self.line_period_s))
        object.__setattr__(self, "harmonic_span", (float(span[0]), float(span[1])))
        if self.correction_centre is None:  # the line's centre, in normalised focal-plane units
            x0, y0 = self.camera.detector_xy(np.array([0.5 * (self.camera.n_cols - 1)]))
            object.__setattr__(self, "correction_centre", (float(x0[0]), float(y0[0])))
        else:
            object.__setattr__(self, "correction_centre",
                               tuple(float(v) for v in self.correction_centre))

    # -- parameters ---------------------------------------------------------------------------
    @property
    def n_cols(self) -> int:
        return self.camera.n_cols

    @property
    def param_names(self) -> tuple[str, ...]:
        return self.adjust

    @property
    def params(self) -> FloatArray:
        """Current corrections of the adjusted parameters (zeros for the delivered model)."""
        return self.corrections.values(self.adjust)

    def with_params(self, p: ArrayLike) -> PushbroomModel:
        """A new model whose adjusted corrections are ``p`` (values, not increments)."""
        p = np.asarray(p, dtype=np.float64).ravel()
        if p.size != len(self.adjust) or not np.all(np.isfinite(p)):
            raise InputError(
                f"with_params needs {len(self.adjust)} finite values for {self.adjust}, "
                f"got {p.size}"
            )
        new = self.corrections.with_values(dict(zip(self.adjust, map(float, p), strict=True)))
        return replace(self, corrections=new)

    @property
    def param_units(self) -> tuple[str, ...]:
        """Unit of each adjusted parameter (module docstring)."""
        return tuple(PARAM_UNITS[n] for n in self.adjust)

    def with_corrections(self, kind: str) -> PushbroomModel:
        """``"offset"``: the attitude biases; ``"linear"``: biases and rates (corrections kept)."""
        if kind not in CORRECTION_KINDS:
            raise InputError(f"correction kind {kind!r} unknown; use one of {CORRECTION_KINDS}")
        return self.with_adjust(ATTITUDE_BIASES if kind == "offset" else DEFAULT_ADJUST)

    def with_adjust(self, names: tuple[str, ...]) -> PushbroomModel:
        """The same model with another selection of adjustable parameters (corrections kept)."""
        return replace(self, adjust=tuple(names))

    def with_image_window(self, col0: float, row0: float, n_cols: int,
                          n_rows: int) -> PushbroomModel:
        """The same sensor in the pixels of a crop of ``n_cols`` x ``n_rows`` whose pixel
        (0, 0) is this model's pixel (``col0``, ``row0``): ``col_crop = col - col0``,
        ``row_crop = row - row0``. Rows are times, so the crop starts ``row0`` line periods
        later; columns are detectors, numbered from the crop's first one (the camera cropped).
        The crop must lie inside this model's image.
        """
        col0, row0, n_cols, n_rows = float(col0), float(row0), int(n_cols), int(n_rows)
        if not (col0 >= 0 and row0 >= 0 and col0 + n_cols <= self.n_cols
                and row0 + n_rows <= self.n_rows and n_cols >= 2 and n_rows >= 1):
            raise InputError(
                f"a crop of {n_cols}x{n_rows} px at pixel ({col0:g}, {row0:g}) does not fit the "
                f"{self.n_cols}x{self.n_rows} image of this model; give the model of this image")
        return replace(self, camera=self.camera.cropped(col0, n_cols), n_rows=n_rows,
                       t0_s=self.t0_s + row0 * self.line_period_s)

    # -- geometry -------------------------------------------------------------------------------
    def line_time_s(self, row: ArrayLike) -> FloatArray:
        """Acquisition time (s since the orbit epoch) of (fractional) rows."""
        return self.t0_s + np.asarray(row, dtype=np.float64) * self.line_period_s

    def _lens(self) -> tuple[float, float, float, float, float]:
        """The delivered distortion (about the optical axis) and the focal scale."""
        d = self.distortion
        return d.k1, d.k3, d.p1, d.p2, self.corrections.focal_scale

    def _centred(self, x: FloatArray, y: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Focal-plane positions relative to :attr:`correction_centre`."""
        x0, y0 = self.correction_centre  # type: ignore[misc]
        return x - x0, y - y0

    def _with_corrections_terms(self, x: FloatArray, y: FloatArray
                                ) -> tuple[FloatArray, FloatArray]:
        """Ideal coordinates: the delivered distortion about the optical axis plus the
        corrections' ``k1, k3, p1, p2`` about the line's centre (the look-angle scale, cubic,
        bow and quadratic of the line itself, whatever steering its look angles carry)."""
        c = self.corrections
        xi, yi = ideal_from_detector(x, y, *self._lens())
        if c.k1 or c.k3 or c.p1 or c.p2:
            u, w = self._centred(x, y)
            ui, wi = ideal_from_detector(u, w, c.k1, c.k3, c.p1, c.p2, 0.0)
            s = 1.0 + c.focal_scale
            xi, yi = xi + (ui - u) / s, yi + (wi - w) / s
        return xi, yi

    def _ideal(self, col: FloatArray) -> tuple[FloatArray, FloatArray]:
        return self._with_corrections_terms(*self.camera.detector_xy(col))

    def _platform(self, t: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """Position (m, 3), camera->ECEF (m, 3, 3), camera->orbital (m, 3, 3), angles (3, m)."""
        ang = self.attitude_angles(t)
        pos, frame, rot, cam2ecef = self.orbit.platform(t, ang)
        c = self.corrections
        off = np.zeros(3)
        for name, (axis, sign) in ORBIT_TERMS.items():
            off[axis] = sign * getattr(c, name)
        if np.any(off):
            pos = pos + frame @ off
        return pos, cam2ecef, rot, ang

    def _harmonic_term(self, t: FloatArray, derivative: bool = False) -> FloatArray | None:
        """(3, m) the along-track harmonics' angles at times t (``sum_k a_k cos(pi k u)``, u =
        0..1 over ``harmonic_span``), or their time derivative; None when they are all zero
        (no cosine is evaluated: this runs in every projection)."""
        coef = self.corrections.harmonics()
        if not coef.any():
            return None
        t0, span = self.harmonic_span  # type: ignore[misc]
        u = (np.asarray(t, dtype=np.float64) - t0) / span
        k = np.arange(1, N_HARMONICS + 1)[:, None]
        basis = (-np.pi * k / span * np.sin(np.pi * k * u) if derivative
                 else np.cos(np.pi * k * u))
        return coef @ basis

    def attitude_angles(self, t: FloatArray) -> FloatArray:
        """(3, m) roll, pitch, yaw (rad) at times t: the delivered attitude with the
        corrections (polynomial and along-track harmonics)."""
        ang = self.attitude.angles(t, self.corrections.attitude_delta())
        wave = self._harmonic_term(t)
        return ang if wave is None else ang + wave

    def attitude_rates(self, t: FloatArray) -> FloatArray:
        """(3, m) time derivatives of :meth:`attitude_angles`."""
        rates = self.attitude.rates(t, self.corrections.attitude_delta())
        wave = self._harmonic_term(t, derivative=True)
        return rates if wave is None else rates + wave

    def localize_time(
        self, col: ArrayLike, t_s: ArrayLike, h_m: ArrayLike
    ) -> tuple[FloatArray, FloatArray]:
        """Detector ``col`` at time ``t_s`` (s since the orbit epoch) and ellipsoidal height h (m)
        -> ground (lon, lat) degrees: :meth:`localize` for a time instead of a row."""
        shape, (col, t, h) = _flat(col, t_s, h_m)
        lon, lat = self._localize_flat(col, t, h)
        return lon.reshape(shape), lat.reshape(shape)

    def lines_of_sight(self, col: FloatArray, t: FloatArray,
                       line: NDArray[np.intp] | None = None) -> tuple[FloatArray, FloatArray]:
        """The platform's position and each detector's unit line of sight (ECEF) at the times
        ``t`` (``t[line]`` for each of ``col`` when ``line`` is given: the platform computed
        once per image line, as a simulator casting rays through blocks of lines wants)."""
        pos, cam2ecef, _, _ = self._platform(t)
        if line is not None:
            pos, cam2ecef = pos[line], cam2ecef[line]
        xi, yi = self._ideal(col)
        u = np.einsum("mij,mj->mi", cam2ecef, np.stack([xi, yi, np.ones_like(xi)], axis=1))
        return pos, u / np.linalg.norm(u, axis=1, keepdims=True)

    def _localize_flat(self, col: FloatArray, t: FloatArray,
                       h: FloatArray) -> tuple[FloatArray, ...]:
        return intersect_ellipsoid(*self.lines_of_sight(col, t), h)

    def localize(
        self, col: ArrayLike, row: ArrayLike, h_m: ArrayLike
    ) -> tuple[FloatArray, FloatArray]:
        """Image (col, row) at ellipsoidal height h (m) -> ground (lon, lat) degrees, exact at h.

        NaN inputs give NaN; a line of sight that misses the Earth raises GeometryError.
        """
        shape, (c, r, h) = _flat(col, row, h_m)
        lon, lat = self._localize_flat(c, self.line_time_s(r), h)
        return lon.reshape(shape), lat.reshape(shape)

    def localize_on_dem(
        self, col: ArrayLike, row: ArrayLike, dem: GeoDEM, **kwargs: object
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Lines of sight met with a DEM: (lon, lat, h); see
        :func:`core.sensors.base.localize_on_dem`."""
        return base.localize_on_dem(self, col, row, dem, **kwargs)  # type: ignore[arg-type]

    def _observe(self, t: FloatArray, g: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Camera-frame vector to ground points g at times t: (x/z, y/z, z)."""
        pos, cam2ecef, _, _ = self._platform(t)
        v = np.einsum("mji,mj->mi", cam2ecef, g - pos)
        return v[:, 0] / v[:, 2], v[:, 1] / v[:, 2], v[:, 2]

    def _d_observe_dt(self, t: FloatArray, g: FloatArray) -> tuple[FloatArray, FloatArray]:
        """d(x/z, y/z)/dt of the observation: the platform's motion by a central difference
        with the attitude held (orbit and frame are smooth), plus the attitude's own rates
        through the rotation axes (exact for sampled attitude, whose rate jumps at samples)."""
        pos, cam2ecef, rot, ang = self._platform(t)
        v = np.einsum("mji,mj->mi", cam2ecef, g - pos)
        held = []
        for step in (_FD_TIME_S, -_FD_TIME_S):
            p_s, c_s, r_s, _ = self._platform(t + step)
            frame = c_s @ np.swapaxes(r_s, 1, 2)  # the orbital frame at t + step
            w = np.einsum("mji,mj->mi", frame @ rot, g - p_s)
            held.append((w[:, 0] / w[:, 2], w[:, 1] / w[:, 2]))
        dx = (held[0][0] - held[1][0]) / (2 * _FD_TIME_S)
        dy = (held[0][1] - held[1][1]) / (2 * _FD_TIME_S)
        rates = self.attitude_rates(t)
        for axis, rate in zip(_rotation_axes(ang), rates, strict=True):
            dv = -np.cross(axis, v) * rate[:, None]
            dx = dx + (dv[:, 0] * v[:, 2] - v[:, 0] * dv[:, 2]) / v[:, 2] ** 2
            dy = dy + (dv[:, 1] * v[:, 2] - v[:, 1] * dv[:, 2]) / v[:, 2] ** 2
        return dx, dy

    def _ideal_and_dcol(self, col: FloatArray) -> tuple[FloatArray, ...]:
        x, y = self.camera.detector_xy(col)
        xi, yi = self._with_corrections_terms(x, y)
        a, b, c, d = ideal_dxy(x, y, *self._lens())
        k = self.corrections
        if k.k1 or k.k3 or k.p1 or k.p2:
            u, w = self._centred(x, y)
            s = 1.0 + k.focal_scale
            ca, cb, cc, cd = ideal_dxy(u, w, k.k1, k.k3, k.p1, k.p2, 0.0)
            a, b, c, d = a + (ca - 1.0) / s, b + cb / s, c + cc / s, d + (cd - 1.0) / s
        dx, dy = self.camera.detector_xy_dcol(col)
        return xi, yi, a * dx + b * dy, c * dx + d * dy

    def _solve_time_col(
        self, g: FloatArray, tol_px: float, max_iter: int
    ) -> tuple[FloatArray, FloatArray]:
        """Newton on (t, col) so that detector col sees ground points g (m, 3) at time t."""
        m = g.shape[0]
        t = np.full(m, self.t0_s + 0.5 * (self.n_rows - 1) * self.line_period_s)
        c = np.full(m, 0.5 * (self.n_cols - 1))
        todo = np.arange(m)
        rate = np.zeros((m, 2))  # d(observation)/dt, the platform's sweep of the ground
        for it in range(max_iter):
            if todo.size == 0:
                break
            ga, ta, ca = g[todo], t[todo], c[todo]
            ox, oy, vz = self._observe(ta, ga)
            if it < _RATE_ITERATIONS:  # then held: it varies little near the solution
                xp, yp, _ = self._observe(ta + _FD_TIME_S, ga)
                rate[todo] = np.column_stack([(xp - ox) / _FD_TIME_S, (yp - oy) / _FD_TIME_S])
            dox, doy = rate[todo, 0], rate[todo, 1]
            xi, yi, dxi, dyi = self._ideal_and_dcol(ca)
            fx, fy = xi - ox, yi - oy
            det = dxi * doy - dox * dyi
            step_t = (fx * dyi - dxi * fy) / det
            step_c = (doy * fx - dox * fy) / det
            t[todo] = ta - step_t
            c[todo] = ca - step_c
            done = (np.abs(step_c) <= tol_px) & (np.abs(step_t) <= tol_px * self.line_period_s)
            if np.any(done & (vz <= 0)):
                raise GeometryError(
                    f"{int(np.sum(done & (vz <= 0)))} ground points lie behind the camera; "
                    "they cannot be projected into this image"
                )
            todo = todo[~(done | ~np.isfinite(step_c))]
        if todo.size:
            raise ConvergenceError(
                f"project did not converge to {tol_px} px for {todo.size} of {m} points in "
                f"{max_iter} iterations; check that the points are near the scene and finite"
            )
        return t, c

    def project(
        self,
        lon_deg: ArrayLike,
        lat_deg: ArrayLike,
        h_m: ArrayLike,
        *,
        tol_px: float = 1e-8,
        max_iter: int = 30,
    ) -> tuple[FloatArray, FloatArray]:
        """Ground (lon, lat degrees, h metres) -> image (col, row) pixels.

        Solves jointly, by vectorised Newton, for the acquisition time (the point lies in the
        instantaneous plane of the detector line) and the column (distortion and CCD rotation
        included). NaN inputs (DEM voids) give NaN; a finite point that does not converge to
        ``tol_px`` in ``max_iter`` iterations raises ConvergenceError.
        """
        shape, (lon, lat, h) = _flat(lon_deg, lat_deg, h_m)
        ok = np.isfinite(lon) & np.isfinite(lat) & np.isfinite(h)
        col, row = np.full(lon.shape, np.nan), np.full(lon.shape, np.nan)
        g = np.stack(geodetic_to_ecef(lon[ok], lat[ok], h[ok]), axis=1)
        t, col[ok] = self._solve_time_col(g, tol_px, max_iter)
        row[ok] = (t - self.t0_s) / self.line_period_s
        return col.reshape(shape), row.reshape(shape)

    def viewing_geometry(
        self, col: ArrayLike, row: ArrayLike, h_m: ArrayLike
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """(incidence_deg, across_track_incidence_deg, slant_range_m) at image points.

        Incidence is the angle at the ground between the local vertical and the direction to the
        satellite; the across-track one is measured in the vertical plane across the ground track
        and is positive when the satellite is west of the point (the view looks east).
        """
        shape, (c, r, h) = _flat(col, row, h_m)
        t = self.line_time_s(r)
        lon, lat = self._localize_flat(c, t, h)
        g = np.stack(geodetic_to_ecef(lon, lat, h), axis=1)
        pos, vel = self.orbit.interpolate(t)
        inc, across, rng = incidence_angles(pos, self.orbit.ground_velocity(pos, vel), g, lon, lat)
        return np.degrees(inc).reshape(shape), np.degrees(across).reshape(shape), rng.reshape(shape)

    # -- Jacobians ----------------------------------------------------------------------------
    def jacobian(
        self,
        lon_deg: ArrayLike,
        lat_deg: ArrayLike,
        h_m: ArrayLike,
        *,
        method: Literal["analytic", "numeric"] = "analytic",
    ) -> FloatArray:
        """d(col, row)/d(params) at ground points: shape (n, 2, len(adjust)), pixels per unit.

        ``analytic`` differentiates the collinearity condition in closed form for every
        parameter and solves the implicit-function system (only d/dt of the motion uses a
        central difference); ``numeric`` takes 4th-order central differences of ``project``.
        """
        _, (lon, lat, h) = _flat(lon_deg, lat_deg, h_m)
        if method == "numeric":
            return base.numeric_jacobian(self, lon, lat, h, self.numeric_steps())
        if method != "analytic":
            raise InputError(f"jacobian method must be 'analytic' or 'numeric', got {method!r}")
        g = np.stack(geodetic_to_ecef(lon, lat, h), axis=1)
        t, col = self._solve_time_col(g, 1e-8, 30)
        return self._jacobian_analytic(g, t, col)

    def _jacobian_analytic(self, g: FloatArray, t: FloatArray, col: FloatArray) -> FloatArray:
        pos, cam2ecef, rot, ang = self._platform(t)
        v = np.einsum("mji,mj->mi", cam2ecef, g - pos)
        dox, doy = self._d_observe_dt(t, g)
        xd, yd = self._centred(*self.camera.detector_xy(col))
        xi, yi, dxi, dyi = self._ideal_and_dcol(col)
        axes = _rotation_axes(ang)
        lens = ideal_partials(xd, yd, xi, yi, self.corrections.focal_scale)
        dt_ref = t - self.attitude.t_ref_s
        fp = np.empty((t.size, 2, len(self.adjust)))
        for k, name in enumerate(self.adjust):
            if name in lens:
                fp[:, 0, k], fp[:, 1, k] = lens[name]
                continue
            if name in ORBIT_TERMS:  # the camera moves by the offset: v changes by -R^T off
                axis, sign = ORBIT_TERMS[name]
                dv = -sign * rot[:, axis, :]
            elif name in ATTITUDE_HARMONICS:
                axis, kk = ATTITUDE_HARMONICS[name]
                t0, span = self.harmonic_span  # type: ignore[misc]
                dv = -np.cross(axes[axis], v) * np.cos(np.pi * kk * (t - t0) / span)[:, None]
            else:
                axis, power = ATTITUDE_TERMS[name]
                dv = -np.cross(axes[axis], v) * (dt_ref ** power)[:, None]
            fp[:, 0, k] = -(dv[:, 0] * v[:, 2] - v[:, 0] * dv[:, 2]) / v[:, 2] ** 2
            fp[:, 1, k] = -(dv[:, 1] * v[:, 2] - v[:, 1] * dv[:, 2]) / v[:, 2] ** 2
        # F = ideal(col) - observed(t) = 0  =>  [dF/dt dF/dcol] d(t, col) = -dF/dp
        a, b, c, d = -dox, dxi, -doy, dyi
        det = (a * d - b * c)[:, None]
        d_t = -(d[:, None] * fp[:, 0] - b[:, None] * fp[:, 1]) / det
        d_col = -(a[:, None] * fp[:, 1] - c[:, None] * fp[:, 0]) / det
        return np.stack([d_col, d_t / self.line_period_s], axis=1)

    def numeric_steps(self) -> FloatArray:
        """Finite-difference steps of the adjusted parameters (each moves ~1 px at most)."""
        ifov = self.camera.ifov_rad
        half_s = max(0.5 * self.n_rows * self.line_period_s, 1.0)
        x, y = self._centred(*self.camera.detector_xy(np.array([0.0, self.n_cols - 1.0])))
        r = max(float(np.max(np.hypot(x, y))), 1e-4)
        by_power = (ifov, ifov / half_s, ifov / half_s**2)
        lens = {"focal_scale": ifov / r, "k1": ifov / r, "k3": ifov / r**3,
                "p1": ifov / r**2, "p2": ifov / r**2}
        out = []
        for name in self.adjust:
            if name in lens:
                out.append(lens[name])
            elif name in ORBIT_TERMS:
                out.append(ifov * 5e5)  # ~0.5 px at a typical range
            elif name in ATTITUDE_HARMONICS:
                out.append(ifov)
            else:
                out.append(by_power[ATTITUDE_TERMS[name][1]])
        return np.array(out)

    # -- serialisation ------------------------------------------------------------------------
    def to_dict(self) -> dict:
        """The whole model as a JSON-ready dict (format in the module docstring)."""
        return {
            "format": FORMAT,
            "version": 1,
            "image": {"n_cols": self.n_cols, "n_rows": self.n_rows},
            "timing": {"t0_s": self.t0_s, "line_period_s": self.line_period_s},
            "orbit": self.orbit.to_dict(),
            "attitude": self.attitude.to_dict(),
            "camera": self.camera.to_dict(),
            "distortion": self.distortion.to_dict(),
            "adjust": list(self.adjust),
            "corrections": {n: self.corrections.value(n) for n in PARAM_NAMES
                            if n not in ATTITUDE_HARMONICS or self.corrections.value(n)},
            "correction_centre": list(self.correction_centre),  # type: ignore[arg-type]
            "harmonic_span_s": list(self.harmonic_span),  # type: ignore[arg-type]
        }

    @classmethod
    def from_dict(cls, d: object) -> PushbroomModel:
        """Read a model dict; InputError names any missing or mistyped key."""
        fmt = get_str(d, "format", "")
        if fmt != FORMAT:
            raise InputError(f"key 'format' is {fmt!r}, not {FORMAT!r}: not a pushbroom model")
        camera = camera_from_dict(get_dict(d, "camera"))
        n_cols = get_int(get_dict(d, "image"), "n_cols", "image")
        if n_cols != camera.n_cols:
            raise InputError(
                f"key 'image.n_cols' ({n_cols}) differs from the camera's {camera.n_cols} columns"
            )
        corr = d.get("corrections", {})  # type: ignore[union-attr]
        if not isinstance(corr, dict) or any(k not in PARAM_NAMES for k in corr):
            raise InputError(
                f"key 'corrections' must map names among {PARAM_NAMES} to numbers, got {corr!r:.80}"
            )
        timing = get_dict(d, "timing")
        return cls(
            orbit=Orbit.from_dict(get_dict(d, "orbit")),
            attitude=attitude_from_dict(get_dict(d, "attitude")),
            camera=camera,
            n_rows=get_int(get_dict(d, "image"), "n_rows", "image"),
            t0_s=get_float(timing, "t0_s", "timing"),
            line_period_s=get_float(timing, "line_period_s", "timing"),
            distortion=LensDistortion.from_dict(get_dict(d, "distortion")),
            adjust=get_str_tuple(d, "adjust", ""),
            corrections=Corrections.from_values(
                {k: get_float(corr, k, "corrections") for k in corr}),
            # files written before the key existed put the lens corrections about the axis
            correction_centre=correction_centre_of(d),
            harmonic_span=harmonic_span_of(d),
        )

    def to_json(self, indent: int | None = None) -> str:
        return to_json(self.to_dict(), indent=indent)

    @classmethod
    def from_json(cls, text: str) -> PushbroomModel:
        return cls.from_dict(parse_json(text, "pushbroom model JSON"))


__all__ = [
    "ATTITUDE_BIASES", "ATTITUDE_HARMONICS", "ATTITUDE_QUADS", "ATTITUDE_RATES", "DEFAULT_ADJUST",
    "LENS", "ORBIT_OFFSETS", "PARAM_NAMES", "Attitude", "Corrections", "LensDistortion",
    "LookAngleTable", "Orbit", "ParametricCamera", "PushbroomModel",
]
