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
dependence kept). No I/O here.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from enum import IntEnum

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.errors import InputError
from core.geodesy import metres_per_degree
from core.matching.peaks import quadratic_peak

FloatArray = NDArray[np.float64]
Project = Callable[[FloatArray, FloatArray, FloatArray], tuple[FloatArray, FloatArray]]


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
    # bilinear across the lattice: per output node, the lattice cell and the weights
    ii, jj = np.arange(ni, dtype=float), np.arange(nj, dtype=float)
    ci = np.clip(np.searchsorted(li, ii, side="right") - 1, 0, li.size - 2)
    cj = np.clip(np.searchsorted(lj, jj, side="right") - 1, 0, lj.size - 2)
    wi = ((ii - li[ci]) / (li[ci + 1] - li[ci]))[:, None]
    wj = ((jj - lj[cj]) / (lj[cj + 1] - lj[cj]))[None, :]
    I0, J0 = ci[:, None], cj[None, :]

    def upsample(v: FloatArray) -> FloatArray:
        return ((1 - wi) * ((1 - wj) * v[I0, J0] + wj * v[I0, J0 + 1])
                + wi * ((1 - wj) * v[I0 + 1, J0] + wj * v[I0 + 1, J0 + 1]))

    t = (h - levels[1]) / (0.5 * (hi - lo))  # -1 at lo, 0 mid, +1 hi
    lagrange = (0.5 * t * (t - 1), 1 - t * t, 0.5 * t * (t + 1))
    col = sum(w * upsample(c) for w, (c, _) in zip(lagrange, at_levels, strict=True))
    row = sum(w * upsample(r) for w, (_, r) in zip(lagrange, at_levels, strict=True))
    return col, row


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
