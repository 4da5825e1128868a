"""Rational polynomial (RPC00B) sensor model with an image-space bias (Fraser & Hanley).

Conventions
-----------
Image coordinates are ``(col, row)``, 0-based, pixel centres at integers (the centre of the
top-left pixel is ``(0, 0)``). Ground is WGS84 lon/lat in degrees and ellipsoidal height ``h`` in
metres.

The projection (ground -> image) is the RPC00B rational function, written out as in the
NITF / GDAL / OSSIM standard::

    L = (lon - lon_off) / lon_scale      P = (lat - lat_off) / lat_scale
    H = (h - alt_off) / alt_scale
    col = col_num(L, P, H) / col_den(L, P, H) * col_scale + col_off
    row = row_num(L, P, H) / row_den(L, P, H) * row_scale + row_off

Each cubic has 20 coefficients in the RPC00B monomial order::

    1, L, P, H, LP, LH, PH, L^2, P^2, H^2, PLH, L^3, LP^2, LH^2, L^2P, P^3, PH^2, L^2H, P^2H, H^3

An optional inverse model (vendor "direct" model, image -> ground) uses the same order with the
normalised column in place of ``L`` and the normalised row in place of ``P``::

    lon = lon_num(C, R, H) / lon_den(C, R, H) * lon_scale + lon_off,  C = (col - col_off) / col_scale

The inverse is only a starting point: :meth:`RPCModel.localize` always refines by Newton
iteration on :meth:`RPCModel.project`, so localisation is exactly the inverse of projection.

Pixel conventions of each source: :mod:`core.sensors.rpc00b` (the named constructors convert
them to ours).

Image-space bias (Fraser & Hanley 2003), applied after the rational function, with ``col, row``
the unbiased RPC image coordinates (0-based, pixels) and ``C, R`` the same normalised by the
RPC's own image offsets and scales (``C = (col - col_off) / col_scale``, in [-1, 1] over the
image)::

    "none":   no parameters
    "shift":  p = [a0, b0];              col += a0;                    row += b0
    "affine": p = [a0, a1, a2, b0, b1, b2]
              col += a0 + a1 * C + a2 * R;       row += b0 + b1 * C + b2 * R

All six are pixels (``a1`` is the shift the affine adds at the right edge of the image relative
to its centre, and so on): well conditioned in an adjustment, and unchanged by a crop.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.dem import GeoDEM
from core.errors import ConvergenceError, InputError
from core.sensors import base, rpc00b
from core.sensors.base import CORRECTION_KINDS
from core.sensors.rpc00b import (
    DX,
    DY,
    GDAL_COEFFS,
    GDAL_INVERSE,
    GDAL_SCALARS,
    parse_number,
    rational_functions,
)

FloatArray = NDArray[np.float64]

BIAS_PARAMS: dict[str, tuple[str, ...]] = {
    "none": (),
    "shift": ("a0", "b0"),
    "affine": ("a0", "a1", "a2", "b0", "b1", "b2"),
}
"""Names of the image-space bias parameters of each bias mode (module docstring)."""
BIAS_MODES: dict[str, int] = {mode: len(names) for mode, names in BIAS_PARAMS.items()}
"""Number of image-space bias parameters of each bias mode."""

_SCALAR_FIELDS = (
    "col_off", "col_scale", "row_off", "row_scale", "lon_off", "lon_scale",
    "lat_off", "lat_scale", "alt_off", "alt_scale",
)
_FORWARD_FIELDS = ("col_num", "col_den", "row_num", "row_den")
_INVERSE_FIELDS = ("lon_num", "lon_den", "lat_num", "lat_den")

@dataclass(frozen=True, eq=False)
class RPCModel:
    """RPC00B sensor model with optional inverse polynomial and image-space bias.

    See the module docstring for the formulas, the monomial order, the pixel conventions and
    the bias parameters. Offsets and scales are in pixels, degrees and metres. Build it with
    the named constructors (:meth:`from_geom`, :meth:`from_gdal_tags`, :meth:`from_dimap_xml`,
    :meth:`from_dict`) or by keyword (an RPC fitter).
    """

    col_off: float
    col_scale: float
    row_off: float
    row_scale: float
    lon_off: float
    lon_scale: float
    lat_off: float
    lat_scale: float
    alt_off: float
    alt_scale: float
    col_num: FloatArray
    col_den: FloatArray
    row_num: FloatArray
    row_den: FloatArray
    lon_num: FloatArray | None = None
    lon_den: FloatArray | None = None
    lat_num: FloatArray | None = None
    lat_den: FloatArray | None = None
    bias_mode: str = "none"
    bias: FloatArray = field(default_factory=lambda: np.zeros(0))

    def __post_init__(self) -> None:
        for name in _SCALAR_FIELDS:
            v = parse_number(name, getattr(self, name))
            if not math.isfinite(v):
                raise InputError(f"RPC {name} is {v}; it must be finite")
            if name.endswith("_scale") and v == 0:
                raise InputError(
                    f"RPC {name} (key {GDAL_SCALARS[name]}) is zero; the RPC cannot be "
                    "normalised, fix the RPC file"
                )
            object.__setattr__(self, name, v)
        for name in _FORWARD_FIELDS:
            object.__setattr__(self, name, self._checked_coeffs(name, getattr(self, name)))
        given = [getattr(self, n) is not None for n in _INVERSE_FIELDS]
        if any(given) and not all(given):
            missing = [n for n, g in zip(_INVERSE_FIELDS, given, strict=True) if not g]
            raise InputError(f"inverse RPC incomplete: {missing} missing; give all four or none")
        if all(given):
            for name in _INVERSE_FIELDS:
                object.__setattr__(self, name, self._checked_coeffs(name, getattr(self, name)))
        if self.bias_mode not in BIAS_MODES:
            raise InputError(f"bias_mode {self.bias_mode!r} unknown; use one of {list(BIAS_MODES)}")
        bias = np.array(self.bias, dtype=np.float64).ravel()
        n = BIAS_MODES[self.bias_mode]
        if bias.size == 0 and n:
            bias = np.zeros(n)
        if bias.size != n:
            raise InputError(
                f"bias_mode {self.bias_mode!r} takes {n} parameters, got {bias.size}"
            )
        if not np.all(np.isfinite(bias)):
            raise InputError("bias parameters must be finite")
        bias.setflags(write=False)
        object.__setattr__(self, "bias", bias)

    @staticmethod
    def _checked_coeffs(name: str, value: Any) -> FloatArray:
        if value is None:
            raise InputError(f"RPC coefficients {name!r} are missing; give 20 values")
        a = np.array(value, dtype=np.float64).ravel()
        if a.shape != (20,):
            raise InputError(f"RPC coefficients {name!r} have {a.size} values, expected 20")
        if not np.all(np.isfinite(a)):
            raise InputError(f"RPC coefficients {name!r} are not all finite; fix the RPC file")
        if not np.any(a):
            key = GDAL_COEFFS.get(name) or GDAL_INVERSE.get(name)
            raise InputError(
                f"RPC coefficients {name!r} (key {key}) are all zero, a degenerate RPC (GDAL "
                "writes zeros for a malformed coefficient list); fix the RPC file"
            )
        a.setflags(write=False)
        return a

    # ------------------------------------------------------------------ evaluation

    @cached_property
    def _forward(self) -> FloatArray:
        return np.stack([self.col_num, self.col_den, self.row_num, self.row_den])

    @property
    def has_inverse(self) -> bool:
        """Whether the model holds an (approximate) image -> ground polynomial."""
        return self.lon_num is not None

    def _bias_matrix(self) -> tuple[FloatArray, FloatArray]:
        """(A, t) with biased = A @ unbiased + t, for 2-vectors (col, row)."""
        p = self.bias
        if self.bias_mode == "shift":
            return np.eye(2), np.array([p[0], p[1]])
        if self.bias_mode == "affine":
            cs, rs, co, ro = self.col_scale, self.row_scale, self.col_off, self.row_off
            a = np.array([[1.0 + p[1] / cs, p[2] / rs], [p[4] / cs, 1.0 + p[5] / rs]])
            return a, np.array([p[0] - p[1] * co / cs - p[2] * ro / rs,
                                p[3] - p[4] * co / cs - p[5] * ro / rs])
        return np.eye(2), np.zeros(2)

    def _apply_bias(self, col: FloatArray, row: FloatArray) -> tuple[FloatArray, FloatArray]:
        if self.bias_mode == "none":
            return col, row
        a, t = self._bias_matrix()
        return a[0, 0] * col + a[0, 1] * row + t[0], a[1, 0] * col + a[1, 1] * row + t[1]

    def _remove_bias(self, col: FloatArray, row: FloatArray) -> tuple[FloatArray, FloatArray]:
        if self.bias_mode == "none":
            return col, row
        a, t = self._bias_matrix()
        det = a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]
        if abs(det) < 1e-12:
            raise InputError("the affine bias is singular; check the bias parameters")
        dc, dr = col - t[0], row - t[1]
        return (a[1, 1] * dc - a[0, 1] * dr) / det, (a[0, 0] * dr - a[1, 0] * dc) / det

    def _project_norm(
        self, x: FloatArray, y: FloatArray, z: FloatArray
    ) -> tuple[FloatArray, FloatArray]:
        """Unbiased image (col, row) in pixels from normalised 1-D (L, P, H)."""
        v = rational_functions(self._forward, x, y, z)
        return v[0] * self.col_scale + self.col_off, v[1] * self.row_scale + self.row_off

    def project(
        self, lon_deg: ArrayLike, lat_deg: ArrayLike, h_m: ArrayLike
    ) -> tuple[FloatArray, FloatArray]:
        """Ground (lon deg, lat deg, ellipsoidal h m) -> image (col, row) pixels, bias applied.

        Inputs broadcast against each other; outputs have the broadcast shape (0-d for scalars).
        """
        lon, lat, h = np.broadcast_arrays(
            np.asarray(lon_deg, dtype=np.float64),
            np.asarray(lat_deg, dtype=np.float64),
            np.asarray(h_m, dtype=np.float64),
        )
        # imports Numba: only when projecting
        from core.sensors.rpc_kernels import rpc_project

        col, row = rpc_project(self._forward, lon.ravel(), lat.ravel(), h.ravel(),
                               self._ground_norm, self._image_affine)
        return col.reshape(lon.shape), row.reshape(lon.shape)

    def _project_numpy(
        self, lon_deg: ArrayLike, lat_deg: ArrayLike, h_m: ArrayLike
    ) -> tuple[FloatArray, FloatArray]:
        """:meth:`project` evaluated with NumPy (:func:`~core.sensors.rpc00b.rational_functions`):
        the reference the compiled kernel is tested against."""
        lon, lat, h = np.broadcast_arrays(
            np.asarray(lon_deg, dtype=np.float64),
            np.asarray(lat_deg, dtype=np.float64),
            np.asarray(h_m, dtype=np.float64),
        )
        shape = lon.shape
        v = rational_functions(
            self._forward, lon.ravel(), lat.ravel(), h.ravel(),
            (self.lon_off, self.lat_off, self.alt_off),
            (self.lon_scale, self.lat_scale, self.alt_scale),
        )
        col, row = v[0], v[1]
        col *= self.col_scale
        col += self.col_off
        row *= self.row_scale
        row += self.row_off
        col, row = self._apply_bias(col, row)
        return col.reshape(shape), row.reshape(shape)

    @cached_property
    def _ground_norm(self) -> FloatArray:
        """lon_off, lat_off, alt_off, lon_scale, lat_scale, alt_scale (the compiled kernel's)."""
        return np.array([self.lon_off, self.lat_off, self.alt_off,
                         self.lon_scale, self.lat_scale, self.alt_scale])

    @cached_property
    def _image_affine(self) -> FloatArray:
        """col_scale, col_off, row_scale, row_off, then the bias A (row-major), t and 1.0
        when there is a bias (0.0 when none)."""
        a, t = self._bias_matrix()
        return np.array([self.col_scale, self.col_off, self.row_scale, self.row_off,
                         *a.ravel(), *t, float(self.bias_mode != "none")])

    @cached_property
    def _forward_with_derivatives(self) -> FloatArray:
        """(12, 20): the forward cubics, then their x-derivatives, then their y-derivatives."""
        f = self._forward
        return np.vstack([f, f @ DX, f @ DY])

    def _jacobian_norm(
        self, x: FloatArray, y: FloatArray, z: FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Unbiased (col, row) pixels and their derivatives d(col,row)/d(x,y), shape (2, 2, n)."""
        v = rational_functions(self._forward_with_derivatives, x, y, z, divide=False)
        scales = (self.col_scale, self.row_scale)
        jac = np.empty((2, 2, x.size))
        out = []
        for i in range(2):
            num, den = v[2 * i], v[2 * i + 1]
            for j in range(2):
                d_num, d_den = v[4 + 4 * j + 2 * i], v[4 + 4 * j + 2 * i + 1]
                jac[i, j] = (d_num * den - num * d_den) / (den * den) * scales[i]
            out.append(num / den)
        return out[0] * self.col_scale + self.col_off, out[1] * self.row_scale + self.row_off, jac

    @cached_property
    def _linear_inverse(self) -> FloatArray:
        """Affine least-squares fit (3, 2): [C, R, H, 1] -> normalised (L, P), over the domain."""
        g = np.linspace(-1.0, 1.0, 7)
        x, y, z = (a.ravel() for a in np.meshgrid(g, g, np.linspace(-1.0, 1.0, 3)))
        col, row = self._project_norm(x, y, z)
        c = (col - self.col_off) / self.col_scale
        r = (row - self.row_off) / self.row_scale
        design = np.column_stack([c, r, z, np.ones_like(c)])
        sol, *_ = np.linalg.lstsq(design, np.column_stack([x, y]), rcond=None)
        return sol

    def _initial_guess(
        self, col: FloatArray, row: FloatArray, z: FloatArray, *, use_inverse: bool = True
    ) -> tuple[FloatArray, FloatArray]:
        """Normalised (L, P) first guess from unbiased pixel coordinates: the inverse
        polynomial when there is one (and ``use_inverse``), else the affine approximation."""
        c = (col - self.col_off) / self.col_scale
        r = (row - self.row_off) / self.row_scale
        if self.has_inverse and use_inverse:
            inv = np.stack([self.lon_num, self.lon_den, self.lat_num, self.lat_den])
            v = rational_functions(inv, c, r, z)
            # the vendor inverse is normalised with the same lon/lat offsets and scales
            return v[0], v[1]
        sol = self._linear_inverse
        design = np.column_stack([c, r, z, np.ones_like(c)])
        guess = design @ sol
        return guess[:, 0], guess[:, 1]

    def localize(
        self,
        col: ArrayLike,
        row: ArrayLike,
        h_m: ArrayLike,
        *,
        tol_px: float = 1e-8,
        max_iter: int = 30,
    ) -> tuple[FloatArray, FloatArray]:
        """Image (col, row) pixels at ellipsoidal height h m -> ground (lon, lat) degrees.

        Starts from the inverse polynomial when the model has one, else from an affine
        approximation of the inverse, then runs Newton iterations on :meth:`project` (bias
        included) until every point reprojects within ``tol_px`` pixels. NaN inputs give NaN.

        Raises:
            ConvergenceError: some points did not converge in ``max_iter`` iterations (e.g. far
                outside the RPC validity domain); the message says how many.
        """
        c, r, h = np.broadcast_arrays(
            np.asarray(col, dtype=np.float64),
            np.asarray(row, dtype=np.float64),
            np.asarray(h_m, dtype=np.float64),
        )
        shape = c.shape
        tc, tr = self._remove_bias(c.ravel(), r.ravel())
        z = (h.ravel() - self.alt_off) / self.alt_scale
        x = np.full(tc.shape, np.nan)
        y = np.full(tc.shape, np.nan)
        ok = np.isfinite(tc) & np.isfinite(tr) & np.isfinite(z)
        idx = np.flatnonzero(ok)
        if idx.size:
            xi, yi = self._initial_guess(tc[idx], tr[idx], z[idx])
            xi, yi, bad = self._newton(tc[idx], tr[idx], z[idx], xi, yi, tol_px, max_iter)
            if bad.size and self.has_inverse:
                # the vendor inverse can be wild outside its domain: retry from the affine guess
                k = idx[bad]
                xb, yb = self._initial_guess(tc[k], tr[k], z[k], use_inverse=False)
                xb, yb, still = self._newton(tc[k], tr[k], z[k], xb, yb, tol_px, max_iter)
                xi[bad], yi[bad] = xb, yb
                bad = bad[still]
            failed = bad.size
            if failed:
                raise ConvergenceError(
                    f"RPC localisation did not converge for {failed} of {idx.size} points "
                    f"within {max_iter} iterations (tolerance {tol_px} px); check that the "
                    "points and heights lie inside the RPC validity domain"
                )
            x[idx], y[idx] = xi, yi
        lon = x * self.lon_scale + self.lon_off
        lat = y * self.lat_scale + self.lat_off
        return lon.reshape(shape), lat.reshape(shape)

    def _newton(
        self,
        tc: FloatArray,
        tr: FloatArray,
        z: FloatArray,
        x: FloatArray,
        y: FloatArray,
        tol_px: float,
        max_iter: int,
    ) -> tuple[FloatArray, FloatArray, NDArray[np.intp]]:
        """Solve unbiased project_norm(x, y, z) = (tc, tr) for normalised (x, y).

        Returns the solution and the indices of the points that did not converge.
        """
        x, y = x.copy(), y.copy()
        todo = np.arange(x.size)
        with np.errstate(all="ignore"):  # diverging points go NaN and are counted as failed
            for _ in range(max_iter + 1):
                # one Newton update at the points not yet within tol_px
                pc, pr, jac = self._jacobian_norm(x[todo], y[todo], z[todo])
                ec, er = tc[todo] - pc, tr[todo] - pr
                keep = ~(np.hypot(ec, er) <= tol_px)
                todo, ec, er, jac = todo[keep], ec[keep], er[keep], jac[:, :, keep]
                if todo.size == 0:
                    break
                det = jac[0, 0] * jac[1, 1] - jac[0, 1] * jac[1, 0]
                x[todo] += (jac[1, 1] * ec - jac[0, 1] * er) / det
                y[todo] += (jac[0, 0] * er - jac[1, 0] * ec) / det
        return x, y, todo

    def localize_on_dem(
        self, col: ArrayLike, row: ArrayLike, dem: GeoDEM
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Intersect lines of sight with a DEM (ellipsoidal heights): -> (lon, lat, h).

        Delegates to :func:`core.sensors.base.localize_on_dem`; NaN where the ray misses.
        """
        return base.localize_on_dem(self, col, row, dem)

    # ------------------------------------------------------------------ parameters

    @property
    def params(self) -> FloatArray:
        """The image-space bias parameters (0, 2 or 6 values, see the module docstring)."""
        return self.bias.copy()

    @property
    def param_names(self) -> tuple[str, ...]:
        """Names of the bias parameters of the current mode: () , (a0, b0) or (a0 .. b2)."""
        return BIAS_PARAMS[self.bias_mode]

    def jacobian(self, lon_deg: ArrayLike, lat_deg: ArrayLike, h_m: ArrayLike) -> FloatArray:
        """d(col, row)/d(bias params) at ground points, shape (n, 2, p): analytic (the bias is
        linear in its parameters; the affine terms multiply the normalised unbiased col, row)."""
        lon, lat, h = (np.ravel(a) for a in np.broadcast_arrays(
            np.asarray(lon_deg, dtype=np.float64), np.asarray(lat_deg, dtype=np.float64),
            np.asarray(h_m, dtype=np.float64)))
        n = lon.size
        jac = np.zeros((n, 2, BIAS_MODES[self.bias_mode]))
        if self.bias_mode == "shift":
            jac[:, 0, 0] = 1.0
            jac[:, 1, 1] = 1.0
        elif self.bias_mode == "affine":
            col, row = replace(self, bias_mode="none", bias=np.zeros(0)).project(lon, lat, h)
            c = (col - self.col_off) / self.col_scale
            r = (row - self.row_off) / self.row_scale
            jac[:, 0, 0], jac[:, 0, 1], jac[:, 0, 2] = 1.0, c, r
            jac[:, 1, 3], jac[:, 1, 4], jac[:, 1, 5] = 1.0, c, r
        return jac

    @property
    def param_units(self) -> tuple[str, ...]:
        """Every bias parameter is in pixels (module docstring)."""
        return ("px",) * BIAS_MODES[self.bias_mode]

    def with_corrections(self, kind: str) -> RPCModel:
        """``"offset"``: an image shift; ``"linear"``: an affine (the current bias carried over)."""
        if kind not in CORRECTION_KINDS:
            raise InputError(f"correction kind {kind!r} unknown; use one of {CORRECTION_KINDS}")
        return self.with_bias_mode("shift" if kind == "offset" else "affine")

    def with_params(self, p: ArrayLike) -> RPCModel:
        """A new model with the bias parameters set to ``p`` (same bias mode)."""
        p = np.asarray(p, dtype=np.float64).ravel()
        n = BIAS_MODES[self.bias_mode]
        if p.size != n:
            raise InputError(
                f"bias_mode {self.bias_mode!r} takes {n} parameters, got {p.size}; "
                "use with_bias_mode() first to change the mode"
            )
        return replace(self, bias=p)

    def with_bias_mode(self, mode: str) -> RPCModel:
        """A new model with bias mode ``mode``; the current bias is carried over when it can be
        expressed exactly in the new mode (e.g. shift -> affine), else InputError."""
        if mode not in BIAS_MODES:
            raise InputError(f"bias_mode {mode!r} unknown; use one of {list(BIAS_MODES)}")
        a, t = self._bias_matrix()
        lin = a - np.eye(2)
        if mode == "affine":  # biased - unbiased = lin @ (col, row) + t, in normalised terms
            cs, rs, co, ro = self.col_scale, self.row_scale, self.col_off, self.row_off
            a1, a2, b1, b2 = lin[0, 0] * cs, lin[0, 1] * rs, lin[1, 0] * cs, lin[1, 1] * rs
            p = np.array([t[0] + lin[0, 0] * co + lin[0, 1] * ro, a1, a2,
                          t[1] + lin[1, 0] * co + lin[1, 1] * ro, b1, b2])
        else:
            if np.any(lin != 0) or (mode == "none" and np.any(t != 0)):
                raise InputError(
                    f"the current {self.bias_mode} bias cannot be expressed in mode {mode!r}; "
                    "reset it with with_params(zeros) first"
                )
            p = t.copy() if mode == "shift" else np.zeros(0)
        return replace(self, bias_mode=mode, bias=p)

    def with_image_offset(self, col0: float, row0: float) -> RPCModel:
        """The same model in the pixel coordinates of a crop whose pixel (0, 0) is pixel
        (col0, row0) of this model's image: ``col_crop = col - col0``, ``row_crop = row - row0``.
        """
        col0, row0 = float(col0), float(row0)
        # the bias acts on coordinates normalised by the offsets, which move with the crop
        return replace(self, col_off=self.col_off - col0, row_off=self.row_off - row0)

    # ------------------------------------------------------------------ constructors

    @classmethod
    def from_geom(cls, text: str) -> RPCModel:
        """From the text of an OSSIM ``.geom`` keyword list
        (:func:`~core.sensors.rpc00b.geom_fields`)."""
        return cls(**rpc00b.geom_fields(text))

    @classmethod
    def from_gdal_tags(cls, tags: Mapping[str, Any]) -> RPCModel:
        """From the GDAL RPC metadata domain (``rasterio`` ``src.tags(ns="RPC")``;
        :func:`~core.sensors.rpc00b.gdal_tag_fields`)."""
        return cls(**rpc00b.gdal_tag_fields(tags))

    @classmethod
    def from_dimap_xml(cls, text: str) -> RPCModel:
        """From a Pleiades / SPOT 6-7 DIMAP v2 RPC XML document (``RPC_*.XML``;
        :func:`~core.sensors.rpc00b.dimap_xml_fields`)."""
        return cls(**rpc00b.dimap_xml_fields(text))

    # ------------------------------------------------------------------ writers

    def to_gdal_tags(self) -> dict[str, str]:
        """The GDAL RPC metadata domain (for ``rasterio`` ``dst.update_tags(ns="RPC", ...)``).

        The bias is folded into the RPC: a shift exactly (into ``SAMP_OFF``/``LINE_OFF``), an
        affine bias only when it has no cross terms (a2 = b1 = 0: folded into offsets and
        scales); otherwise InputError (refit the RPC to the adjusted model instead). The
        inverse polynomial is not written (GDAL has no key for it). Pixel convention: ours.
        """
        col_off, col_scale, row_off, row_scale = (
            self.col_off, self.col_scale, self.row_off, self.row_scale
        )
        if self.bias_mode != "none":
            a, t = self._bias_matrix()
            if a[0, 1] != 0 or a[1, 0] != 0:
                raise InputError(
                    "an affine bias with cross terms (a2, b1) cannot be folded into an RPC00B; "
                    "refit the RPC to the adjusted model before writing it"
                )
            col_off, col_scale = a[0, 0] * col_off + t[0], a[0, 0] * col_scale
            row_off, row_scale = a[1, 1] * row_off + t[1], a[1, 1] * row_scale
        vals = {name: getattr(self, name) for name in _SCALAR_FIELDS}
        vals.update(col_off=col_off, col_scale=col_scale, row_off=row_off, row_scale=row_scale)
        return rpc00b.gdal_tags(vals, {name: getattr(self, name) for name in GDAL_COEFFS})

    def to_dict(self) -> dict[str, Any]:
        """A JSON-serialisable dict holding every field (arrays as lists, absent inverse None)."""
        out: dict[str, Any] = {"type": "rpc", "version": 1}
        for f in fields(self):
            v = getattr(self, f.name)
            out[f.name] = v.tolist() if isinstance(v, np.ndarray) else v
        return out

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> RPCModel:
        """Inverse of :meth:`to_dict`."""
        if d.get("type", "rpc") != "rpc":
            raise InputError(f"the dict describes a {d.get('type')!r} model, not an RPC model")
        names = {f.name for f in fields(cls)}
        required = set(_SCALAR_FIELDS) | set(_FORWARD_FIELDS)
        missing = sorted(required - set(d))
        if missing:
            raise InputError(f"RPC dict lacks {missing}; give a dict written by to_dict()")
        return cls(**{k: v for k, v in d.items() if k in names})

    def __repr__(self) -> str:
        inv = "with inverse" if self.has_inverse else "no inverse"
        return (
            f"RPCModel(col_off={self.col_off}, row_off={self.row_off}, lon_off={self.lon_off}, "
            f"lat_off={self.lat_off}, {inv}, bias_mode={self.bias_mode!r}, "
            f"bias={self.bias.tolist()})"
        )

