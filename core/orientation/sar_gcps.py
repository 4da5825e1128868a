"""SAR-optical ground control (Goncalves 2002): GCPs for an optical image from a SAR scene of
the same ground, whose geolocation does not depend on attitude.

**Conjugate points** (:func:`match_sar_optical`). Both images are resampled onto one ground
grid (cells of the SAR's ground spacing) at the reference DEM's heights, through the optical
image's approximate model and the SAR's delivered one, and matched with the oriented-gradient
descriptor of :mod:`core.matching.multimodal`: a few large templates first (the scene's
offset, up to ``max_offset_m``), then a template every ``spacing_cells`` cells around it.
A match gives an optical pixel (the template's centre) and a SAR pixel (where its content is
in the SAR image).

**Heights from the SAR-optical parallax** (:func:`parallax_heights`). At a height ``h`` the SAR
pixel's ground point and the optical pixel's ground point differ by ``d(h)``; raising ``h``
moves them apart along one direction ``v`` (metres per metre: the SAR point moves towards the
radar by ``1 / tan(incidence)``, the optical one away from its sensor), so
``d(h) = d(h_ref) + (h - h_ref) v``. The optical model's error adds a field ``a(x)`` smooth
across the scene (affine in the ground coordinates: attitude biases and drifts). Calibrated on
altimetric control, the points where the reference's heights can be trusted (not a void, a
gentle slope), ``a`` is the robust fit of ``d(h_ref)`` there; every point's height is then
the one that brings its ``d(h)`` onto ``a``, known to ``sigma_match / |v|``. The component of
``d`` across ``v`` does not depend on height: a point whose cross component leaves the field
by more than ``reject_k`` robust sigmas is a blunder. Where the reference agrees with the
parallax height (within 3 sigma of both) the two are combined (inverse variance), elsewhere
(canopy, a void, a steep slope: where SRTM is wrong) the parallax height stands alone.

**The GCP** (:func:`sar_control_points`): the SAR pixel localised at that height (the SAR model:
orbit and two times, no attitude), with the optical pixel as its image measurement;
``sigma_xy_m`` from the SAR product's geolocation (``geolocation_sigma_m``), the matching and
the height's uncertainty through the radar's ``1 / tan(incidence)``; ``source: "sar"``.

A common error of the SAR product (its orbit, azimuth time and range delay) passes whole into
the orientation, as the reference DEM's misregistration does for SRTM GCPs.

**A bias the method cannot see.** The matched features are where the grey levels change; at a
height step (a forest edge, a building) the radar and the optical sensor do not see the change
at the same place (the radar lays the canopy top over the ground in front of it, adds the
facing wall's return, and leaves a shadow behind; the optical sensor sees the tree shadows the
sun casts). That offset is along the radar's range, the direction of the height parallax, so
the calibration cannot tell it from the optical model's error. Measured on the simulator
(``bench/bench_sar_gcps.py``, tiny scene of patchy forest 17.5 m tall, ERS-like 80 m pixels):
0.7-1.0 SAR pixel in range, while edges without a height step match to 0.05 pixel.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from core.dem import GeoDEM, sample_bilinear
from core.errors import InputError
from core.geodesy import metres_per_degree
from core.matching import multimodal as mm
from core.points import ControlPoint, ImagePoint
from core.robust import nmad, robust_fit
from core.sensors.base import SensorModel

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class SarGcpConfig:
    """Settings of the SAR-optical GCPs (see the module docstring): ``cell_m`` the ground
    grid's cell (default the SAR's ground spacing, read from its model); ``max_offset_m`` the
    largest offset of the optical model searched; ``max_points`` per image (the template
    spacing is widened to keep under it); ``geolocation_sigma_m`` the SAR product's
    geolocation error (1 sigma, horizontal); ``reference_sigma_m`` the reference's height
    error where it is reliable; ``max_slope`` the steepest reference slope of altimetric
    control; ``reject_k`` the blunder threshold in robust sigmas."""

    cell_m: float | None = None
    max_offset_m: float = 1500.0
    max_points: int = 400
    min_spacing_cells: int = 8
    matching: mm.MultimodalConfig = field(default_factory=mm.MultimodalConfig)
    geolocation_sigma_m: float = 10.0
    reference_sigma_m: float = 5.0
    max_slope: float = 0.15
    reject_k: float = 3.0

    def __post_init__(self) -> None:
        if self.cell_m is not None and not self.cell_m > 0:
            raise InputError(f"the SAR-optical ground cell must be > 0 m (got {self.cell_m})")
        if not (self.max_offset_m > 0 and self.max_points >= 10
                and self.geolocation_sigma_m >= 0 and self.reject_k > 1):
            raise InputError("SAR GCP settings: need max_offset_m > 0, max_points >= 10, "
                             "geolocation_sigma_m >= 0 and reject_k > 1")


@dataclass(frozen=True, eq=False)
class GroundImages:
    """Both images on one ground grid: values (NaN outside an image) and each grid node's
    image position (col, row) in each, at the reference heights ``h_m``."""

    grid: mm.GroundGrid
    h_m: FloatArray
    optical: FloatArray
    optical_pos: tuple[FloatArray, FloatArray]
    sar: FloatArray
    sar_pos: tuple[FloatArray, FloatArray]


def ground_spacing_m(model: SensorModel, shape: tuple[int, ...], reference: GeoDEM) -> float:
    """The coarser of an image's two ground pixel sizes (m) at its centre, at the reference's
    median height."""
    c, r = 0.5 * (shape[1] - 1), 0.5 * (shape[0] - 1)
    h = np.full(3, float(np.nanmedian(reference.h_m)))
    lon, lat = model.localize(np.array([c, c + 1, c]), np.array([r, r, r + 1]), h)
    mx, my = metres_per_degree(lat[0])
    step = np.hypot((lon[1:] - lon[0]) * mx, (lat[1:] - lat[0]) * my)
    return float(step.max())


def _remap(z: NDArray[np.float32], col: FloatArray, row: FloatArray) -> FloatArray:
    """Bilinear values of ``z`` at (col, row) in float32 (OpenCV's remap, NaN outside): the
    images stay in single precision, a 6000-pixel image costs 144 MB, not 288."""
    out = cv2.remap(z, col.astype(np.float32), row.astype(np.float32), cv2.INTER_LINEAR,
                    borderMode=cv2.BORDER_CONSTANT, borderValue=float("nan"))
    inside = (col >= 0) & (col <= z.shape[1] - 1) & (row >= 0) & (row <= z.shape[0] - 1)
    return np.where(inside, out, np.nan)


def _pixel_m(col: FloatArray, row: FloatArray, cell_m: float) -> float:
    """An image's pixel size on the ground (m), from its positions on a grid of ``cell_m``."""
    step = np.hypot(np.diff(col, axis=1), np.diff(row, axis=1))
    return cell_m / max(float(np.nanmedian(step)), 1e-12)


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
        sigma = 0.5 * cell_m / _pixel_m(col, row, cell_m)
        if sigma > 0.5:
            z = cv2.GaussianBlur(z, (0, 0), sigma)
        out.append((_remap(z, col, row), (col, row)))
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
    ``ignore``: grid cells left out of the templates' scores (``bench/bench_sar_gcps.py``
    tries the cells near height steps)."""
    da, db = mm.orientation_channels(g.optical), mm.orientation_channels(g.sar)
    va, vb = np.isfinite(g.optical), np.isfinite(g.sar)
    structure = mm.gradient_energy(g.optical)
    cell = g.grid.cell_m
    half = max(min(g.grid.shape) // 6, cfg.matching.half_cells)
    coarse = mm.MultimodalConfig(
        orientations=cfg.matching.orientations, sigma_cells=cfg.matching.sigma_cells,
        half_cells=half, radius_cells=max(int(np.ceil(cfg.max_offset_m / cell)), 2),
        min_score=min(cfg.matching.min_score, 0.15), min_structure=0.0)
    ci, cj = mm.template_centres(va, half, half)
    mc = mm.match_points(da, db, va, vb, structure, (ci, cj), (0.0, 0.0), coarse)
    if not mc.ok.any():
        raise InputError(
            f"the SAR and the optical image do not match anywhere over the +-"
            f"{cfg.max_offset_m:.0f} m searched ({mc.counts()}): they do not overlap, show "
            "different ground, or the optical model is further off; check the SAR scene")
    offset = (float(np.median(mc.di[mc.ok])), float(np.median(mc.dj[mc.ok])))
    hw = cfg.matching.half_cells
    n_valid = int(va.sum())
    spacing = max(cfg.min_spacing_cells, int(np.ceil(np.sqrt(n_valid / cfg.max_points))))
    ci, cj = mm.template_centres(va, hw, spacing)
    m = mm.match_points(da, db, va, vb, structure, (ci, cj), offset, cfg.matching,
                        ignore_a=ignore)
    oc, orow = g.optical_pos
    sc, srow = g.sar_pos
    bi, bj = m.i + np.nan_to_num(m.di), m.j + np.nan_to_num(m.dj)
    sar_col = np.where(m.ok, sample_bilinear(sc, bi, bj), np.nan)
    sar_row = np.where(m.ok, sample_bilinear(srow, bi, bj), np.nan)
    lon, lat = g.grid.lonlat(m.i, m.j)
    return SarOpticalMatches(m, oc[ci, cj], orow[ci, cj], sar_col, sar_row, lon, lat,
                             g.h_m[ci, cj], offset, cell)


@dataclass(frozen=True, eq=False)
class ParallaxHeights:
    """Per matched point: the height from the parallax (``h_parallax_m``, its 1-sigma
    ``sigma_parallax_m``), the height kept (``h_m``, ``sigma_h_m``; ``from_reference``: the
    reference's height took part), ``inlier`` (not a blunder), ``control`` (used to
    calibrate), ``cross_m`` (the cross-parallax residual), the parallax's sensitivity
    ``m_per_m``, the SAR point's own (``sar_m_per_m``, 1 / tan(incidence)), the ground
    direction towards the radar (``range_direction_en``, east, north) and the matching's noise ``sigma_match_m`` (robust, from the cross
    residuals)."""

    h_parallax_m: FloatArray
    sigma_parallax_m: FloatArray
    h_m: FloatArray
    sigma_h_m: FloatArray
    from_reference: NDArray[np.bool_]
    inlier: NDArray[np.bool_]
    control: NDArray[np.bool_]
    cross_m: FloatArray
    m_per_m: FloatArray
    sar_m_per_m: FloatArray
    range_direction_en: tuple[float, float]
    sigma_match_m: float


def parallax_heights(optical: SensorModel, sar: SensorModel, optical_px: tuple[FloatArray,
                     FloatArray], sar_px: tuple[FloatArray, FloatArray], h_ref_m: FloatArray,
                     reliable: NDArray[np.bool_], cfg: SarGcpConfig) -> ParallaxHeights:
    """Goncalves's heights of conjugate points (see the module docstring); ``reliable``:
    where the reference's height may serve as altimetric control."""
    n = h_ref_m.size
    h0 = np.where(np.isfinite(h_ref_m), h_ref_m, np.nanmedian(h_ref_m))

    def parallax(h: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        ls, as_ = sar.localize(*sar_px, h)
        lo, ao = optical.localize(*optical_px, h)
        mx, my = metres_per_degree(ao)
        sar_m = np.stack([ls * mx, as_ * my], axis=1)
        return np.stack([(ls - lo) * mx, (as_ - ao) * my], axis=1), lo, ao, sar_m

    d0, lon, lat, sar0 = parallax(h0)
    d1, _, _, sar1 = parallax(h0 + 10.0)
    v = (d1 - d0) / 10.0
    sar_move = np.linalg.norm(sar1 - sar0, axis=1) / 10.0  # 1 / tan(incidence)
    towards = np.median(sar1 - sar0, axis=0)  # a raised point moves towards the radar
    range_dir = towards / max(float(np.linalg.norm(towards)), 1e-12)
    s = np.linalg.norm(v, axis=1)
    u = v / s[:, None]
    w = np.stack([-u[:, 1], u[:, 0]], axis=1)
    mx, my = metres_per_degree(float(np.mean(lat)))
    basis = np.stack([np.ones(n), (lon - lon.mean()) * mx / 1e4,
                      (lat - lat.mean()) * my / 1e4], axis=1)
    control = reliable & np.isfinite(h_ref_m) & np.isfinite(d0).all(axis=1)
    inlier = np.isfinite(d0).all(axis=1)
    for _ in range(3):  # blunders out of the calibration, then refit
        if control.sum() < MIN_POINTS:
            raise InputError(f"only {int(control.sum())} SAR-optical points on reliable "
                             f"reference heights ({MIN_POINTS} needed) to calibrate the "
                             "parallax")
        coef = [robust_fit(d0[control, k], basis[control])[0] for k in range(2)]
        field_ = np.stack([basis @ c for c in coef], axis=1)
        cross = np.einsum("ij,ij->i", d0 - field_, w)
        sigma_match = max(nmad(cross[control & inlier]), 1e-3)
        inlier = np.isfinite(cross) & (np.abs(cross) <= cfg.reject_k * sigma_match)
        along = np.einsum("ij,ij->i", field_ - d0, u)  # (h - h_ref) * s
        dh = along / s
        sig_par = sigma_match / s
        agree = np.abs(dh) <= cfg.reject_k * np.hypot(sig_par, cfg.reference_sigma_m)
        control = control & inlier & agree
    h_par = h0 + dh
    agree = np.isfinite(h_ref_m) & (np.abs(dh) <= 3.0 * np.hypot(sig_par,
                                                               cfg.reference_sigma_m))
    wp, wr = 1.0 / sig_par**2, 1.0 / cfg.reference_sigma_m**2
    h = np.where(agree, (wp * h_par + wr * h0) / (wp + wr), h_par)
    sigma_h = np.where(agree, 1.0 / np.sqrt(wp + wr), sig_par)
    return ParallaxHeights(h_par, sig_par, h, sigma_h, agree, inlier, control, cross, s,
                           sar_move, (float(range_dir[0]), float(range_dir[1])),
                           float(sigma_match))


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


def sar_control_points(name: str, sar: SensorModel, m: SarOpticalMatches, hts: ParallaxHeights,
                       cfg: SarGcpConfig, first_id: int = 1) -> tuple[ControlPoint, ...]:
    """The GCPs of one optical image (named ``name``): each inlier SAR pixel localised at its
    height (see the module docstring)."""
    ok = m.matches.ok
    idx = np.flatnonzero(ok)[hts.inlier]
    sel = hts.inlier
    lon, lat = sar.localize(m.sar_col[idx], m.sar_row[idx], hts.h_m[sel])
    sigma_xy = np.sqrt(cfg.geolocation_sigma_m**2 + hts.sigma_match_m**2
                       + (hts.sigma_h_m[sel] * hts.sar_m_per_m[sel])**2)
    points = []
    for k, (i, x, y, h) in enumerate(zip(idx, lon, lat, hts.h_m[sel], strict=True)):
        j = int(np.flatnonzero(sel)[k])
        prov: dict[str, Any] = {
            "image": name, "sar_col": float(m.sar_col[i]), "sar_row": float(m.sar_row[i]),
            "score": float(m.matches.score[i]),
            "h_parallax_m": float(hts.h_parallax_m[j]),
            "h_reference_m": float(m.h_ref_m[i]),
            "height_from": "parallax+reference" if hts.from_reference[j] else "parallax"}
        points.append(ControlPoint(
            first_id + k, float(x), float(y), float(h),
            {name: ImagePoint(float(m.optical_col[i]), float(m.optical_row[i]))},
            float(sigma_xy[k]), float(hts.sigma_h_m[j]), "sar", prov))
    return tuple(points)


@dataclass(frozen=True, eq=False)
class SarImageResult:
    """One optical image against the SAR scene: its conjugate points, their heights and the
    GCPs made of them; ``refused``: why there are none (too few conjugate points or too
    little altimetric control; ``heights`` is then None)."""

    name: str
    matches: SarOpticalMatches
    heights: ParallaxHeights | None
    gcps: tuple[ControlPoint, ...]
    refused: str = ""

    def counts(self) -> dict[str, int]:
        c = self.matches.matches.counts()
        if self.heights is not None:
            c["BLUNDER"] = int((~self.heights.inlier).sum())
        return c


MIN_POINTS = 6  # conjugate points, and of them on altimetric control, to calibrate


def sar_gcps_of_image(name: str, optical: SensorModel, optical_image: NDArray,
                      sar: SensorModel, sar_image: NDArray, reference: GeoDEM,
                      corners: tuple[FloatArray, FloatArray], cfg: SarGcpConfig,
                      first_id: int = 1) -> SarImageResult:
    """The whole method for one optical image (see the module docstring); ``corners``: the
    lon/lat of the image's footprint. No GCP (``refused`` says why) where the images match
    at fewer than :data:`MIN_POINTS` places or too few of them lie on reliable reference
    heights (steep terrain, where the radar's and the sun's shading differ most)."""
    g = ground_images(optical, optical_image, sar, sar_image, reference, corners,
                      cfg.cell_m or ground_spacing_m(sar, np.shape(sar_image), reference))
    m = match_sar_optical(g, cfg)
    ok = m.matches.ok
    if ok.sum() < MIN_POINTS:
        return SarImageResult(name, m, None, (), f"{int(ok.sum())} conjugate points "
                              f"({MIN_POINTS} needed): {m.matches.counts()}")
    reliable = reliable_reference(reference, m.lon_deg[ok], m.lat_deg[ok], cfg.max_slope)
    if reliable.sum() < MIN_POINTS:
        return SarImageResult(name, m, None, (), f"{int(reliable.sum())} of {int(ok.sum())} "
                              f"conjugate points on reliable reference heights (slope under "
                              f"{cfg.max_slope:g}, no void; {MIN_POINTS} needed)")
    hts = parallax_heights(optical, sar, (m.optical_col[ok], m.optical_row[ok]),
                           (m.sar_col[ok], m.sar_row[ok]), m.h_ref_m[ok], reliable, cfg)
    return SarImageResult(name, m, hts, sar_control_points(name, sar, m, hts, cfg, first_id))


# the delivered geolocation of a SAR product, 1 sigma horizontal (m): Sentinel-1 a few
# metres (Schubert et al. 2015, 2017: ALE of IW products 2-3 m before tropospheric and
# timing corrections), ERS of the 10 m class (restituted orbits in delivered products,
# azimuth time-tag and range biases); a mission not listed gets ERS's
GEOLOCATION_SIGMA_M = {"S1": 3.0, "ERS": 10.0}


def geolocation_sigma_m(mission: str) -> float:
    """The delivered geolocation error (1 sigma, m) of a SAR mission id (``S1A``, ``ERS2``)."""
    for prefix, sigma in GEOLOCATION_SIGMA_M.items():
        if mission.upper().startswith(prefix):
            return sigma
    return GEOLOCATION_SIGMA_M["ERS"]


@dataclass(frozen=True)
class CommonShift:
    """The SAR GCPs' common horizontal offset (east, north, m) from where models oriented on
    other control put their image points, its standard error and the points used."""

    east_m: float
    north_m: float
    sigma_east_m: float
    sigma_north_m: float
    n: int

    def to_dict(self) -> dict[str, float | int]:
        return {"east_m": self.east_m, "north_m": self.north_m,
                "sigma_east_m": self.sigma_east_m, "sigma_north_m": self.sigma_north_m,
                "n": self.n}


def common_shift(models: dict[str, SensorModel], gcps: tuple[ControlPoint, ...]) -> CommonShift:
    """How far the SAR GCPs sit, in common, from the ground their image points reach through
    ``models`` (name -> model oriented without them, e.g. on SRTM GCPs): the robust mean of
    (model's ground - GCP's ground), east and north. The SAR scene's own geolocation error
    and the matching's bias at height steps (see the module docstring) are such a common
    offset; with other control it is estimated and removed (:func:`shifted`), alone it
    passes into the orientation."""
    de, dn = [], []
    for p in gcps:
        for name, ip in p.image_points.items():
            lon, lat = models[name].localize(np.array([ip.col]), np.array([ip.row]),
                                             np.array([p.h_m]))
            mx, my = metres_per_degree(p.lat_deg)
            de.append((float(lon[0]) - p.lon_deg) * float(mx))
            dn.append((float(lat[0]) - p.lat_deg) * float(my))
    if len(de) < 3:
        raise InputError(f"only {len(de)} SAR GCPs to measure their common shift (3 needed)")
    e, n = np.asarray(de), np.asarray(dn)
    one = np.ones((e.size, 1))
    (ce,), se = robust_fit(e, one)
    (cn,), sn = robust_fit(n, one)
    return CommonShift(float(ce), float(cn), float(se / np.sqrt(e.size)),
                       float(sn / np.sqrt(n.size)), int(e.size))


def shifted(gcps: tuple[ControlPoint, ...], shift: CommonShift) -> tuple[ControlPoint, ...]:
    """The GCPs moved by ``shift`` (their image points kept), its provenance recorded."""
    out = []
    for p in gcps:
        mx, my = metres_per_degree(p.lat_deg)
        prov = {**p.provenance, "common_shift_m": [shift.east_m, shift.north_m]}
        out.append(replace(p, lon_deg=p.lon_deg + shift.east_m / float(mx),
                           lat_deg=p.lat_deg + shift.north_m / float(my), provenance=prov))
    return tuple(out)


def registration_sigma_m(geolocation_sigma_m: float, radar_pixel_m: float,
                         range_direction_en: tuple[float, float], up_m: float
                         ) -> tuple[float, float, float]:
    """What an orientation on SAR GCPs alone cannot see, as the reference registration
    sigma (east, north, up; m) its predicted uncertainty adds: the SAR product's geolocation
    error, and the matching's bias at height steps, one radar ground pixel along the ground
    direction of the range (measured 0.7-1.0 pixel on the simulator's forest edges; the
    module docstring), split over east and north; ``up_m`` as given."""
    e, n = (abs(float(v)) for v in range_direction_en)
    return (float(np.hypot(geolocation_sigma_m, radar_pixel_m * e)),
            float(np.hypot(geolocation_sigma_m, radar_pixel_m * n)), float(up_m))
