"""Correlation peaks, one home for every matcher: the normalised cross-correlation (NCC) of a
template over a search area, its integer peak, and the sub-pixel peak of a 3x3 neighbourhood;
and orientation correlation, the tie points' measure for pairs lit by two suns.

Used by the tie points (:mod:`core.matching.tiepoints`), the pointing correction of dense
matching (:mod:`core.matching.dense`), the ortho-versus-ortho check
(:mod:`core.ortho.ortho_compare`) and surface matching (:mod:`core.matching.surface`, whose
correlation over lon/lat shifts is its own but whose peak is fitted here).

Conventions: correlation arrays are indexed ``[row, col]`` (``[dy, dx]``); offsets are returned
``(d_col, d_row)`` in grid steps. An NCC that is undefined (nodata in the window, a flat
patch) is :data:`INVALID` (-2, below any correlation), so ``argmax`` never picks it.

Orientation correlation (Fitch, Kadyrov, Christmas & Kittler 2002; Heid & Kaab 2012 chose it
for glacier feature tracking for its robustness to illumination) compares the directions of
the two images' gradients, not their values: the mean, over the template, of the cosine of the
angle between the unit gradients. Shading that changes with the sun changes the values of a
slope more than where its edges are, so the peak moves less between two dates' images: at true
correspondences of the simulated tiny pair under its two suns, the right rows' mean error is
-0.023 px against NCC's -0.052 px and the spread 0.19 against 0.30 px
(``git show c6fc9f8:bench/illumination_bias.py``, a study since removed). Its inputs carry a
one-pixel border the gradients use.
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.choices import MEASURES

FloatArray = NDArray[np.float64]

#: the tie points' correlation measures (``TiePointConfig.measure``) and their names
MEASURE_NAMES = dict(zip(MEASURES, ("normalised cross-correlation", "orientation correlation"),
                         strict=True))

#: the value of an undefined correlation (nodata under the window, a flat patch)
INVALID = -2.0

_U3, _V3 = np.meshgrid([-1.0, 0.0, 1.0], [-1.0, 0.0, 1.0])
_QUAD_PINV = np.linalg.pinv(np.stack([np.ones(9), _U3.ravel(), _V3.ravel(), _U3.ravel() ** 2,
                                      _V3.ravel() ** 2, (_U3 * _V3).ravel()], axis=1))


def ncc_surface(search: NDArray[np.float32], template: NDArray[np.float32],
                invalid: NDArray[np.float32] | NDArray[np.uint8] | None = None
                ) -> NDArray[np.float32]:
    """NCC (OpenCV's ``TM_CCOEFF_NORMED``) of ``template`` at every position inside
    ``search``, shape ``(H - h + 1, W - w + 1)``; :data:`INVALID` where the window touches a
    pixel flagged in ``invalid`` (same shape as ``search``, non-zero = invalid) or where the
    correlation is undefined."""
    ncc = cv2.matchTemplate(np.asarray(search, np.float32), np.asarray(template, np.float32),
                            cv2.TM_CCOEFF_NORMED)
    return _mark_invalid(ncc, template.shape, invalid)


def _mark_invalid(surface: NDArray[np.float32], template_shape: tuple[int, ...],
                  invalid: NDArray[np.float32] | NDArray[np.uint8] | None
                  ) -> NDArray[np.float32]:
    """``surface`` with :data:`INVALID` where a window of ``template_shape`` touches a pixel
    flagged in ``invalid`` (the search area's shape) or where it is not finite."""
    if invalid is not None and np.any(invalid):
        th, tw = template_shape
        counts = cv2.boxFilter(np.asarray(invalid, np.float32), -1, (tw, th), normalize=False,
                               anchor=(0, 0), borderType=cv2.BORDER_CONSTANT)
        surface[counts[:surface.shape[0], :surface.shape[1]] > 1e-3] = INVALID
    surface[~np.isfinite(surface)] = INVALID
    return surface


def unit_gradients(a: ArrayLike) -> FloatArray:
    """Unit gradient directions of a 2-D array or a stack ``(..., h, w)``: ``(..., 2, h - 2,
    w - 2)``, the 3x3 Sobel gradient (along columns, then along rows) of the interior pixels
    divided by its length; 0 where the gradient is 0 (a flat pixel has no direction), NaN where
    its 3x3 neighbourhood holds a NaN."""
    a = np.asarray(a, dtype=np.float64)
    dc = a[..., :, 2:] - a[..., :, :-2]
    dr = a[..., 2:, :] - a[..., :-2, :]
    g = np.stack([dc[..., :-2, :] + 2.0 * dc[..., 1:-1, :] + dc[..., 2:, :],
                  dr[..., :, :-2] + 2.0 * dr[..., :, 1:-1] + dr[..., :, 2:]], axis=-3)
    m = np.sqrt(np.sum(g * g, axis=-3, keepdims=True))
    u = np.divide(g, m, out=np.zeros_like(g), where=m > 0)
    u[np.broadcast_to(np.isnan(m), u.shape)] = np.nan
    return u


def orientation_surface(search: NDArray[np.float32], template: NDArray[np.float32],
                        invalid: NDArray[np.float32] | NDArray[np.uint8] | None = None
                        ) -> NDArray[np.float32]:
    """Orientation correlation of ``template``'s interior at every position inside
    ``search``'s interior (both carry a one-pixel border for the gradients): the mean cosine
    between the unit gradients, 1 for equal directions, about 0 for unrelated patches (a
    standard deviation of 0.073 over 15x15 pixels of white noise, 0.12 of noise smoothed over
    1.2 px; NCC's: 0.066 and 0.18); shape ``(H - h + 1, W - w + 1)``,
    :data:`INVALID` where the window with its border touches a pixel flagged in ``invalid``."""
    s = unit_gradients(search).astype(np.float32)
    t = unit_gradients(template).astype(np.float32)
    oc = (cv2.matchTemplate(s[0], t[0], cv2.TM_CCORR)
          + cv2.matchTemplate(s[1], t[1], cv2.TM_CCORR)) / np.float32(t[0].size)
    return _mark_invalid(oc, template.shape, invalid)


def orientation_correlation(a: ArrayLike, b: ArrayLike) -> FloatArray:
    """Orientation correlation of equal patches with a one-pixel border, over their last two
    axes (``(h, w)`` -> a 0-d array, ``(n, h, w)`` -> ``(n,)``); NaN where a patch holds a
    NaN."""
    ua, ub = unit_gradients(a), unit_gradients(b)
    return np.einsum("...kij,...kij->...", ua, ub) / (ua.shape[-1] * ua.shape[-2])


def correlation_surface(measure: str, search: NDArray[np.float32],
                        template: NDArray[np.float32],
                        invalid: NDArray[np.float32] | NDArray[np.uint8] | None = None
                        ) -> NDArray[np.float32]:
    """:func:`ncc_surface` or :func:`orientation_surface` (``measure`` one of
    :data:`MEASURES`; the orientation's inputs carry its one-pixel border, NCC's do not)."""
    if measure == "orientation":
        return orientation_surface(search, template, invalid)
    return ncc_surface(search, template, invalid)


def patch_correlation(measure: str, a: ArrayLike, b: ArrayLike) -> FloatArray:
    """:func:`ncc` or :func:`orientation_correlation` of equal patches (see
    :func:`correlation_surface` for their borders)."""
    return orientation_correlation(a, b) if measure == "orientation" else ncc(a, b)


def border_px(measure: str) -> int:
    """The border a measure's inputs carry beyond the compared template: 1 for the
    orientation's gradients, 0 for NCC."""
    return 1 if measure == "orientation" else 0


def integer_peak(ncc: NDArray[np.floating]
                 ) -> tuple[int, int, float, NDArray[np.float64] | None]:
    """The highest value's position ``(col, row)``, the value, and its 3x3 neighbourhood for
    :func:`quadratic_peak`: None when the peak is on the border (the true peak may lie
    beyond) or a neighbour is :data:`INVALID` (no curvature to fit)."""
    iy, ix = np.unravel_index(int(np.argmax(ncc)), ncc.shape)
    h, w = ncc.shape
    val = float(ncc[iy, ix])
    if 0 < ix < w - 1 and 0 < iy < h - 1:
        nb = np.asarray(ncc[iy - 1:iy + 2, ix - 1:ix + 2], dtype=np.float64)
        return int(ix), int(iy), val, (nb if np.all(nb > INVALID + 0.5) else None)
    return int(ix), int(iy), val, None


def ncc(a: ArrayLike, b: ArrayLike) -> FloatArray:
    """NCC of equal patches over their last two axes: ``(h, w)`` -> a 0-d array, ``(n, h, w)``
    -> ``(n,)``; NaN where a patch is flat."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    a = a - a.mean(axis=(-2, -1), keepdims=True)
    b = b - b.mean(axis=(-2, -1), keepdims=True)
    num = np.einsum("...ij,...ij->...", a, b)
    den = np.sqrt(np.einsum("...ij,...ij->...", a, a) * np.einsum("...ij,...ij->...", b, b))
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, num / den, np.nan)


def _quadratic(z: ArrayLike) -> tuple[FloatArray, ...]:
    """Coefficients ``(a, b, c, d, e, f)`` of ``a + b u + c v + d u^2 + e v^2 + f u v`` fitted
    by least squares to 3x3 neighbourhoods (n, 3, 3) (u along columns, v along rows)."""
    zz = np.asarray(z, dtype=np.float64).reshape(-1, 9)
    return tuple(_QUAD_PINV @ zz.T)


def quadratic_peak(z: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Sub-pixel peak offsets ``(d_col, d_row)`` (arrays ``(n,)``, grid steps) of 3x3
    neighbourhoods ``(n, 3, 3)`` or ``(3, 3)`` centred on an integer peak.

    The vertex of the 2-D quadratic fitted by least squares; where that quadratic has no
    maximum (a ridge, a saddle), the vertices of the parabolas through the three values on
    each axis (0 where those have none either). Offsets are clipped to +-1 step.

    The one sub-pixel peak of the project: the tie points' and the ortho check's (that is
    this one), and surface matching's, which took the quadratic's stationary point whatever
    its kind (clipped to +-1); the fallback keeps a window whose fit is a saddle from being
    moved by a whole step towards nowhere.
    """
    zz = np.asarray(z, dtype=np.float64).reshape(-1, 3, 3)
    _, b, c, d, e, f = _quadratic(zz)
    det = 4.0 * d * e - f * f
    with np.errstate(invalid="ignore", divide="ignore"):
        good = (d < 0) & (det > 1e-12)
        dx = np.where(good, (f * c - 2.0 * e * b) / det, np.nan)
        dy = np.where(good, (f * b - 2.0 * d * c) / det, np.nan)
    px = parabola_peak(zz[:, 1, 0], zz[:, 1, 1], zz[:, 1, 2])
    py = parabola_peak(zz[:, 0, 1], zz[:, 1, 1], zz[:, 2, 1])
    dx = np.where(np.isfinite(dx), dx, px)
    dy = np.where(np.isfinite(dy), dy, py)
    return np.clip(np.nan_to_num(dx), -1.0, 1.0), np.clip(np.nan_to_num(dy), -1.0, 1.0)


def peak_hessian(z: ArrayLike) -> FloatArray:
    """The Hessian ``(n, 2, 2)`` (per step squared; order col, row) of the quadratic
    :func:`quadratic_peak` fits: how sharp the peak is in each direction."""
    _, _, _, d, e, f = _quadratic(z)
    return np.stack([np.stack([2.0 * d, f], -1), np.stack([f, 2.0 * e], -1)], -2)


def parabola_peak(a: ArrayLike, b: ArrayLike, c: ArrayLike) -> FloatArray:
    """Offset (steps, from ``b``'s position) of the vertex of the parabola through three
    equally spaced values ``a, b, c``; 0 where it has no maximum."""
    a, b, c = (np.asarray(v, dtype=np.float64) for v in (a, b, c))
    den = a - 2.0 * b + c
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den < 0, 0.5 * (a - c) / den, 0.0)
