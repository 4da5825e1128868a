"""Matching across modalities: a SAR image against an optical one, both resampled onto one
ground grid.

Grey levels do not correlate between a radar and an optical image (a forest is dark in one and
bright in the other, a slope facing the sun is not the slope facing the antenna), but the
*places* where the grey level changes, and the direction of the change, are the same: field
and forest edges, roads, rivers, towns. The matcher compares those, as CFOG does (Ye, Bruzzone,
Shan, Bovolo, Zhu: "Fast and robust matching for multimodal remote sensing image
registration", IEEE TGRS 57(11), 2019):

- **Descriptor** (:func:`orientation_channels`): at every cell the gradient's magnitude along
  ``n`` directions over half a turn (``|g . u_k|``: the sign of the contrast is dropped, so a
  reversed edge still matches), each channel smoothed by a Gaussian, then along the
  orientations by ``[1, 2, 1]``, and the vector normalised to unit length. A SAR image is
  described from its log intensity, where speckle is additive and an edge is a ratio.
- **Score** (:func:`channel_ncc`): the correlation coefficient of the template's and the
  search window's descriptor vectors, all channels together, for every shift at once
  (:func:`cv2.matchTemplate` per channel, the sums by box filters).
- **Search** (:func:`match_points`): each template searched within a radius around a predicted
  offset; the peak refined by :func:`core.matching.peaks.quadratic_peak`; refused when the
  template lacks structure, the peak is low, on the border, or not clearly above the best
  peak elsewhere (the ratio test).

The ground grid and the images' positions on it are :class:`GroundGrid` and
:func:`image_positions` (a lattice of exact projections, interpolated, with the height
dependence kept).

**A SAR image predicted from a surface** (:func:`splat`, :func:`radar_shadow`,
:func:`quantile_lut`): where the ground has height steps (forest edges, buildings) the radar
does not show the step where an optical image does, whatever heights the two are resampled
at: it lays the top over the ground in front of it (summed with it in one pixel) and stretches
or hides what lies behind, and an orthoimage cannot undo a many-to-one mapping. What can be
compared with the radar is the radar's view of a surface: every cell of it sent to its image
position (energy kept: foreshortened slopes brighten, stretched ones dim), nothing from the
cells hidden from the antenna, each cell's brightness a function of its optical grey level
learnt from the two images themselves. No I/O here.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from enum import IntEnum

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.errors import InputError
from core.geodesy import metres_per_degree
from core.matching.peaks import quadratic_peak

FloatArray = NDArray[np.float64]
Project = Callable[[FloatArray, FloatArray, FloatArray], tuple[FloatArray, FloatArray]]
Localize = Project  # (col, row, h) -> (lon, lat)


@dataclass(frozen=True)
class GroundGrid:
    """A lon/lat grid with square cells of ``cell_m`` metres at its centre latitude: node
    ``(i, j)`` at ``(lon0 + j dlon, lat0 - i dlat)`` (rows go south)."""

    lon0_deg: float
    lat0_deg: float
    dlon_deg: float
    dlat_deg: float
    shape: tuple[int, int]
    cell_m: float

    @classmethod
    def covering(cls, lon_deg: ArrayLike, lat_deg: ArrayLike, cell_m: float) -> GroundGrid:
        """The grid of ``cell_m`` cells covering the points' lon/lat box."""
        lon, lat = np.asarray(lon_deg, float), np.asarray(lat_deg, float)
        if not (cell_m > 0 and np.isfinite(lon).all() and np.isfinite(lat).all()):
            raise InputError("a ground grid needs finite corners and a positive cell size")
        mlon, mlat = metres_per_degree(0.5 * (lat.min() + lat.max()))
        dlon, dlat = cell_m / float(mlon), cell_m / float(mlat)
        shape = (int(np.ceil((lat.max() - lat.min()) / dlat)) + 1,
                 int(np.ceil((lon.max() - lon.min()) / dlon)) + 1)
        return cls(float(lon.min()), float(lat.max()), dlon, dlat, shape, float(cell_m))

    def lonlat(self, i: ArrayLike, j: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Lon/lat of fractional node indices (row ``i``, column ``j``)."""
        return (self.lon0_deg + np.asarray(j, float) * self.dlon_deg,
                self.lat0_deg - np.asarray(i, float) * self.dlat_deg)

    def indices(self, lon_deg: ArrayLike, lat_deg: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Fractional (row, column) indices of lon/lat points."""
        return ((self.lat0_deg - np.asarray(lat_deg, float)) / self.dlat_deg,
                (np.asarray(lon_deg, float) - self.lon0_deg) / self.dlon_deg)

    def nodes(self) -> tuple[FloatArray, FloatArray]:
        """Lon/lat of every node, arrays of the grid's shape."""
        i, j = np.mgrid[0:self.shape[0], 0:self.shape[1]]
        return self.lonlat(i, j)


def image_positions(project: Project, grid: GroundGrid, h_m: FloatArray,
                    step: int = 16) -> tuple[FloatArray, FloatArray]:
    """Image (col, row) of every node of ``grid`` at heights ``h_m`` (grid-shaped; NaN: the
    mean): exact projections on a lattice every ``step`` nodes at three heights spanning
    ``h_m``, interpolated bilinearly across the lattice and quadratically in height. Sensor
    models are smooth over a lattice cell (its error is printed by the tests, under 1e-3 px
    on the simulated pushbroom and SAR models at 16 cells of 80 m)."""
    h = np.where(np.isfinite(h_m), h_m, np.nanmean(h_m) if np.isfinite(h_m).any() else 0.0)
    lo, hi = float(h.min()), float(h.max())
    if hi - lo < 1.0:
        lo, hi = lo - 0.5, hi + 0.5
    levels = np.array([lo, 0.5 * (lo + hi), hi])
    ni, nj = grid.shape
    li = np.unique(np.r_[np.arange(0, ni, step), ni - 1])
    lj = np.unique(np.r_[np.arange(0, nj, step), nj - 1])
    LI, LJ = np.meshgrid(li, lj, indexing="ij")
    lon, lat = grid.lonlat(LI, LJ)
    at_levels = []
    for level in levels:
        c, r = project(lon.ravel(), lat.ravel(), np.full(lon.size, level))
        at_levels.append((np.reshape(c, LI.shape), np.reshape(r, LI.shape)))
    # bilinear across the lattice, one axis after the other: per output row (column), the
    # lattice cell and the weight
    ii, jj = np.arange(ni, dtype=float), np.arange(nj, dtype=float)
    ci = np.clip(np.searchsorted(li, ii, side="right") - 1, 0, li.size - 2)
    cj = np.clip(np.searchsorted(lj, jj, side="right") - 1, 0, lj.size - 2)
    wi = ((ii - li[ci]) / (li[ci + 1] - li[ci]))[:, None]
    wj = ((jj - lj[cj]) / (lj[cj + 1] - lj[cj]))[None, :]

    def upsample(v: FloatArray) -> FloatArray:
        rows = (1 - wi) * v[ci] + wi * v[ci + 1]  # (ni, lattice columns)
        return (1 - wj) * rows[:, cj] + wj * rows[:, cj + 1]

    t = (h - levels[1]) / (0.5 * (hi - lo))  # -1 at lo, 0 mid, +1 hi
    lagrange = (0.5 * t * (t - 1), 1 - t * t, 0.5 * t * (t + 1))
    col = sum(w * upsample(c) for w, (c, _) in zip(lagrange, at_levels, strict=True))
    row = sum(w * upsample(r) for w, (_, r) in zip(lagrange, at_levels, strict=True))
    return col, row


def remap(z: NDArray[np.float32], col: FloatArray, row: FloatArray) -> FloatArray:
    """Bilinear values of ``z`` at (col, row) in float32 (OpenCV's remap, NaN outside): the
    images stay in single precision, a 6000-pixel image costs 144 MB, not 288."""
    out = cv2.remap(z, col.astype(np.float32), row.astype(np.float32), cv2.INTER_LINEAR,
                    borderMode=cv2.BORDER_CONSTANT, borderValue=float("nan"))
    inside = (col >= 0) & (col <= z.shape[1] - 1) & (row >= 0) & (row <= z.shape[0] - 1)
    return np.where(inside, out, np.nan)


def pixel_size_m(col: FloatArray, row: FloatArray, cell_m: float) -> float:
    """An image's pixel size on the ground (m), from its positions on a grid of ``cell_m``."""
    step = np.hypot(np.diff(col, axis=1), np.diff(row, axis=1))
    return cell_m / max(float(np.nanmedian(step)), 1e-12)


def remap_lowpass(img: NDArray[np.float32], col: FloatArray, row: FloatArray,
             sigma: float) -> FloatArray:
    """``img`` at positions (col, row), low-passed by ``sigma`` pixels first (NaN-aware:
    a pixel next to unknown ones stays unknown)."""
    if sigma <= 0.5:
        return remap(img, col, row)
    known = np.isfinite(img)
    lo = cv2.GaussianBlur(np.where(known, img, 0.0).astype(np.float32), (0, 0), sigma)
    w = cv2.GaussianBlur(known.astype(np.float32), (0, 0), sigma)
    return remap(np.where(w > 0.99, lo / np.maximum(w, 1e-6), np.nan).astype(np.float32),
                  col, row)


def _gradients(image: FloatArray) -> tuple[NDArray[np.bool_], NDArray[np.float32],
                                          NDArray[np.float32]]:
    """Where ``image`` has data, and its Sobel gradients (x, y) with no-data cells filled
    by the mean (0 when there is none)."""
    valid = np.isfinite(image)
    z = np.where(valid, image, np.nanmean(image) if valid.any() else 0.0).astype(np.float32)
    return (valid, cv2.Sobel(z, cv2.CV_32F, 1, 0, ksize=3),
            cv2.Sobel(z, cv2.CV_32F, 0, 1, ksize=3))


def orientation_channels(image: FloatArray, n_orientations: int = 9,
                         sigma_cells: float = 1.0) -> NDArray[np.float32]:
    """The CFOG descriptor ``(n, rows, cols)`` of ``image`` (NaN: no data, described as 0):
    per cell, the unsigned gradient along ``n`` directions over half a turn, smoothed in space
    (Gaussian ``sigma_cells``) and across orientations (``[1, 2, 1]``), normalised to unit
    length; zero where a no-data cell is within two cells."""
    valid, gx, gy = _gradients(image)
    if not valid.any():
        return np.zeros((n_orientations, *image.shape), np.float32)
    angles = np.arange(n_orientations) * np.pi / n_orientations
    raw = np.empty((n_orientations, *image.shape), np.float32)
    for k, a in enumerate(angles):
        raw[k] = cv2.GaussianBlur(np.abs(np.float32(np.cos(a)) * gx + np.float32(np.sin(a)) * gy),
                                  (0, 0), sigma_cells)
    ch = np.empty_like(raw)  # [1, 2, 1] across orientations (circular), one copy
    for k in range(n_orientations):
        ch[k] = 0.25 * (raw[k - 1] + 2.0 * raw[k] + raw[(k + 1) % n_orientations])
    del raw
    norm = np.sqrt(np.einsum("kij,kij->ij", ch, ch))
    ch /= np.maximum(norm, np.float32(1e-6 * max(float(norm.max()), 1e-30)))
    bad = cv2.dilate((~valid).astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
    ch[:, bad] = 0.0
    return ch


def channel_ncc(template: NDArray[np.float32], search: NDArray[np.float32],
                mask: NDArray[np.bool_] | None = None) -> FloatArray:
    """Correlation coefficient of the descriptor vectors (all channels together) of
    ``template`` ``(n, t, t)`` and of every ``(t, t)`` window of ``search`` ``(n, s, s)``:
    ``(s - t + 1, s - t + 1)``, indexed by the window's top-left corner. With ``mask``
    ``(t, t)``, only the template's cells where it is True take part, in the template and in
    every window (the masked correlation: the search image is not altered, so a mask cannot
    correlate with itself)."""
    n, th, tw = template.shape
    w = np.ones((th, tw), np.float32) if mask is None else mask.astype(np.float32)
    n_cells = float(w.sum())
    if n_cells < 2:
        return np.full((search.shape[1] - th + 1, search.shape[2] - tw + 1), -1.0)
    mean = (template * w).sum(axis=(1, 2), keepdims=True) / n_cells
    t = (template - mean) * w
    t_energy = float((t * t).sum())
    num = den = None
    for k in range(n):
        cc = cv2.matchTemplate(search[k], t[k], cv2.TM_CCORR)
        s1 = cv2.matchTemplate(search[k], w, cv2.TM_CCORR)
        s2 = cv2.matchTemplate(search[k] * search[k], w, cv2.TM_CCORR)
        var = s2 - s1 * s1 / n_cells
        num = cc if num is None else num + cc
        den = var if den is None else den + var
    with np.errstate(invalid="ignore", divide="ignore"):
        score = num / np.sqrt(np.maximum(den, 0.0) * t_energy)
    return np.where(np.isfinite(score), score, -1.0).astype(np.float64)


class MatchStatus(IntEnum):
    """Outcome of one template: 0 matched, else why it was refused."""

    OK = 0
    NO_DATA = 1  # the template or its search window leaves one of the images
    FLAT = 2  # too little structure in the template
    LOW_SCORE = 3  # the best correlation is too low to trust
    EDGE_PEAK = 4  # the peak is on the border of the searched offsets
    AMBIGUOUS = 5  # another peak nearly as high (a repeated pattern)


@dataclass(frozen=True)
class MultimodalConfig:
    """Settings of :func:`match_points`: the descriptor's ``orientations`` and smoothing
    ``sigma_cells``; the template's half size ``half_cells``; the search radius
    ``radius_cells`` around the predicted offset; the refusals: ``min_score`` (correlation of
    the descriptors), ``max_ratio`` (second peak over first, the second at least
    ``exclusion_cells`` away), ``min_structure`` (the template's mean gradient energy over
    the image's median, below which it is flat); ``min_used``: the share of a template's cells
    that must remain when some are ignored."""

    orientations: int = 9
    sigma_cells: float = 1.0
    half_cells: int = 16
    radius_cells: int = 6
    min_score: float = 0.35
    max_ratio: float = 0.9
    exclusion_cells: int = 3
    min_structure: float = 0.5
    min_used: float = 0.2

    def __post_init__(self) -> None:
        if self.orientations < 3 or self.half_cells < 4 or self.radius_cells < 2:
            raise InputError("multimodal matching needs >= 3 orientations, a template half "
                             "size >= 4 cells and a search radius >= 2 cells")
        if not (0 < self.min_score < 1 and 0 < self.max_ratio <= 1):
            raise InputError("min_score must be in (0, 1) and max_ratio in (0, 1]")


@dataclass(frozen=True, eq=False)
class MultimodalMatches:
    """Per template centre ``(i, j)`` (grid indices in image A): the offset ``(di, dj)``
    (cells) to its conjugate in image B, the peak ``score``, the second peak's ``ratio`` and
    the ``status``; the offsets are NaN unless OK."""

    i: FloatArray
    j: FloatArray
    di: FloatArray
    dj: FloatArray
    score: FloatArray
    ratio: FloatArray
    status: NDArray[np.int8]

    @property
    def ok(self) -> NDArray[np.bool_]:
        return self.status == MatchStatus.OK

    def counts(self) -> dict[str, int]:
        return {s.name: int((self.status == s).sum()) for s in MatchStatus
                if (self.status == s).any()}


def gradient_energy(image: FloatArray, sigma_cells: float = 1.0) -> FloatArray:
    """Smoothed squared gradient magnitude (NaN cells: 0), the structure measure of a
    template, relative to the image's median over valid cells."""
    valid, gx, gy = _gradients(image)
    e = cv2.GaussianBlur(gx * gx + gy * gy, (0, 0), sigma_cells).astype(np.float64)
    med = np.median(e[valid]) if valid.any() else 1.0
    return np.where(valid, e / max(med, 1e-30), 0.0)


def match_points(desc_a: NDArray[np.float32], desc_b: NDArray[np.float32],
                 valid_a: NDArray[np.bool_], valid_b: NDArray[np.bool_],
                 structure_a: FloatArray, centres: tuple[ArrayLike, ArrayLike],
                 prior: tuple[ArrayLike, ArrayLike], cfg: MultimodalConfig = MultimodalConfig(),
                 ignore_a: NDArray[np.bool_] | None = None) -> MultimodalMatches:
    """Each template of ``desc_a`` centred at ``centres`` (integer grid indices) searched in
    ``desc_b`` within ``cfg.radius_cells`` of the offset ``prior`` (cells, per centre or one
    for all); ``valid_a``, ``valid_b``: where each image has data (a masked cell, described
    as 0, is still valid); ``structure_a`` (:func:`gradient_energy`, 0 where masked) refuses
    flat templates; ``ignore_a``: cells of image A left out of every score (where the two
    sensors see a feature at different places, e.g. next to a height step), a template with
    fewer than ``cfg.min_used`` of its cells left is NO_DATA."""
    ci = np.atleast_1d(np.asarray(centres[0])).astype(int)
    cj = np.atleast_1d(np.asarray(centres[1])).astype(int)
    pi = np.broadcast_to(np.asarray(prior[0], float), ci.shape)
    pj = np.broadcast_to(np.asarray(prior[1], float), ci.shape)
    n = ci.size
    out = {k: np.full(n, np.nan) for k in ("di", "dj", "score", "ratio")}
    status = np.zeros(n, np.int8)
    hw, rad = cfg.half_cells, cfg.radius_cells
    _, nr, nc = desc_a.shape
    for k in range(n):
        i, j = ci[k], cj[k]
        oi, oj = round(float(pi[k])), round(float(pj[k]))
        a0i, a0j, a1i, a1j = i - hw, j - hw, i + hw + 1, j + hw + 1
        b0i, b0j = a0i + oi - rad, a0j + oj - rad
        b1i, b1j = a1i + oi + rad, a1j + oj + rad
        if (min(a0i, a0j, b0i, b0j) < 0 or max(a1i, b1i) > nr or max(a1j, b1j) > nc
                or not valid_a[a0i:a1i, a0j:a1j].all()
                or valid_b[b0i:b1i, b0j:b1j].mean() < 0.95):
            status[k] = MatchStatus.NO_DATA
            continue
        use = None if ignore_a is None else ~ignore_a[a0i:a1i, a0j:a1j]
        if use is not None and use.mean() < cfg.min_used:
            status[k] = MatchStatus.NO_DATA
            continue
        structure = structure_a[a0i:a1i, a0j:a1j]
        if (structure.mean() if use is None else structure[use].mean()) < cfg.min_structure:
            status[k] = MatchStatus.FLAT
            continue
        score = channel_ncc(desc_a[:, a0i:a1i, a0j:a1j], desc_b[:, b0i:b1i, b0j:b1j], use)
        pk = np.unravel_index(int(np.argmax(score)), score.shape)
        best = float(score[pk])
        far = score.copy()
        e = cfg.exclusion_cells
        far[max(pk[0] - e, 0):pk[0] + e + 1, max(pk[1] - e, 0):pk[1] + e + 1] = -1.0
        second = float(far.max()) if far.size else -1.0
        out["score"][k] = best
        out["ratio"][k] = second / best if best > 0 else np.inf
        if best < cfg.min_score:
            status[k] = MatchStatus.LOW_SCORE
            continue
        if pk[0] in (0, score.shape[0] - 1) or pk[1] in (0, score.shape[1] - 1):
            status[k] = MatchStatus.EDGE_PEAK
            continue
        if second > cfg.max_ratio * best:
            status[k] = MatchStatus.AMBIGUOUS
            continue
        dc, dr = quadratic_peak(score[pk[0] - 1:pk[0] + 2, pk[1] - 1:pk[1] + 2])
        out["di"][k] = oi - rad + pk[0] + float(dr[0])
        out["dj"][k] = oj - rad + pk[1] + float(dc[0])
    return MultimodalMatches(ci.astype(float), cj.astype(float), out["di"], out["dj"],
                             out["score"], out["ratio"], status)


def template_centres(valid: NDArray[np.bool_], half_cells: int, spacing_cells: int
                     ) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """Centres of templates on a regular grid ``spacing_cells`` apart whose whole template
    lies on valid cells."""
    nr, nc = valid.shape
    i = np.arange(half_cells, nr - half_cells, spacing_cells)
    j = np.arange(half_cells, nc - half_cells, spacing_cells)
    I, J = (a.ravel() for a in np.meshgrid(i, j, indexing="ij"))
    if I.size == 0:
        return I, J
    # valid templates: the count of invalid cells in the box, from an integral image
    bad = np.pad(np.cumsum(np.cumsum(~valid, 0), 1), ((1, 0), (1, 0)))
    h = half_cells
    n_bad = (bad[I + h + 1, J + h + 1] - bad[I - h, J + h + 1] - bad[I + h + 1, J - h]
             + bad[I - h, J - h])
    keep = n_bad == 0
    return I[keep], J[keep]


def splat(col: FloatArray, row: FloatArray, weight: FloatArray,
          shape: tuple[int, int]) -> NDArray[np.float32]:
    """The weights at fractional image positions (col, row) accumulated into an image of
    ``shape`` (rows, cols), each spread bilinearly over its four pixels (sum and centroid
    kept); positions off the image add nothing."""
    col, row, w = (np.ravel(np.asarray(a, dtype=np.float64)) for a in (col, row, weight))
    ok = np.isfinite(col) & np.isfinite(row) & np.isfinite(w) & (w != 0)
    ok &= (col > -1) & (row > -1) & (col < shape[1]) & (row < shape[0])
    col, row, w = col[ok], row[ok], w[ok]
    ci, ri = np.floor(col).astype(np.int64), np.floor(row).astype(np.int64)
    fc, fr = col - ci, row - ri
    width = shape[1] + 2  # one pixel of margin each side, cut at the end
    idx = (ri + 1) * width + ci + 1
    out = np.zeros((shape[0] + 2) * width)
    for step, wt in ((0, (1 - fr) * (1 - fc)), (1, (1 - fr) * fc), (width, fr * (1 - fc)),
                     (width + 1, fr * fc)):
        out += np.bincount(idx + step, weights=w * wt, minlength=out.size)
    return out.reshape(shape[0] + 2, width)[1:-1, 1:-1].astype(np.float32)


def radar_shadow(h_m: FloatArray, towards_cells: tuple[float, float],
                 rise_m_per_cell: float) -> NDArray[np.bool_]:
    """Cells of a height grid hidden from a radar: somewhere towards the radar (the unit
    step ``towards_cells`` = (rows, cols) on the grid) the surface rises above the line of
    sight, which climbs ``rise_m_per_cell`` (the cell size over tan(incidence)) per cell.
    Marched in half cells as far as the grid's height range needs; NaN heights hide
    nothing."""
    h = np.asarray(h_m, dtype=np.float64)
    finite = np.isfinite(h)
    if not finite.any() or rise_m_per_cell <= 0:
        return np.zeros(h.shape, bool)
    span = float(np.nanmax(h) - np.nanmin(h))
    z = np.where(finite, h, -np.inf).astype(np.float32)
    ii, jj = np.mgrid[0:h.shape[0], 0:h.shape[1]].astype(np.float32)
    hidden = np.zeros(h.shape, bool)
    k = 1
    while 0.5 * k * rise_m_per_cell <= span:
        d = 0.5 * k
        ahead = cv2.remap(z, jj + np.float32(d * towards_cells[1]),
                          ii + np.float32(d * towards_cells[0]), cv2.INTER_LINEAR,
                          borderMode=cv2.BORDER_CONSTANT, borderValue=float("-inf"))
        hidden |= ahead > h + d * rise_m_per_cell
        k += 1
    return hidden & finite


def quantile_lut(values: FloatArray, target: FloatArray, n_bins: int = 32
                 ) -> tuple[FloatArray, FloatArray]:
    """The median of ``target`` per quantile bin of ``values`` (both finite where used):
    ``(edges, lut)`` for :func:`apply_lut`. How the grey level of one image maps to the
    other's where the two see different physics (a forest dark in the optical, bright in the
    radar), learnt from the images themselves; an empty bin takes its neighbour's value."""
    ok = np.isfinite(values) & np.isfinite(target)
    if ok.sum() < n_bins:
        raise InputError(f"{int(ok.sum())} values to learn a {n_bins}-bin grey-level table")
    v, t = values[ok], target[ok]
    edges = np.quantile(v, np.linspace(0.0, 1.0, n_bins + 1))
    b = np.clip(np.searchsorted(edges, v, side="right") - 1, 0, n_bins - 1)
    lut = np.full(n_bins, np.nan)
    for k in range(n_bins):
        if (b == k).any():
            lut[k] = np.median(t[b == k])
    filled = np.flatnonzero(np.isfinite(lut))
    lut = np.interp(np.arange(n_bins), filled, lut[filled])
    return edges, lut


def apply_lut(values: FloatArray, edges: FloatArray, lut: FloatArray) -> FloatArray:
    """The table of :func:`quantile_lut` applied (NaN stays NaN)."""
    b = np.clip(np.searchsorted(edges, values, side="right") - 1, 0, lut.size - 1)
    return np.where(np.isfinite(values), lut[b], np.nan)


@dataclass(frozen=True)
class ElevatedClass:
    """The optical pair's surface sharpened: the DSM sees height steps through its matching
    window (a blur of ``blur_m``); the optical image sees them sharp, as the edges of a
    class of grey levels (``dark``: darker than the ``percentile``-th percentile, else
    brighter) standing ``height_m`` above the rest, chosen where it explains most of the
    DSM's detail (``r2``, the share of the DSM's variance finer than ``highpass_m``); the
    DSM gets back that class's sharp edges. ``height_m`` 0: no class explains the DSM as
    trees or roofs would (``r2`` under :data:`MIN_R2`, or a class taller than
    :data:`MAX_ELEVATED_M`, or blurred as much as the widest blur tried: the shading of
    slopes follows the terrain's relief, not its steps); the DSM is kept as it is."""

    dark: bool
    percentile: float
    blur_m: float
    height_m: float
    r2: float
    highpass_m: float

    def to_dict(self) -> dict[str, float | bool]:
        return {"dark": self.dark, "percentile": self.percentile, "blur_m": self.blur_m,
                "height_m": self.height_m, "r2": self.r2, "highpass_m": self.highpass_m}


MIN_R2 = 0.005  # below it no grey-level class explains the DSM's detail: no sharpening
MAX_ELEVATED_M = 40.0  # trees and roofs: a grey-level class "taller" follows the terrain
BLURS_CELLS = (1.0, 1.5, 2.0, 2.5, 3.0)  # the DSM's blur tried, in its own cells
HIGHPASS_CELLS = 12.5  # the detail fitted: finer than this many DSM cells (250 m at 20 m)


def _blur(z: FloatArray, sigma_cells: float) -> FloatArray:
    return cv2.GaussianBlur(np.asarray(z, np.float32), (0, 0), float(sigma_cells)
                            ).astype(np.float64)


def sharpened_surface(dsm_m: FloatArray, optical: FloatArray, cell_m: float, dsm_cell_m: float,
                      max_fit_cells: int = 512
                      ) -> tuple[FloatArray, ElevatedClass, NDArray[np.bool_]]:
    """The DSM (a grid of ``cell_m``, NaN where unknown) with the sharp edges of the grey
    level class of ``optical`` (the same grid) that explains its detail (see
    :class:`ElevatedClass`): ``dsm + height (M - G_blur M)``, M the class's mask, its height
    and the DSM's blur (1 to 3 of its cells, ``dsm_cell_m``) fitted by least squares on the
    DSM's detail finer than :data:`HIGHPASS_CELLS` of its cells, over a window of at most
    ``max_fit_cells`` square in the middle of the known cells. A step blurred by 3 cells
    lies within that detail; the terrain's relief mostly does not (a detail of 1 km held
    the slopes of a mountain scene, where the trees were 0.4 % of it and no class was
    found). NaN stays NaN. Also the cells of the other class away from the elevated one
    (the bare ground: everywhere when there is no class)."""
    known_all = np.isfinite(dsm_m) & np.isfinite(optical)
    hp = HIGHPASS_CELLS * dsm_cell_m / cell_m
    o_all = _blur(np.where(np.isfinite(optical), optical, np.nanmedian(optical)),
                  max(0.5 * dsm_cell_m / cell_m, 0.5))
    none = ElevatedClass(True, 50.0, 0.0, 0.0, 0.0, hp * cell_m)
    everywhere = np.ones(np.shape(dsm_m), bool)
    if known_all.sum() < 100:
        return dsm_m, none, everywhere
    rows, cols = np.flatnonzero(known_all.any(axis=1)), np.flatnonzero(known_all.any(axis=0))
    ci, cj = (rows[0] + rows[-1]) // 2, (cols[0] + cols[-1]) // 2
    half = max_fit_cells // 2
    win = (slice(max(ci - half, 0), ci + half), slice(max(cj - half, 0), cj + half))
    known, o = known_all[win], o_all[win]
    w = known.astype(np.float64)
    w_blur = np.maximum(_blur(w, hp), 1e-6)

    def detail(z: FloatArray) -> FloatArray:  # high-pass normalised over the known cells
        return (z - _blur(z * w, hp) / w_blur)[known]

    if known.sum() < 100:
        return dsm_m, none, everywhere
    d = detail(np.where(known, dsm_m[win], 0.0))
    d -= d.mean()
    best = (0.0, 50.0, 1.0, 0.0, 0.0)
    for pct in range(10, 91, 5):
        threshold = float(np.percentile(o[known], pct))
        mask = (o < threshold).astype(np.float64)
        for blur in BLURS_CELLS:
            x = detail(_blur(mask, blur * dsm_cell_m / cell_m))
            x -= x.mean()
            a = float(x @ d / max(float(x @ x), 1e-12))
            r2 = a * a * float(x @ x) / max(float(d @ d), 1e-12)
            if r2 > best[0]:
                best = (r2, float(pct), blur, a, threshold)
    r2, pct, blur, a, threshold = best
    cls = ElevatedClass(a > 0, pct, blur * dsm_cell_m, abs(a), r2, hp * cell_m)
    if r2 < MIN_R2 or abs(a) > MAX_ELEVATED_M or blur == BLURS_CELLS[-1]:
        return dsm_m, replace(cls, height_m=0.0), everywhere
    mask = (o_all < threshold).astype(np.float64)
    elevated = mask if a > 0 else 1.0 - mask
    ground = _blur(elevated, 2.0 * blur * dsm_cell_m / cell_m) < 0.05
    return dsm_m + a * (mask - _blur(mask, blur * dsm_cell_m / cell_m)), cls, ground


def radar_step(project: Project, localize: Localize, lon: float, lat: float, h: float,
               cell_m: float) -> tuple[tuple[float, float], float]:
    """The unit step towards the radar on a lon/lat grid (rows go south) and the rise of its
    line of sight per cell of ``cell_m``, at one ground point."""
    c, r = project(np.array([lon]), np.array([lat]), np.array([h + 10.0]))
    lon1, lat1 = localize(c, r, np.array([h]))  # a raised point's pixel: nearer the radar
    mx, my = metres_per_degree(lat)
    east, north = (float(lon1[0]) - lon) * mx / 10.0, (float(lat1[0]) - lat) * my / 10.0
    cot_incidence = float(np.hypot(east, north))
    return (-north / cot_incidence, east / cot_incidence), cot_incidence * cell_m
