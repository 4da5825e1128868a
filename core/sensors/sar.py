"""Zero-Doppler range-Doppler geometry of a SAR image (Sentinel-1 stripmap SLC, TOPS SLC, GRD).

A ground point P (ECEF) is imaged at the azimuth time t where the sensor S(t), moving with the
Earth-relative velocity V(t), sees it at zero Doppler: ``(P - S(t)) . V(t) = 0`` (solved by
Newton, vectorised over points), and at the two-way slant-range time ``tau = 2 |P - S(t)| / c``.
The orbit is the delivered ECEF state vectors interpolated by 8-point Lagrange polynomials
(:class:`core.sensors.orbit.Orbit`). Image coordinates from (t, tau), 0-based, pixel centres at
integers:

- stripmap SLC: ``row = (t - t0) / dt``, ``col = (tau - tau0) fs``;
- GRD: ``row = (t - t0) / dt``, ``col = gr / rangePixelSpacing`` with the ground range
  ``gr = sum_i c_i (sr - sr0)^i`` of the slant range ``sr = c tau / 2``, from the
  slant-to-ground-range record *nearest in azimuth time* (the coefficients do not interpolate
  linearly: interpolating them costs up to 1.5 px); its inverse by Newton on that polynomial;
- TOPS SLC: bursts of ``lines_per_burst`` lines stacked, burst k starting at its own azimuth
  time t_k: ``row = k lines_per_burst + (t - t_k) / dt``. Consecutive bursts overlap in time:
  a point in an overlap has a line in both; :meth:`SarModel.project` returns the one in the
  burst whose centre time is nearest (the point farthest from a burst edge).

Correctable parameters (what SAR products really get wrong): an azimuth-time offset
``azimuth_offset_s`` and a range delay ``range_delay_s`` (two-way, seconds), added to the
modelled times: ``t_image = t_zero_doppler + azimuth_offset_s``,
``tau_image = 2 |P - S| / c + range_delay_s``.

A model may describe a crop of the product (:meth:`SarModel.with_image_window`): ``col0_px``,
``row0_px`` are the product pixel of the crop's pixel (0, 0), ``n_cols``/``n_rows`` the crop's
size; the formulas above give product pixels, from which the offsets are subtracted.

Times are seconds since ``orbit.epoch_utc``. Heights ellipsoidal WGS84, lon/lat degrees.

JSON format (:meth:`SarModel.to_dict` / :meth:`SarModel.from_dict`; ``load_model`` recognises
it by its ``format``)::

    {
      "format": "gcpfree.sar", "version": 1,
      "kind": "slc" | "grd" | "tops", "look_side": "right", "mission": "S1B", "mode": "IW",
      "image": {"n_cols": 25788, "n_rows": 16685, "col0_px": 0.0, "row0_px": 0.0},
      "timing": {"first_line_time_s": 38.2, "line_interval_s": 0.00206,
                 "slant_range_time_s": 0.00533, "range_sampling_rate_hz": 64345238.1,
                 "range_pixel_spacing_m": 10.0},
      "orbit": {"epoch_utc": "...Z", "times_s": [...], "positions_m": [[x, y, z], ...],
                "velocities_m_s": [[vx, vy, vz], ...]},                         # ECEF
      "grd": {"srgr_times_s": [...], "srgr_sr0_m": [...], "srgr_coeffs": [[c0, c1, ...], ...]},
      "tops": {"burst_times_s": [...], "lines_per_burst": 1500},
      "corrections": {"azimuth_offset_s": 0.0, "range_delay_s": 0.0}
    }

``grd`` only for kind ``grd``, ``tops`` only for kind ``tops``; ``corrections`` optional
(absent = 0). Numbers are written with Python's shortest repr, so a round trip is exact.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.errors import ConvergenceError, InputError
from core.geodesy import (
    WGS84_A_M,
    WGS84_B_M,
    ecef_to_geodetic,
    geodetic_to_ecef,
    intersect_ellipsoid,
)
from core.jsonio import parse_json, to_json
from core.sensors._dictio import (
    float_lists,
    get_dict,
    get_float,
    get_float_array,
    get_float_arrays,
    get_int,
    get_str,
)
from core.sensors.orbit import Orbit

FloatArray = NDArray[np.float64]

SPEED_OF_LIGHT_M_S = 299792458.0
SAR_KINDS = ("slc", "grd", "tops")
LOOK_SIDES = ("right", "left")
PARAM_NAMES = ("azimuth_offset_s", "range_delay_s")
FORMAT = "gcpfree.sar"


def _ro(a: ArrayLike, ndim: int) -> FloatArray:
    out = np.array(a, dtype=np.float64, ndmin=ndim)
    out.setflags(write=False)
    return out


def _flat(*arrays: ArrayLike) -> tuple[tuple[int, ...], list[FloatArray]]:
    b = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in arrays))
    return b[0].shape, [np.ravel(x) for x in b]


@dataclass(frozen=True, eq=False)
class SarModel:
    """A zero-Doppler SAR sensor model; see the module docstring for the equations.

    ``kind`` one of :data:`SAR_KINDS`; ``n_cols``/``n_rows`` the image size; ``first_line_time_s``
    t0 and ``line_interval_s`` dt; ``slant_range_time_s`` tau0 (two-way, first pixel) and
    ``range_sampling_rate_hz`` fs; GRD: ``range_pixel_spacing_m`` and the slant-to-ground
    records ``srgr_times_s`` (m,), ``srgr_sr0_m`` (m,), ``srgr_coeffs`` (m, k) (ground range in
    metres of slant range minus sr0, coefficient of power 0 first); TOPS: ``burst_times_s`` (nb,)
    and ``lines_per_burst``. ``look_side`` ``"right"`` (Sentinel-1) or ``"left"``.
    ``col0_px``/``row0_px`` the product pixel of this image's pixel (0, 0) (non-zero for a
    crop, :meth:`with_image_window`; the times above stay the product's).
    """

    orbit: Orbit
    kind: str
    n_cols: int
    n_rows: int
    first_line_time_s: float
    line_interval_s: float
    slant_range_time_s: float
    range_sampling_rate_hz: float
    range_pixel_spacing_m: float = 0.0
    srgr_times_s: FloatArray = field(default_factory=lambda: np.zeros(0))
    srgr_sr0_m: FloatArray = field(default_factory=lambda: np.zeros(0))
    srgr_coeffs: FloatArray = field(default_factory=lambda: np.zeros((0, 1)))
    burst_times_s: FloatArray = field(default_factory=lambda: np.zeros(0))
    lines_per_burst: int = 0
    look_side: str = "right"
    azimuth_offset_s: float = 0.0
    range_delay_s: float = 0.0
    mission: str = ""
    mode: str = ""
    col0_px: float = 0.0
    row0_px: float = 0.0

    def __post_init__(self) -> None:
        if self.kind not in SAR_KINDS:
            raise InputError(f"SAR kind {self.kind!r} unknown; use one of {SAR_KINDS}")
        if self.look_side not in LOOK_SIDES:
            raise InputError(f"SAR look side {self.look_side!r} unknown; use one of {LOOK_SIDES}")
        if not (self.line_interval_s > 0 and self.range_sampling_rate_hz > 0):
            raise InputError("SAR azimuth time interval and range sampling rate must be > 0")
        if self.n_cols < 1 or self.n_rows < 1:
            raise InputError(f"SAR image size {self.n_cols}x{self.n_rows} must be positive")
        object.__setattr__(self, "srgr_times_s", _ro(self.srgr_times_s, 1))
        object.__setattr__(self, "srgr_sr0_m", _ro(self.srgr_sr0_m, 1))
        object.__setattr__(self, "srgr_coeffs", _ro(self.srgr_coeffs, 2))
        object.__setattr__(self, "burst_times_s", _ro(self.burst_times_s, 1))
        if self.kind == "grd":
            m = self.srgr_times_s.size
            if m == 0 or self.srgr_sr0_m.shape != (m,) or self.srgr_coeffs.shape[0] != m:
                raise InputError("a GRD model needs slant-to-ground-range records (times, sr0, "
                                 "coefficients), one per time; the annotation lacks them")
            if not self.range_pixel_spacing_m > 0:
                raise InputError("a GRD model needs a positive range pixel spacing")
        if self.kind == "tops" and (self.burst_times_s.size == 0 or self.lines_per_burst < 1):
            raise InputError("a TOPS SLC model needs its burst list and lines per burst")
        if not (np.isfinite(self.col0_px) and np.isfinite(self.row0_px)):
            raise InputError("a SAR model's crop offset (col0_px, row0_px) must be finite")

    def with_image_window(self, col0: float, row0: float, n_cols: int, n_rows: int) -> SarModel:
        """The same model in the pixels of a crop of ``n_cols`` x ``n_rows`` whose pixel (0, 0)
        is this model's pixel (``col0``, ``row0``): ``col_crop = col - col0``,
        ``row_crop = row - row0`` (exact for every kind: the product's timing, range and bursts
        are kept, the offset applied after them). The crop must lie inside this image."""
        col0, row0, n_cols, n_rows = float(col0), float(row0), int(n_cols), int(n_rows)
        if not (col0 >= 0 and row0 >= 0 and col0 + n_cols <= self.n_cols
                and row0 + n_rows <= self.n_rows and n_cols >= 1 and n_rows >= 1):
            raise InputError(
                f"a crop of {n_cols}x{n_rows} px at pixel ({col0:g}, {row0:g}) does not fit the "
                f"{self.n_cols}x{self.n_rows} image of this SAR model; give the model of this "
                "image")
        return replace(self, n_cols=n_cols, n_rows=n_rows, col0_px=self.col0_px + col0,
                       row0_px=self.row0_px + row0)

    # ------------------------------------------------------------------ protocol: parameters

    @property
    def param_names(self) -> tuple[str, ...]:
        return PARAM_NAMES

    @property
    def param_units(self) -> tuple[str, ...]:
        return ("s", "s")

    @property
    def params(self) -> FloatArray:
        return np.array([self.azimuth_offset_s, self.range_delay_s])

    def with_params(self, p: ArrayLike) -> SarModel:
        p = np.asarray(p, dtype=np.float64).ravel()
        if p.shape != (2,) or not np.all(np.isfinite(p)):
            raise InputError(f"a SAR model has 2 finite parameters {PARAM_NAMES}, got {p.tolist()}")
        return replace(self, azimuth_offset_s=float(p[0]), range_delay_s=float(p[1]))

    def with_corrections(self, kind: str) -> SarModel:
        """Both kinds are the same two offsets for SAR (its errors are a timing and a delay)."""
        if kind not in ("offset", "linear"):
            raise InputError(f"correction kind {kind!r} unknown; use 'offset' or 'linear'")
        return self

    # ------------------------------------------------------------------ orbit and times

    def _state(self, t: FloatArray) -> tuple[FloatArray, FloatArray]:
        pos, vel = self.orbit.interpolate(t)
        return pos, self.orbit.ground_velocity(pos, vel)

    def zero_doppler(self, ground_ecef: FloatArray, *, tol_s: float = 1e-9,
                     max_iter: int = 30) -> tuple[FloatArray, FloatArray]:
        """Zero-Doppler time t (s since the epoch, no offset) and slant range |P - S(t)| (m) of
        ECEF points (n, 3): Newton on ``f(t) = (P - S(t)) . V(t)``,
        ``f'(t) = -|V|^2 + (P - S) . A`` (A from the interpolated velocities)."""
        g = np.atleast_2d(ground_ecef)
        t = np.full(g.shape[0], self._mid_time_s())
        for _ in range(max_iter):
            s, v = self._state(t)
            _, v2 = self._state(t + 1e-3)
            acc = (v2 - v) / 1e-3
            d = g - s
            step = np.sum(d * v, axis=1) / (np.sum(v * v, axis=1) - np.sum(d * acc, axis=1))
            t = t + step
            if not np.any(np.abs(step) > tol_s):
                s, _ = self._state(t)
                return t, np.linalg.norm(g - s, axis=1)
        raise ConvergenceError(f"zero-Doppler time did not converge to {tol_s} s in {max_iter} "
                               "iterations; the points are probably far outside the orbit span")

    def _mid_time_s(self) -> float:
        """Azimuth time (s) of this image's middle row: the zero-Doppler start."""
        if self.kind == "tops":
            t, _ = self.times_of_image(0.5 * (self.n_cols - 1), 0.5 * (self.n_rows - 1))
            return float(t)
        return self.first_line_time_s + (self.row0_px + 0.5 * self.n_rows) * self.line_interval_s

    def times(self, lon_deg: ArrayLike, lat_deg: ArrayLike, h_m: ArrayLike
              ) -> tuple[FloatArray, FloatArray]:
        """Image azimuth time (s since the epoch) and two-way slant-range time (s) of ground
        points, the corrections included."""
        shape, (lon, lat, h) = _flat(lon_deg, lat_deg, h_m)
        g = np.stack(geodetic_to_ecef(lon, lat, h), axis=1)
        t, r = self.zero_doppler(g)
        t_img = t + self.azimuth_offset_s
        tau = 2.0 * r / SPEED_OF_LIGHT_M_S + self.range_delay_s
        return t_img.reshape(shape), tau.reshape(shape)

    # ------------------------------------------------------------------ image coordinates

    def _srgr_record(self, t_img: FloatArray) -> NDArray[np.intp]:
        """Index of the slant-to-ground record nearest in time to each azimuth time."""
        tt = self.srgr_times_s
        k = np.clip(np.searchsorted(tt, t_img), 1, max(tt.size - 1, 1))
        if tt.size == 1:
            return np.zeros(t_img.shape, dtype=np.intp)
        return np.where(np.abs(t_img - tt[k - 1]) <= np.abs(tt[k] - t_img), k - 1, k)

    def _ground_range(self, sr: FloatArray, k: NDArray[np.intp]) -> tuple[FloatArray, FloatArray]:
        """Ground range (m) and d(ground range)/d(slant range) of slant ranges with records k."""
        c = self.srgr_coeffs[k]
        x = sr - self.srgr_sr0_m[k]
        gr = np.zeros_like(x)
        dgr = np.zeros_like(x)
        for i in range(c.shape[1] - 1, -1, -1):  # Horner, value and derivative
            dgr = dgr * x + gr
            gr = gr * x + c[:, i]
        return gr, dgr

    def _slant_range_of_ground(self, gr: FloatArray, k: NDArray[np.intp]) -> FloatArray:
        """Inverse of :meth:`_ground_range` by Newton (start: a linear guess)."""
        sr = self.srgr_sr0_m[k] + (gr - self.srgr_coeffs[k, 0]) / self.srgr_coeffs[k, 1]
        for _ in range(30):
            g, dg = self._ground_range(sr, k)
            step = (g - gr) / dg
            sr = sr - step
            if not np.any(np.abs(step) > 1e-7):
                return sr
        raise ConvergenceError("the slant-to-ground-range polynomial did not invert; check the "
                               "annotation's srgr coefficients")

    def _burst_of_time(self, t_img: FloatArray) -> NDArray[np.intp]:
        centres = self.burst_times_s + 0.5 * (self.lines_per_burst - 1) * self.line_interval_s
        return np.argmin(np.abs(t_img[:, None] - centres[None, :]), axis=1)

    def image_of_times(self, t_img: ArrayLike, tau: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """(col, row) of image azimuth times and two-way slant-range times."""
        shape, (t, tau) = _flat(t_img, tau)
        if self.kind == "tops":
            k = self._burst_of_time(t)
            row = k * self.lines_per_burst + (t - self.burst_times_s[k]) / self.line_interval_s
        else:
            row = (t - self.first_line_time_s) / self.line_interval_s
        if self.kind == "grd":
            gr, _ = self._ground_range(0.5 * SPEED_OF_LIGHT_M_S * tau, self._srgr_record(t))
            col = gr / self.range_pixel_spacing_m
        else:
            col = (tau - self.slant_range_time_s) * self.range_sampling_rate_hz
        col, row = col - self.col0_px, row - self.row0_px
        return col.reshape(shape), row.reshape(shape)

    def times_of_image(self, col: ArrayLike, row: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Image azimuth time (s since the epoch) and two-way slant-range time of (col, row)."""
        shape, (col, row) = _flat(col, row)
        col, row = col + self.col0_px, row + self.row0_px
        if self.kind == "tops":
            k = np.clip(np.floor(row / self.lines_per_burst), 0,
                        self.burst_times_s.size - 1).astype(np.intp)
            t = self.burst_times_s[k] + (row - k * self.lines_per_burst) * self.line_interval_s
        else:
            t = self.first_line_time_s + row * self.line_interval_s
        if self.kind == "grd":
            sr = self._slant_range_of_ground(col * self.range_pixel_spacing_m,
                                             self._srgr_record(t))
            tau = 2.0 * sr / SPEED_OF_LIGHT_M_S
        else:
            tau = self.slant_range_time_s + col / self.range_sampling_rate_hz
        return t.reshape(shape), tau.reshape(shape)

    def project(self, lon_deg: ArrayLike, lat_deg: ArrayLike, h_m: ArrayLike
                ) -> tuple[FloatArray, FloatArray]:
        """Ground (lon, lat, h) -> image (col, row)."""
        return self.image_of_times(*self.times(lon_deg, lat_deg, h_m))

    def localize(self, col: ArrayLike, row: ArrayLike, h_m: ArrayLike
                 ) -> tuple[FloatArray, FloatArray]:
        """Image (col, row) at ellipsoidal height h -> ground (lon, lat): the point on the
        ellipsoid raised by h, in the zero-Doppler plane of the sensor at the row's time, at
        the column's slant range, on the look side."""
        shape, (col, row, h) = _flat(col, row, h_m)
        t_img, tau = self.times_of_image(col, row)
        r = 0.5 * SPEED_OF_LIGHT_M_S * (tau - self.range_delay_s)
        s, v = self._state(t_img - self.azimuth_offset_s)
        lon, lat = self._range_sphere_on_height(s, v, r, h)
        return lon.reshape(shape), lat.reshape(shape)

    def _range_sphere_on_height(self, s: FloatArray, v: FloatArray, r: FloatArray,
                                h: FloatArray, *, tol_m: float = 1e-5) -> tuple[FloatArray, ...]:
        """Where the range sphere |P - S| = r, the zero-Doppler plane (P - S).V = 0 and the
        ellipsoid raised by h meet: a look angle in the plane found by Newton on the range of
        the ray's intersection with the raised ellipsoid."""
        vhat = v / np.linalg.norm(v, axis=1, keepdims=True)
        down = -s + np.sum(s * vhat, axis=1, keepdims=True) * vhat
        down /= np.linalg.norm(down, axis=1, keepdims=True)
        side = np.cross(down, vhat) * (1.0 if self.look_side == "right" else -1.0)
        rs = np.linalg.norm(s, axis=1)
        # spherical start: Earth radius under the sensor (geocentric) plus h
        lat_c = np.arcsin(s[:, 2] / rs)
        re = np.hypot(WGS84_A_M**2 * np.cos(lat_c), WGS84_B_M**2 * np.sin(lat_c)) / np.hypot(
            WGS84_A_M * np.cos(lat_c), WGS84_B_M * np.sin(lat_c)) + h
        cos_look = np.clip((rs**2 + r**2 - re**2) / (2.0 * rs * r), -1.0, 1.0)
        look = np.arccos(cos_look)

        def ground(a: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
            u = np.cos(a)[:, None] * down + np.sin(a)[:, None] * side
            lon, lat = intersect_ellipsoid(s, u, h)
            p = np.stack(geodetic_to_ecef(lon, lat, h), axis=1)
            return lon, lat, np.linalg.norm(p - s, axis=1)

        da = 1e-7
        for _ in range(20):
            lon, lat, rng = ground(look)
            err = rng - r
            if not np.any(np.abs(err) > tol_m):
                return lon, lat
            _, _, rng2 = ground(look + da)
            look = look - err * da / (rng2 - rng)
        raise ConvergenceError("the range sphere does not meet the raised ellipsoid in the "
                               "zero-Doppler plane; check the pixel, the height and the orbit")

    def localize_ecef(self, col: ArrayLike, row: ArrayLike, h_m: ArrayLike) -> FloatArray:
        """:meth:`localize` as ECEF points (n, 3)."""
        lon, lat = self.localize(col, row, h_m)
        _, (lon, lat, h) = _flat(lon, lat, h_m)
        return np.stack(geodetic_to_ecef(lon, lat, h), axis=1)

    # ------------------------------------------------------------------ derivatives

    def jacobian(self, lon_deg: ArrayLike, lat_deg: ArrayLike, h_m: ArrayLike) -> FloatArray:
        """d(col, row)/d(azimuth_offset_s, range_delay_s), shape (n, 2, 2), pixels per second.

        row moves 1/dt per second of azimuth offset; col moves fs (SLC) or
        (c / 2) d(gr)/d(sr) / spacing (GRD) per second of range delay. (The GRD record chosen
        by time makes col depend on the azimuth offset only across record boundaries: 0.)
        """
        _, (lon, lat, h) = _flat(lon_deg, lat_deg, h_m)
        out = np.zeros((lon.size, 2, 2))
        out[:, 1, 0] = 1.0 / self.line_interval_s
        if self.kind == "grd":
            t, tau = self.times(lon, lat, h)
            _, dgr = self._ground_range(0.5 * SPEED_OF_LIGHT_M_S * tau, self._srgr_record(t))
            out[:, 0, 1] = 0.5 * SPEED_OF_LIGHT_M_S * dgr / self.range_pixel_spacing_m
        else:
            out[:, 0, 1] = self.range_sampling_rate_hz
        return out

    def line_of_sight_ecef(self, col: ArrayLike, row: ArrayLike, h_m: ArrayLike) -> FloatArray:
        """Unit vectors (n, 3) from the ground points of (col, row, h) to the sensor at their
        zero-Doppler time: the radar's line of sight (incidence, azimuth). A SAR point raised in
        height moves along its range circle, not along this line."""
        g = self.localize_ecef(col, row, h_m)
        t, _ = self.zero_doppler(g)
        s, _ = self._state(t)
        d = s - g
        return d / np.linalg.norm(d, axis=1, keepdims=True)

    def utc_of_times(self, t_s: ArrayLike) -> list[str]:
        """ISO 8601 UTC strings (microseconds, ``Z``) of times in seconds since the epoch."""
        epoch = np.datetime64(self.orbit.epoch_utc.rstrip("Z"), "ns")
        ns = np.round(np.ravel(np.asarray(t_s, dtype=np.float64)) * 1e9).astype(np.int64)
        return [str(np.datetime64(epoch + np.timedelta64(int(k), "ns"), "us")) + "Z" for k in ns]

    def along_track_speed_m_s(self, t_s: ArrayLike) -> FloatArray:
        """Speed of the zero-Doppler footprint on the ground (m/s): the sensor's Earth-relative
        speed scaled to the Earth's surface under it (turns an azimuth time error into metres)."""
        s, v = self._state(np.atleast_1d(np.asarray(t_s, dtype=np.float64)))
        lon, lat, hs = ecef_to_geodetic(s[:, 0], s[:, 1], s[:, 2])
        rs = np.linalg.norm(s, axis=1)
        return np.linalg.norm(v, axis=1) * (rs - hs) / rs

    # ------------------------------------------------------------------ serialisation

    def to_dict(self) -> dict:
        """The whole model, corrections and crop included, as a JSON-ready dict (format in the
        module docstring)."""
        d: dict = {
            "format": FORMAT, "version": 1, "kind": self.kind, "look_side": self.look_side,
            "mission": self.mission, "mode": self.mode,
            "image": {"n_cols": self.n_cols, "n_rows": self.n_rows,
                      "col0_px": float(self.col0_px), "row0_px": float(self.row0_px)},
            "timing": {"first_line_time_s": float(self.first_line_time_s),
                       "line_interval_s": float(self.line_interval_s),
                       "slant_range_time_s": float(self.slant_range_time_s),
                       "range_sampling_rate_hz": float(self.range_sampling_rate_hz),
                       "range_pixel_spacing_m": float(self.range_pixel_spacing_m)},
            "orbit": self.orbit.to_dict(),
        }
        if self.kind == "grd":
            d["grd"] = float_lists(self, "srgr_times_s", "srgr_sr0_m", "srgr_coeffs")
        if self.kind == "tops":
            d["tops"] = {"burst_times_s": self.burst_times_s.tolist(),
                         "lines_per_burst": self.lines_per_burst}
        d["corrections"] = {n: float(getattr(self, n)) for n in PARAM_NAMES}
        return d

    @classmethod
    def from_dict(cls, d: object) -> SarModel:
        """Read a dict written by :meth:`to_dict`; InputError names a missing or mistyped key."""
        try:
            return cls._from_dict(d)
        except InputError as exc:  # the shared readers name the pushbroom model: say SAR
            msg = str(exc).replace("pushbroom model:", "SAR model:").replace(
                "core/sensors/pushbroom.py", "core/sensors/sar.py")
            raise InputError(msg) from None

    @classmethod
    def _from_dict(cls, d: object) -> SarModel:
        fmt = get_str(d, "format", "")
        if fmt != FORMAT:
            raise InputError(f"key 'format' is {fmt!r}, not {FORMAT!r}: not a SAR model")
        kind = get_str(d, "kind", "")
        image, timing = get_dict(d, "image"), get_dict(d, "timing")
        corr = d.get("corrections", {})  # type: ignore[union-attr]
        if not isinstance(corr, dict) or any(k not in PARAM_NAMES for k in corr):
            raise InputError(f"key 'corrections' must map names among {PARAM_NAMES} to "
                             f"numbers, got {corr!r:.80}")
        extra: dict = {}
        if kind == "grd":
            grd = get_dict(d, "grd")
            extra = get_float_arrays(grd, "grd", srgr_times_s=1, srgr_sr0_m=1, srgr_coeffs=2)
        elif kind == "tops":
            tops = get_dict(d, "tops")
            extra = {"burst_times_s": get_float_array(tops, "burst_times_s", "tops", ndim=1),
                     "lines_per_burst": get_int(tops, "lines_per_burst", "tops")}
        return cls(
            orbit=Orbit.from_dict(get_dict(d, "orbit")), kind=kind,
            n_cols=get_int(image, "n_cols", "image"), n_rows=get_int(image, "n_rows", "image"),
            col0_px=get_float(image, "col0_px", "image", default=0.0),
            row0_px=get_float(image, "row0_px", "image", default=0.0),
            **{k: get_float(timing, k, "timing") for k in (
                "first_line_time_s", "line_interval_s", "slant_range_time_s",
                "range_sampling_rate_hz")},
            range_pixel_spacing_m=get_float(timing, "range_pixel_spacing_m", "timing",
                                            default=0.0),
            look_side=get_str(d, "look_side", "", default="right"),
            mission=get_str(d, "mission", "", default=""),
            mode=get_str(d, "mode", "", default=""),
            **{k: get_float(corr, k, "corrections", default=0.0) for k in PARAM_NAMES},
            **extra)

    def to_json(self, indent: int | None = None) -> str:
        return to_json(self.to_dict(), indent=indent)

    @classmethod
    def from_json(cls, text: str) -> SarModel:
        return cls.from_dict(parse_json(text, "SAR model JSON"))


@dataclass(frozen=True)
class GridCheck:
    """A SAR model against an annotation's geolocation grid: errors of the model's line,
    pixel, azimuth time (as metres along track) and slant range (mm) at the grid's
    lon/lat/h, and of its localisation (metres on the ground) at the grid's line/pixel/h."""

    n_points: int
    line_max_px: float
    line_rms_px: float
    pixel_max_px: float
    pixel_rms_px: float
    azimuth_max_m: float
    azimuth_rms_m: float
    range_max_mm: float
    range_rms_mm: float
    ground_max_m: float
    ground_rms_m: float

    def to_dict(self) -> dict[str, float | int]:
        return dict(self.__dict__)


def _max_rms(e: FloatArray) -> tuple[float, float]:
    e = np.abs(e)
    return float(np.max(e)), float(np.sqrt(np.mean(e**2)))


def grid_check(model: SarModel, lon_deg: ArrayLike, lat_deg: ArrayLike, h_m: ArrayLike,
               col: ArrayLike, row: ArrayLike, azimuth_time_s: ArrayLike,
               slant_range_time_s: ArrayLike) -> GridCheck:
    """Compare the model with a geolocation grid (arrays of equal length, times as the model's:
    seconds since its epoch, two-way slant-range time)."""
    _, (lon, lat, h, col, row, t_grid, tau_grid) = _flat(
        lon_deg, lat_deg, h_m, col, row, azimuth_time_s, slant_range_time_s)
    if lon.size == 0:
        raise InputError("the geolocation grid is empty; nothing to check the model against")
    t, tau = model.times(lon, lat, h)
    c, r = model.image_of_times(t, tau)
    speed = model.along_track_speed_m_s(t)
    p_grid = np.stack(geodetic_to_ecef(lon, lat, h), axis=1)
    p_model = model.localize_ecef(col, row, h)
    return GridCheck(
        lon.size, *_max_rms(r - row), *_max_rms(c - col), *_max_rms((t - t_grid) * speed),
        *_max_rms((tau - tau_grid) * 0.5 * SPEED_OF_LIGHT_M_S * 1e3),
        *_max_rms(np.linalg.norm(p_model - p_grid, axis=1)))
