"""SAR-optical conjugate points on a common ground grid, the first step of the SAR-optical
ground control of :mod:`core.orientation.sar_gcps` (Goncalves 2002).

**On the reference** (:func:`match_sar_optical`). Both images are resampled
onto one ground grid (cells of the SAR's ground spacing) at the reference DEM's heights,
through the optical image's approximate model and the SAR's delivered one, and matched with
the oriented-gradient descriptor of :mod:`core.matching.multimodal`: a few large templates
first (the scene's offset, up to ``max_offset_m``), then a template every ``spacing_cells``
cells around it. A match gives an optical pixel (the template's centre) and a SAR pixel
(where its content is in the SAR image). This is biased where the ground has height steps:
at a forest edge the radar lays the canopy over the field in front of it and leaves a dark
gap behind, in the same pixels, which no resampling undoes (an orthoimage cannot unmix a
pixel): the radar's edges sit towards the radar, along its range, the direction of the
height parallax, so the calibration below cannot tell them from the optical model's error.
Measured on the simulator (``bench/validation/sar_gcps.py``, patchy forest 17.5 m tall): 0.7-1.0
radar pixel on the flat ``tiny`` and ``spot`` pairs, 0.97 with the optical image resampled
on the true surface, 0.1 with the SAR rendered from the bare terrain.

**Altimetric control** (:func:`reliable_reference`): where the reference's heights can be
trusted (no void next to it, a gentle slope).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Protocol

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.dem import GeoDEM, sample_bilinear
from core.errors import InputError
from core.geodesy import metres_per_degree
from core.matching import multimodal as mm
from core.sensors.base import SensorModel

FloatArray = NDArray[np.float64]

MIN_POINTS = 6  # conjugate points, and of them on altimetric control, to calibrate


class Surface(Protocol):
    """Heights of a surface at lon/lat points (NaN where unknown) and its cell size (m):
    :class:`core.dem.GeoDEM`, or a projected grid read through its CRS."""

    def height_m(self, lon_deg: FloatArray, lat_deg: FloatArray) -> FloatArray: ...

    def cell_size_m(self) -> float: ...


@dataclass(frozen=True)
class SarGcpConfig:
    """Settings of the SAR-optical GCPs (see the module docstring): ``cell_m`` the ground
    grid's cell (default the SAR's ground spacing, read from its model); ``max_offset_m`` the
    largest offset of the optical model searched; ``max_points`` per image (the template
    spacing is widened to keep under it); ``geolocation_sigma_m`` the SAR product's
    geolocation error (1 sigma, horizontal); ``reference_sigma_m`` the reference's height
    error where it is reliable; ``max_slope`` the steepest reference slope of altimetric
    control; ``reject_k`` the blunder threshold in robust sigmas; ``passes``: matches against
    the SAR image predicted from the optical pair's surface (each refines the offset the
    next renders with; used when the surface is given)."""

    cell_m: float | None = None
    max_offset_m: float = 1500.0
    max_points: int = 400
    min_spacing_cells: int = 8
    matching: mm.MultimodalConfig = field(default_factory=mm.MultimodalConfig)
    geolocation_sigma_m: float = 10.0
    reference_sigma_m: float = 5.0
    max_slope: float = 0.15
    reject_k: float = 3.0
    passes: int = 2

    def __post_init__(self) -> None:
        if self.cell_m is not None and not self.cell_m > 0:
            raise InputError(f"the SAR-optical ground cell must be > 0 m (got {self.cell_m})")
        if not (self.max_offset_m > 0 and self.max_points >= 10
                and self.geolocation_sigma_m >= 0 and self.reject_k > 1 and self.passes >= 1):
            raise InputError("SAR GCP settings: need max_offset_m > 0, max_points >= 10, "
                             "geolocation_sigma_m >= 0, reject_k > 1 and passes >= 1")


@dataclass(frozen=True, eq=False)
class GroundImages:
    """Both images on one ground grid: values (NaN outside an image) and each grid node's
    image position (col, row) in each, at the reference heights ``h_m``; ``holes``: cells
    inside the optical side's image where its value is unknown (NaN there too: the SAR
    image predicted from the pair's surface, where that surface has a gap), which templates
    may hold where they are scattered, their scores leaving them out (:func:`template_cells`)."""

    grid: mm.GroundGrid
    h_m: FloatArray
    optical: FloatArray
    optical_pos: tuple[FloatArray, FloatArray]
    sar: FloatArray
    sar_pos: tuple[FloatArray, FloatArray]
    holes: NDArray[np.bool_] | None = None


#: the largest share of a template's cells that may be holes of the prediction
MAX_HOLE_SHARE = 0.25


def template_cells(g: GroundImages, half_cells: int, spacing_cells: int,
                   ignore: NDArray[np.bool_] | None = None
                   ) -> tuple[tuple[NDArray[np.intp], NDArray[np.intp]], NDArray[np.bool_],
                              NDArray[np.bool_] | None]:
    """The templates' centres on ``g`` (:func:`core.matching.multimodal.template_centres`),
    the cells taken as data and those the scores leave out (``ignore``). Templates lie whole
    on data; where the optical side has holes (``g.holes``) that would leave fewer than a
    quarter of the templates that holes in at most :data:`MAX_HOLE_SHARE` of their cells
    give, those are taken, the holes (grown by the two cells
    :func:`core.matching.multimodal.orientation_channels` describes as 0 around a no-data
    cell) left out of their scores: a relative DEM's gaps (shadows, changed ground, water)
    are scattered over a whole scene, and a spot scene's prediction on the Sentinel-1's
    30 m looked cells held one whole template of 25 on the first, coarse grid."""
    valid = np.isfinite(g.optical)
    whole = mm.template_centres(valid, half_cells, spacing_cells)
    if g.holes is None or not g.holes.any():
        return whole, valid, ignore
    ci, cj = mm.template_centres(valid | g.holes, half_cells, spacing_cells)
    n = 2 * half_cells + 1
    share = cv2.boxFilter(g.holes.astype(np.float32), -1, (n, n), normalize=True,
                          borderType=cv2.BORDER_CONSTANT)
    keep = share[ci, cj] <= MAX_HOLE_SHARE
    if whole[0].size >= 0.25 * keep.sum():
        return whole, valid, ignore
    grown = cv2.dilate(g.holes.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
    return (ci[keep], cj[keep]), valid | g.holes, grown if ignore is None else (grown | ignore)


def ground_spacing_m(model: SensorModel, shape: tuple[int, ...], reference: GeoDEM,
                     coarser: bool = True) -> float:
    """The coarser (else the finer) of an image's two ground pixel sizes (m) at its centre,
    at the reference's median height."""
    steps = axis_spacing_m(model, shape, reference)
    return max(steps) if coarser else min(steps)


#: the ground grids of the matching hold at most this many cells (the render grid at the SAR's
#: finer spacing, the matching grid at its coarser): a grid of 36 M cells (a Sentinel-1 GRD's
#: 10 m over a 60 km SPOT scene) took 14 GB for the two images of a pair; past it the SAR image
#: is multilooked (:func:`looked`) until the grid fits
MAX_GRID_CELLS = 10_000_000


@dataclass(frozen=True)
class LookedModel:
    """A SAR model in the pixels of its image averaged over blocks of ``looks`` (rows, cols):
    pixel ``i`` of the looked image covers the pixels ``k i .. k i + k - 1``, its centre
    ``k i + (k - 1) / 2``."""

    base: SensorModel
    looks: tuple[int, int]

    def to_full(self, col: ArrayLike, row: ArrayLike) -> tuple[FloatArray, FloatArray]:
        kr, kc = self.looks
        return (np.asarray(col, float) * kc + 0.5 * (kc - 1),
                np.asarray(row, float) * kr + 0.5 * (kr - 1))

    def project(self, lon_deg: ArrayLike, lat_deg: ArrayLike, h_m: ArrayLike
                ) -> tuple[FloatArray, FloatArray]:
        kr, kc = self.looks
        c, r = self.base.project(lon_deg, lat_deg, h_m)
        return ((np.asarray(c, float) - 0.5 * (kc - 1)) / kc,
                (np.asarray(r, float) - 0.5 * (kr - 1)) / kr)

    def localize(self, col: ArrayLike, row: ArrayLike, h_m: ArrayLike
                 ) -> tuple[FloatArray, FloatArray]:
        return self.base.localize(*self.to_full(col, row), h_m)


def axis_spacing_m(model: SensorModel, shape: tuple[int, ...], reference: GeoDEM
                   ) -> tuple[float, float]:
    """An image's ground pixel size (m) along its rows and along its columns (one row step,
    one column step) at its centre, at the reference's median height."""
    c, r = 0.5 * (shape[1] - 1), 0.5 * (shape[0] - 1)
    h = np.full(3, float(np.nanmedian(reference.h_m)))
    lon, lat = model.localize(np.array([c, c + 1, c]), np.array([r, r, r + 1]), h)
    mx, my = metres_per_degree(lat[0])
    step = np.hypot((lon[1:] - lon[0]) * mx, (lat[1:] - lat[0]) * my)
    return float(step[1]), float(step[0])


def looked(sar: SensorModel, sar_image: NDArray, reference: GeoDEM,
           corners: tuple[FloatArray, FloatArray], max_cells: int | None = None
           ) -> tuple[SensorModel, NDArray[np.float32], tuple[int, int]]:
    """The SAR model and image (amplitude) multilooked, the intensity averaged over blocks of
    whole pixels (the mean of the squared amplitudes, then its root), so that a ground grid
    of the looked image's finer spacing over the lon/lat ``corners`` holds at most
    ``max_cells`` cells (default :data:`MAX_GRID_CELLS`); unchanged (looks (1, 1)) where it
    already does."""
    max_cells = max_cells or MAX_GRID_CELLS
    row_m, col_m = axis_spacing_m(sar, np.shape(sar_image), reference)
    lon, lat = np.asarray(corners[0], float), np.asarray(corners[1], float)
    mx, my = metres_per_degree(float(np.mean(lat)))
    area = (np.ptp(lon) * mx) * (np.ptp(lat) * my)
    need = float(np.sqrt(area / max_cells))
    if min(row_m, col_m) >= need:
        return sar, np.asarray(sar_image), (1, 1)
    kr, kc = max(1, int(np.ceil(need / row_m))), max(1, int(np.ceil(need / col_m)))
    z = np.asarray(sar_image, dtype=np.float32)
    nr, nc = z.shape[0] // kr, z.shape[1] // kc
    if min(nr, nc) < 2:
        return sar, z, (1, 1)
    return LookedModel(sar, (kr, kc)), multilooked(z, (kr, kc)), (kr, kc)


def multilooked(sar_image: NDArray, looks: tuple[int, int]) -> NDArray[np.float32]:
    """An amplitude image averaged in intensity over blocks of ``looks`` (rows, cols) whole
    pixels (the mean of the squared amplitudes, then its root; the last partial blocks
    dropped): the image of :class:`LookedModel`."""
    kr, kc = looks
    z = np.asarray(sar_image, dtype=np.float32)
    nr, nc = z.shape[0] // kr, z.shape[1] // kc
    power = np.square(z[:nr * kr, :nc * kc], dtype=np.float32)
    mean = power.reshape(nr, kr, nc, kc).mean(axis=(1, 3), dtype=np.float64)
    return np.sqrt(mean).astype(np.float32)


def ground_images(optical: SensorModel, optical_image: NDArray, sar: SensorModel,
                  sar_image: NDArray, reference: GeoDEM, corners: tuple[FloatArray, FloatArray],
                  cell_m: float) -> GroundImages:
    """The optical image (grey levels) and the SAR image (log intensity; it is given as
    amplitude) resampled onto the ground grid of ``cell_m`` covering the lon/lat ``corners``,
    at the reference's heights; each image first low-passed to the grid's cell (a Gaussian of
    half a cell, in its own pixels)."""
    grid = mm.GroundGrid.covering(corners[0], corners[1], cell_m)
    lon, lat = grid.nodes()
    h = reference.height_m(lon, lat)
    out = []
    for model, image, log in ((optical, optical_image, False), (sar, sar_image, True)):
        col, row = mm.image_positions(model.project, grid, h)
        z = np.asarray(image, dtype=np.float32)
        if log:
            z = 2.0 * np.log(np.maximum(z, 1.0))
        sigma = 0.5 * cell_m / mm.pixel_size_m(col, row, cell_m)
        if sigma > 0.5:
            z = cv2.GaussianBlur(z, (0, 0), sigma)
        out.append((mm.remap(z, col, row), (col, row)))
    return GroundImages(grid, h, out[0][0], out[0][1], out[1][0], out[1][1])


@dataclass(frozen=True, eq=False)
class SarOpticalMatches:
    """The conjugate points of one optical image and the SAR image: per template, the
    optical pixel, the SAR pixel (NaN unless matched), the grid node's lon/lat and the
    reference height there; ``matches`` the matcher's record; ``offset_cells`` the scene's
    offset found first."""

    matches: mm.MultimodalMatches
    optical_col: FloatArray
    optical_row: FloatArray
    sar_col: FloatArray
    sar_row: FloatArray
    lon_deg: FloatArray
    lat_deg: FloatArray
    h_ref_m: FloatArray
    offset_cells: tuple[float, float]
    cell_m: float


def match_sar_optical(g: GroundImages, cfg: SarGcpConfig,
                      ignore: NDArray[np.bool_] | None = None) -> SarOpticalMatches:
    """Conjugate points of the optical and the SAR image on their common ground grid;
    ``ignore``: grid cells left out of the templates' scores (``bench/validation/sar_gcps.py``
    tries the cells near height steps)."""
    da, db = mm.orientation_channels(g.optical), mm.orientation_channels(g.sar)
    vb = np.isfinite(g.sar)
    structure = mm.gradient_energy(g.optical)
    cell = g.grid.cell_m
    half = max(min(g.grid.shape) // 6, cfg.matching.half_cells)
    coarse = mm.MultimodalConfig(
        orientations=cfg.matching.orientations, sigma_cells=cfg.matching.sigma_cells,
        half_cells=half, radius_cells=max(int(np.ceil(cfg.max_offset_m / cell)), 2),
        min_score=min(cfg.matching.min_score, 0.15), min_structure=0.0)
    (ci, cj), va, ignore_all = template_cells(g, half, half, ignore)
    while ci.size == 0 and half > cfg.matching.half_cells:  # an image known in part only
        half = max(int(0.7 * half), cfg.matching.half_cells)
        coarse = replace(coarse, half_cells=half)
        (ci, cj), va, ignore_all = template_cells(g, half, half, ignore)
    mc = mm.match_points(da, db, va, vb, structure, (ci, cj), (0.0, 0.0), coarse,
                         ignore_a=None if ignore_all is ignore else ignore_all)  # holes only
    if not mc.ok.any():
        raise InputError(
            f"the SAR and the optical image do not match anywhere over the +-"
            f"{cfg.max_offset_m:.0f} m searched ({mc.counts()}): they do not overlap, show "
            "different ground, or the optical model is further off; check the SAR scene")
    offset = (float(np.median(mc.di[mc.ok])), float(np.median(mc.dj[mc.ok])))
    return template_matches(g, (da, db), structure, offset, cfg, ignore)


def template_matches(g: GroundImages, desc: tuple[NDArray[np.float32], NDArray[np.float32]],
                      structure: FloatArray, prior: tuple[float, float], cfg: SarGcpConfig,
                      ignore: NDArray[np.bool_] | None = None) -> SarOpticalMatches:
    """A template every ``spacing`` cells of ``g.optical`` (at most ``cfg.max_points``)
    searched in ``g.sar`` around the offset ``prior`` (cells)."""
    vb = np.isfinite(g.sar)
    hw = cfg.matching.half_cells
    spacing = max(cfg.min_spacing_cells,
                  int(np.ceil(np.sqrt(np.isfinite(g.optical).sum() / cfg.max_points))))
    (ci, cj), va, ignore = template_cells(g, hw, spacing, ignore)
    m = mm.match_points(desc[0], desc[1], va, vb, structure, (ci, cj), prior, cfg.matching,
                        ignore_a=ignore)
    oc, orow = g.optical_pos
    sc, srow = g.sar_pos
    bi, bj = m.i + np.nan_to_num(m.di), m.j + np.nan_to_num(m.dj)
    sar_col = np.where(m.ok, sample_bilinear(sc, bi, bj), np.nan)
    sar_row = np.where(m.ok, sample_bilinear(srow, bi, bj), np.nan)
    lon, lat = g.grid.lonlat(m.i, m.j)
    return SarOpticalMatches(m, oc[ci, cj], orow[ci, cj], sar_col, sar_row, lon, lat,
                             g.h_m[ci, cj], prior, g.grid.cell_m)


def reliable_reference(reference: GeoDEM, lon_deg: FloatArray, lat_deg: FloatArray,
                       max_slope: float) -> NDArray[np.bool_]:
    """Where the reference's height may be control: not next to a void, and a slope (over
    one reference cell each way) under ``max_slope``."""
    mx, my = metres_per_degree(lat_deg)
    _, _, dlon, dlat = reference.axes
    step_lon, step_lat = abs(dlon), abs(dlat)
    h = reference.height_m(lon_deg, lat_deg)
    gx = (reference.height_m(lon_deg + step_lon, lat_deg)
          - reference.height_m(lon_deg - step_lon, lat_deg)) / (2 * step_lon * mx)
    gy = (reference.height_m(lon_deg, lat_deg + step_lat)
          - reference.height_m(lon_deg, lat_deg - step_lat)) / (2 * step_lat * my)
    slope = np.hypot(gx, gy)
    return np.isfinite(h) & np.isfinite(slope) & (slope < max_slope)
