"""Tie points over N images (*tracks*): each point's pixel in every image that sees it, the
tracks chained from the tie points of pairs of images, and each track's equations on the
models' corrections with its ground eliminated (:func:`fit_group`, :func:`equations_of`; the
joint relative orientation, :mod:`core.orientation.multiview`, solves them).

Tie points are matched pair by pair; a point the same pixel of one image ties to two others (the
fixed image's interest points matched into each of the other views, say) is one ground point
seen three times: :func:`tracks_from_pairs` joins such points into one track, so that the joint
relative orientation (:mod:`core.orientation.multiview`) can ask its rays to meet in one point.
No I/O here.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from core.errors import InputError
from core.sensors.base import SensorModel

FloatArray = NDArray[np.float64]
LONLAT_STEP_DEG = 1e-5  # ~1 m: the step of the projections' lon/lat derivatives
#: a target whose epipolar curve moves less than this per metre of height sees no height
MIN_RATE_PX_PER_M = 1e-5  # B/H 4e-4 in 40 m pixels, 1e-5 in 1 m ones


@dataclass(frozen=True, eq=False)
class Tracks:
    """Tie points over N images: ``col``, ``row`` (n, N), 0-based pixels, NaN in the images
    that do not see the point (each point seen in at least two); ``h0_m`` (n,) a first
    height (ellipsoidal metres, e.g. from a reference DEM)."""

    col: FloatArray
    row: FloatArray
    h0_m: FloatArray

    def __post_init__(self) -> None:
        col = np.atleast_2d(np.asarray(self.col, dtype=np.float64))
        row = np.atleast_2d(np.asarray(self.row, dtype=np.float64))
        if col.shape != row.shape or col.shape[1] < 2:
            raise InputError(f"tracks need columns and rows of one shape (n, N >= 2), got "
                             f"{col.shape} and {row.shape}")
        h = np.broadcast_to(np.asarray(self.h0_m, dtype=np.float64), col.shape[:1]).copy()
        seen = np.isfinite(col) & np.isfinite(row)
        if np.any(seen.sum(axis=1) < 2):
            raise InputError("a tie point is seen in fewer than two images; give each point "
                             "in two or more")
        object.__setattr__(self, "col", col)
        object.__setattr__(self, "row", row)
        object.__setattr__(self, "h0_m", h)

    @property
    def n(self) -> int:
        return int(self.col.shape[0])

    @property
    def n_images(self) -> int:
        return int(self.col.shape[1])

    @property
    def seen(self) -> NDArray[np.bool_]:
        return np.isfinite(self.col) & np.isfinite(self.row)



@dataclass(frozen=True, eq=False)
class PairTies:
    """Tie points between images ``i`` and ``j``: pixels ``col_i``, ``row_i`` in image ``i``
    and ``col_j``, ``row_j`` in image ``j``, and a first height each (``h0_m``; NaN when
    unknown)."""

    i: int
    j: int
    col_i: FloatArray
    row_i: FloatArray
    col_j: FloatArray
    row_j: FloatArray
    h0_m: FloatArray

    def __post_init__(self) -> None:
        if self.i == self.j or min(self.i, self.j) < 0:
            raise InputError(f"a pair's tie points need two different images, got {self.i} "
                             f"and {self.j}")
        arrays = [np.atleast_1d(np.asarray(getattr(self, k), dtype=np.float64)).ravel()
                  for k in ("col_i", "row_i", "col_j", "row_j")]
        n = arrays[0].size
        h = np.broadcast_to(np.asarray(self.h0_m, dtype=np.float64), (n,)).copy()
        if any(a.size != n for a in arrays):
            raise InputError(f"tie points of images {self.i} and {self.j}: columns and rows "
                             "differ in length")
        for k, a in zip(("col_i", "row_i", "col_j", "row_j"), arrays, strict=True):
            object.__setattr__(self, k, a)
        object.__setattr__(self, "h0_m", h)

    @property
    def n(self) -> int:
        return int(self.col_i.size)


def tracks_from_pairs(n_images: int, pairs: Sequence[PairTies], h_default_m: float = 0.0
                      ) -> tuple[Tracks, list[NDArray[np.intp]]]:
    """The pairs' tie points chained into tracks: points that share a pixel (the same
    coordinates, exactly) of an image are one track. A chain that would give one image two
    different pixels is split back into its pairs' points. Returns the tracks (first height:
    the mean of the pairs' finite ones, else ``h_default_m``) and, for each pair, the track
    of each of its points."""
    if not pairs:
        raise InputError("no tie points: give the tie points of at least one pair")
    if any(max(p.i, p.j) >= n_images for p in pairs):
        raise InputError(f"tie points name an image beyond the {n_images} given")
    img = np.concatenate([np.r_[np.full(p.n, p.i), np.full(p.n, p.j)] for p in pairs])
    col = np.concatenate([np.r_[p.col_i, p.col_j] for p in pairs])
    row = np.concatenate([np.r_[p.row_i, p.row_j] for p in pairs])
    keys, node = np.unique(np.stack([img.astype(np.float64), col, row], axis=1), axis=0,
                           return_inverse=True)
    node = node.ravel()
    half = np.concatenate([np.r_[np.ones(p.n, bool), np.zeros(p.n, bool)] for p in pairs])
    a, b = node[half], node[~half]  # the two ends of every observation, in the pairs' order
    n_nodes = keys.shape[0]
    graph = coo_matrix((np.ones(a.size), (a, b)), shape=(n_nodes, n_nodes))
    _, comp = connected_components(graph, directed=False)
    node_img = keys[:, 0].astype(np.intp)
    per_image = np.zeros((comp.max() + 1, n_images), np.intp)
    np.add.at(per_image, (comp, node_img), 1)
    ok = (per_image <= 1).all(axis=1)  # components that give no image two pixels
    h = np.concatenate([p.h0_m for p in pairs])
    edge_comp = comp[a]
    edge_track = np.full(a.size, -1, np.intp)
    good = np.flatnonzero(ok)
    track_of_comp = np.full(comp.max() + 1, -1, np.intp)
    track_of_comp[good] = np.arange(good.size)
    use = ok[edge_comp]
    edge_track[use] = track_of_comp[edge_comp[use]]
    split = np.flatnonzero(~use)  # observations of split chains: one track each
    edge_track[split] = good.size + np.arange(split.size)
    n_tracks = good.size + split.size
    tc, tr = np.full((n_tracks, n_images), np.nan), np.full((n_tracks, n_images), np.nan)
    for ends in (a, b):
        tc[edge_track, node_img[ends]] = keys[ends, 1]
        tr[edge_track, node_img[ends]] = keys[ends, 2]
    finite = np.isfinite(h)
    total = np.bincount(edge_track[finite], weights=h[finite], minlength=n_tracks)
    count = np.bincount(edge_track[finite], minlength=n_tracks)
    h0 = np.where(count > 0, total / np.maximum(count, 1), h_default_m)
    starts = np.cumsum([0] + [p.n for p in pairs])
    return Tracks(tc, tr, h0), [edge_track[starts[k]:starts[k + 1]]
                                for k in range(len(pairs))]


# ---------------------------------------------------------------------------- equations


@dataclass(frozen=True, eq=False)
class TrackGroup:
    """The tracks seen by one set of images: ``idx`` into the tracks, their ``source`` image
    and ``targets``."""

    idx: NDArray[np.intp]
    source: int
    targets: tuple[int, ...]

    @property
    def k(self) -> int:
        return len(self.targets)


@dataclass(frozen=True, eq=False)
class GroupFit:
    """A group's tracks on their epipolar curves: heights, ground (lon, lat), residuals
    (n, k, 2) measured - curve, curve rates D (n, k, 2) px per metre, unit tangents and
    normals (n, k, 2), and the ``2 k - 1`` equations ``y`` (n, 2k - 1) with the along
    combinations ``alpha`` (n, k - 1, k)."""

    h_m: FloatArray
    lon_deg: FloatArray
    lat_deg: FloatArray
    residual: FloatArray
    rate: FloatArray
    tangent: FloatArray
    normal: FloatArray
    alpha: FloatArray
    y: FloatArray

    @property
    def speed(self) -> FloatArray:
        return np.linalg.norm(self.rate, axis=2)


def track_groups(tracks: Tracks, fixed: int) -> list[TrackGroup]:
    """The tracks grouped by the images that see them (in the order of their patterns)."""
    seen = tracks.seen
    patterns, inverse = np.unique(seen, axis=0, return_inverse=True)
    out = []
    for g, pattern in enumerate(patterns):
        views = np.flatnonzero(pattern)
        source = fixed if pattern[fixed] else int(views[0])
        out.append(TrackGroup(np.flatnonzero(inverse.ravel() == g), source,
                          tuple(int(v) for v in views if v != source)))
    return out


def _curves(models: Sequence[SensorModel], g: TrackGroup, col: FloatArray, row: FloatArray,
            h: FloatArray, dh: float) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """E_j(h) (n, k, 2) in every target, dE_j/dh (n, k, 2) by a central difference, and the
    source ray's ground point (lon, lat) at h."""
    n = col.size
    hh = np.concatenate([h, h + dh, h - dh])
    lon, lat = models[g.source].localize(np.concatenate([col, col, col]),
                                         np.concatenate([row, row, row]), hh)
    e = np.empty((n, g.k, 2))
    d = np.empty((n, g.k, 2))
    for k, j in enumerate(g.targets):
        c, r = models[j].project(lon, lat, hh)
        e[:, k] = np.stack([c[:n], r[:n]], axis=1)
        d[:, k] = np.stack([c[n:2 * n] - c[2 * n:], r[n:2 * n] - r[2 * n:]], axis=1) / (2 * dh)
    return e, d, lon[:n], lat[:n]


def _along_basis(speed: FloatArray) -> FloatArray:
    """(n, k - 1, k): orthonormal combinations of the targets' along-curve residuals that a
    height change leaves alone (orthogonal to the curves' speeds): the columns 2..k of the
    Householder reflection that takes the first axis to ``speed / |speed|``."""
    k = speed.shape[1]
    v = speed / np.linalg.norm(speed, axis=1, keepdims=True)
    u = v.copy()
    u[:, 0] -= 1.0
    norm2 = np.sum(u**2, axis=1)
    u = u / np.sqrt(np.where(norm2 > 0, norm2, 1.0))[:, None]
    house = np.eye(k)[None] - 2.0 * u[:, :, None] * u[:, None, :]
    return np.transpose(house[:, :, 1:], (0, 2, 1))


def fit_group(models: Sequence[SensorModel], g: TrackGroup, col_px: FloatArray,
              row_px: FloatArray, h0_m: ArrayLike, *, dh_m: float = 10.0, max_iter: int = 10,
              tol_m: float = 1e-3) -> GroupFit:
    """Each track of the group (pixels ``col_px``, ``row_px`` (n, N) of all the tracks, e.g.
    :attr:`Tracks.col`) at its height along its source ray, closest to its targets' pixels
    together, and its equations (module docstring). With one target (a pair), the height
    and y-parallax of :func:`core.orientation.epipolar.epipolar_fit`, which is this."""
    col, row = col_px[g.idx, g.source], row_px[g.idx, g.source]
    obs = np.stack([col_px[g.idx][:, g.targets], row_px[g.idx][:, g.targets]], axis=2)
    h = np.broadcast_to(np.asarray(h0_m, dtype=np.float64), col.shape).copy()
    e, d, _, _ = _curves(models, g, col, row, h, dh_m)
    # a target on the source's own lines of sight (one pass's consecutive scenes) sees no
    # height: its rate is 0 and both its components are observations
    flat = np.linalg.norm(d, axis=2) < MIN_RATE_PX_PER_M
    if np.any(np.all(flat, axis=1)):
        raise InputError("two images look along the same direction at some tie points (no "
                         "parallax with height): they are not a stereo pair")
    for _ in range(max_iter):
        d = np.where(flat[..., None], 0.0, d)
        step = np.einsum("nki,nki->n", d, obs - e) / np.einsum("nki,nki->n", d, d)
        h += step
        e, d, lon, lat = _curves(models, g, col, row, h, dh_m)
        if np.max(np.abs(step)) < tol_m:
            break
    d = np.where(flat[..., None], 0.0, d)
    speed = np.linalg.norm(d, axis=2)
    t = np.where(flat[..., None], np.array([1.0, 0.0]),
                 d / np.where(flat, 1.0, speed)[:, :, None])
    nrm = np.stack([-t[..., 1], t[..., 0]], axis=2)
    res = obs - e
    parallax = np.einsum("nki,nki->nk", nrm, res)
    alpha = _along_basis(speed) if g.k > 1 else np.zeros((col.size, 0, 1))
    along = np.einsum("nlk,nk->nl", alpha, np.einsum("nki,nki->nk", t, res))
    return GroupFit(h, lon, lat, res, d, t, nrm, alpha, np.concatenate([parallax, along],
                                                                         axis=1))


def _lonlat_design(model: SensorModel, lon: FloatArray, lat: FloatArray, h: FloatArray
                   ) -> FloatArray:
    """d(col, row)/d(lon, lat) (n, 2, 2), pixels per degree, by central differences."""
    s = LONLAT_STEP_DEG
    n = lon.size
    c, r = model.project(np.concatenate([lon + s, lon - s, lon, lon]),
                         np.concatenate([lat, lat, lat + s, lat - s]), np.tile(h, 4))
    c, r = np.asarray(c).reshape(4, n), np.asarray(r).reshape(4, n)
    out = np.empty((n, 2, 2))
    out[:, 0, 0], out[:, 1, 0] = (c[0] - c[1]) / (2 * s), (r[0] - r[1]) / (2 * s)
    out[:, 0, 1], out[:, 1, 1] = (c[2] - c[3]) / (2 * s), (r[2] - r[3]) / (2 * s)
    return out


def motion(models: Sequence[SensorModel], g: TrackGroup, fit: GroupFit,
           offsets: dict[int, tuple[int, int]], n_params: int) -> FloatArray:
    """dE_j/dp (n, k, 2, P): how the parameters move each target's curve point relative to its
    measurement; a target's own parameters move its projection, the source's move the ray
    (the ground point slides to keep projecting onto the source pixel, at the same height)."""
    n = fit.h_m.size
    out = np.zeros((n, g.k, 2, n_params))
    src = offsets.get(g.source)
    if src is not None:
        a0 = _lonlat_design(models[g.source], fit.lon_deg, fit.lat_deg, fit.h_m)
        j0 = np.asarray(models[g.source].jacobian(fit.lon_deg, fit.lat_deg, fit.h_m))
        ground = -np.linalg.solve(a0, j0)  # d(lon, lat)/dp of the source ray: (n, 2, p0)
    for k, j in enumerate(g.targets):
        if j in offsets:
            lo, hi = offsets[j]
            out[:, k, :, lo:hi] = models[j].jacobian(fit.lon_deg, fit.lat_deg, fit.h_m)
        if src is not None:
            aj = _lonlat_design(models[j], fit.lon_deg, fit.lat_deg, fit.h_m)
            out[:, k, :, src[0]:src[1]] = aj @ ground
    return out


def equations_of(fit: GroupFit, m: FloatArray) -> FloatArray:
    """d(equations)/dp (n, 2k - 1, P) from the curve motions ``m`` (:func:`motion`)."""
    across = -np.einsum("nki,nkip->nkp", fit.normal, m)
    along = -np.einsum("nlk,nki,nkip->nlp", fit.alpha, fit.tangent, m)
    return np.concatenate([across, along], axis=1)
