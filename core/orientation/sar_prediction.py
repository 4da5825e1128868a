"""SAR-optical conjugate points matched against the SAR image predicted from the optical
pair's own surface (the chain's case, when the relative DEM is given): the bias of
:mod:`core.orientation.sar_matching` at height steps removed.

**The radar's view of the pair's own surface**
(:func:`predicted_sar_matches`, when the pair's relative DEM is given: the chain's case).
The SAR image is predicted from the optical pair's surface in the optical model's frame,
crowns and roofs included: its datum put right against the reference on the bare ground
(:func:`vertical_plane`), its steps sharpened with the optical image's edges
(:func:`core.matching.multimodal.sharpened_surface`: the DSM sees them through its matching
window), every cell sent where the SAR model sees it (energy kept: foreshortened slopes
brighten, stretched ones dim, hidden cells add nothing), each with the SAR brightness its
optical grey level has in the scene (a table learnt from the two images). The prediction
and the SAR image, resampled through the same SAR positions, differ by the optical model's
error only: it is searched as above, then each pass renders the prediction where the last
found it (:class:`OffsetField`). A match gives the template centre's optical pixel (on the
surface) and the SAR pixel where the radar saw what the prediction put there, and the
centre's height on the surface is its altimetric control. Measured: 0.0-0.2 radar pixel of
bias (``tiny`` 80 m pixels, ``spot`` 20 m; the rest where the relative DEM is too blurred
for the trees even sharpened).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from core.dem import GeoDEM, sample_bilinear
from core.errors import InputError
from core.geodesy import metres_per_degree
from core.matching import multimodal as mm
from core.orientation.sar_matching import (
    MIN_POINTS,
    GroundImages,
    SarGcpConfig,
    SarOpticalMatches,
    Surface,
    ground_spacing_m,
    match_sar_optical,
    reliable_reference,
    template_matches,
)
from core.robust import robust_fit
from core.sensors.base import SensorModel

FloatArray = NDArray[np.float64]




@dataclass(frozen=True)
class OffsetField:
    """Where the ground an optical image's model shows truly lies: the offset (degrees of
    lon, lat) from a point of the model's ground (the relative frame of the pair) to the
    same content on the true ground, affine in the position (the attitude's biases and
    drifts): ``d = c0 + c1 x + c2 y`` with x, y the point's lon/lat offsets from
    (``lon0_deg``, ``lat0_deg``) in units of 0.01 degree."""

    lon0_deg: float
    lat0_deg: float
    lon_coef: tuple[float, float, float]
    lat_coef: tuple[float, float, float]

    def _basis(self, lon_deg: FloatArray, lat_deg: FloatArray) -> FloatArray:
        x = (np.asarray(lon_deg, float) - self.lon0_deg) * 100.0
        y = (np.asarray(lat_deg, float) - self.lat0_deg) * 100.0
        return np.stack([np.ones(np.shape(x)), x, y], axis=-1)

    def at(self, lon_deg: FloatArray, lat_deg: FloatArray) -> tuple[FloatArray, FloatArray]:
        """The offset (dlon, dlat; degrees) at model-ground points."""
        b = self._basis(lon_deg, lat_deg)
        return b @ np.asarray(self.lon_coef), b @ np.asarray(self.lat_coef)

    @classmethod
    def zero(cls, lon0_deg: float, lat0_deg: float) -> OffsetField:
        """No offset: the ground where the model puts it."""
        return cls(lon0_deg, lat0_deg, (0.0,) * 3, (0.0,) * 3)

    def through(self, project: mm.Project) -> mm.Project:
        """``project`` of the true ground, called with the model-ground points."""

        def at_true_place(lon: FloatArray, lat: FloatArray, h: FloatArray
                          ) -> tuple[FloatArray, FloatArray]:
            dlon, dlat = self.at(lon, lat)
            return project(lon + dlon, lat + dlat, h)

        return at_true_place

    @classmethod
    def fit(cls, lon_deg: FloatArray, lat_deg: FloatArray, dlon_deg: FloatArray,
            dlat_deg: FloatArray) -> OffsetField:
        """The robust affine fit (:func:`core.robust.robust_fit`) of measured offsets."""
        if np.size(lon_deg) < 3:
            raise InputError(f"{np.size(lon_deg)} offsets to fit an offset field (3 needed)")
        f = cls(float(np.mean(lon_deg)), float(np.mean(lat_deg)), (0.0,) * 3, (0.0,) * 3)
        b = f._basis(lon_deg, lat_deg)
        (cx, _), (cy, _) = robust_fit(dlon_deg, b), robust_fit(dlat_deg, b)
        return replace(f, lon_coef=tuple(float(v) for v in cx),
                       lat_coef=tuple(float(v) for v in cy))

    @classmethod
    def of_matches(cls, m: SarOpticalMatches, grid: mm.GroundGrid,
                   base: OffsetField | None = None) -> OffsetField:
        """The field of the matched templates' offsets (from a template's grid node to its
        conjugate's), added to ``base`` (the field the grid's SAR positions were made with)."""
        ok = m.matches.ok
        i, j = m.matches.i[ok], m.matches.j[ok]
        lon, lat = grid.lonlat(i, j)
        lon1, lat1 = grid.lonlat(i + m.matches.di[ok], j + m.matches.dj[ok])
        dlon, dlat = lon1 - lon, lat1 - lat
        if base is not None:
            blon, blat = base.at(lon, lat)
            dlon, dlat = dlon + blon, dlat + blat
        return cls.fit(lon, lat, dlon, dlat)


def vertical_plane(dsm_m: FloatArray, reference: GeoDEM, lon_deg: FloatArray,
                   lat_deg: FloatArray, ground: NDArray[np.bool_], cfg: SarGcpConfig,
                   max_cells: int = 200_000) -> FloatArray:
    """The vertical datum error of a relative DSM (its heights minus the true ones; the
    relative orientation leaves a tilted offset) on a grid whose cells' true places are
    ``lon_deg``, ``lat_deg``, as a plane in the grid's indices: the reference's heights
    there, on the bare ``ground`` cells (unless they are under a tenth of them) where the
    reference is reliable (:func:`reliable_reference`), the robust fit moved to the
    dominant mode of the
    differences (:func:`core.robust.robust_fit` with the reference's sigma as its scale),
    which what canopy and buildings remain leave aside; on at most ``max_cells`` cells (a
    regular subsample). Coefficients (offset, per 100 rows, per 100 columns)."""
    step = max(int(np.ceil(np.sqrt(np.size(dsm_m) / max_cells))), 1)
    sub = (slice(None, None, step), slice(None, None, step))
    d, lon, lat = dsm_m[sub], lon_deg[sub], lat_deg[sub]
    i, j = np.mgrid[0:dsm_m.shape[0]:step, 0:dsm_m.shape[1]:step]
    h_ref = reference.height_m(lon, lat)
    ok = np.isfinite(d) & np.isfinite(h_ref)
    ok[ok] = reliable_reference(reference, lon[ok], lat[ok], cfg.max_slope)
    if (ok & ground[sub]).sum() >= 0.1 * ok.sum():  # else too little bare ground: all of it
        ok &= ground[sub]
    if ok.sum() < 3 * MIN_POINTS:
        raise InputError(f"only {int(ok.sum())} cells of the relative DSM on reliable "
                         "reference heights to find its vertical datum")
    basis = np.stack([np.ones(ok.sum()), i[ok] / 100.0, j[ok] / 100.0], axis=1)
    coef, _ = robust_fit(d[ok] - h_ref[ok], basis, mode_scale_m=cfg.reference_sigma_m)
    return coef


@dataclass(frozen=True)
class Prediction:
    """How the SAR image was predicted from the optical pair's surface: the surface's
    vertical datum plane (m: offset, per 100 rows, per 100 columns of the ``cell_m`` grid),
    the sharpening (:class:`core.matching.multimodal.ElevatedClass`), and per pass the
    matching cell, the matches and the median offset (m, east and north) the match added
    to the field."""

    cell_m: float
    vertical_plane_m: tuple[float, float, float]
    elevated: mm.ElevatedClass
    passes: tuple[dict[str, Any], ...]

    def to_dict(self) -> dict[str, Any]:
        return {"cell_m": self.cell_m, "vertical_plane_m": list(self.vertical_plane_m),
                "elevated": self.elevated.to_dict(), "passes": list(self.passes)}


@dataclass(frozen=True, eq=False)
class _Scene:
    """What the predictions of one optical image share: the render grid (cells of the SAR's
    finer ground spacing, in the optical model's frame), the surface on it (NaN unknown),
    where it is known (``support``), its sharpened heights, the optical image on it."""

    render: mm.GroundGrid
    dsm_m: FloatArray
    support: NDArray[np.bool_]
    sharp_m: FloatArray
    elevated: mm.ElevatedClass
    ground: NDArray[np.bool_]
    ortho: FloatArray


def _scene(optical: SensorModel, optical_image: NDArray, surface: Surface,
           render: mm.GroundGrid) -> _Scene:
    lon, lat = render.nodes()
    dsm = surface.height_m(lon, lat)
    if not np.isfinite(dsm).any():
        raise InputError("the relative DEM does not cover the image: no SAR image to predict")
    support = cv2.morphologyEx(np.isfinite(dsm).astype(np.uint8), cv2.MORPH_CLOSE,
                               np.ones((7, 7), np.uint8)).astype(bool)
    # the optical image on its own surface: a true orthoimage, shifted by the model's error
    oc, orow = mm.image_positions(optical.project, render,
                                  np.where(np.isfinite(dsm), dsm, np.nanmedian(dsm)))
    z = np.asarray(optical_image, dtype=np.float32)
    sigma = 0.5 * render.cell_m / mm.pixel_size_m(oc, orow, render.cell_m)
    ortho = mm.remap(cv2.GaussianBlur(z, (0, 0), sigma) if sigma > 0.5 else z, oc, orow)
    del oc, orow
    sharp, elevated, ground = mm.sharpened_surface(dsm, ortho, render.cell_m,
                                                   surface.cell_size_m())
    return _Scene(render, dsm.astype(np.float32), support, sharp.astype(np.float32),
                  elevated, ground, ortho.astype(np.float32))


def _predict(sc_: _Scene, sar: SensorModel, log_sar: NDArray[np.float32], reference: GeoDEM,
             field: OffsetField, cfg: SarGcpConfig
             ) -> tuple[NDArray[np.float32], FloatArray, FloatArray]:
    """The SAR image (log intensity, the SAR's pixels; NaN where the surface is unknown)
    predicted from the scene's surface put at its true place by ``field``, its heights
    there (the render grid) and the surface's vertical datum plane."""
    r = sc_.render
    lon, lat = r.nodes()
    dlon, dlat = field.at(lon, lat)
    tlon, tlat = lon + dlon, lat + dlat
    del lon, lat, dlon, dlat
    plane = vertical_plane(sc_.dsm_m, reference, tlon, tlat, sc_.ground, cfg)
    datum = (plane[0] + plane[1] * np.arange(r.shape[0])[:, None] / 100.0
             + plane[2] * np.arange(r.shape[1])[None, :] / 100.0)
    h = sc_.sharp_m.astype(np.float64) - datum
    del datum
    unknown = ~np.isfinite(h)
    h[unknown] = reference.height_m(tlon[unknown], tlat[unknown])
    h = np.where(np.isfinite(h), h, np.nanmedian(h))  # the reference's voids too
    h = np.where(np.isfinite(h), h, np.nanmedian(h))
    col, row = mm.image_positions(field.through(sar.project), r, h)
    # each cell's brightness from its optical grey level, learnt where the images overlap
    edges, lut = mm.quantile_lut(sc_.ortho[sc_.support], mm.remap(log_sar, col, row)[sc_.support])
    bright = np.exp(mm.apply_lut(sc_.ortho, edges, lut) - float(np.median(lut)))
    towards, rise = mm.radar_step(sar.project, sar.localize, float(np.mean(tlon)), float(np.mean(tlat)),
                                    float(np.median(h)), r.cell_m)
    del tlon, tlat
    bright = np.where(sc_.support & ~mm.radar_shadow(h, towards, rise),
                      np.nan_to_num(bright), 0.0)
    shape = np.shape(log_sar)
    predicted = mm.splat(col, row, bright, shape)
    del bright
    # where the surface is known: a pixel no cell reaches (a stretched slope) is dark there
    cover = cv2.GaussianBlur(mm.splat(col, row, sc_.support, shape), (0, 0), 1.5)
    every = cv2.GaussianBlur(mm.splat(col, row, np.ones(r.shape), shape), (0, 0), 1.5)
    floor = 0.05 * float(np.median(predicted[predicted > 0]))
    log_pred = np.where((every > 0) & (cover >= 0.9 * every), np.log(predicted + floor),
                        np.nan).astype(np.float32)
    return log_pred, h, plane


def _predicted_images(grid: mm.GroundGrid, sc_: _Scene, sar: SensorModel,
                      log_pred: NDArray[np.float32], log_sar: NDArray[np.float32],
                      h_render: FloatArray, field: OffsetField) -> GroundImages:
    """The predicted (as ``optical``) and the real SAR image on ``grid`` (the optical
    model's frame) through the same SAR positions (both as ``sar_pos``: the optical pixels
    are wanted at the matched templates' centres only, :func:`_match_predicted`); the
    prediction's holes: where the optical image is but its surface is not known."""
    at = sc_.render.indices(*grid.nodes())
    h = sample_bilinear(h_render, *at)
    inside = sample_bilinear(np.isfinite(sc_.ortho).astype(np.float32), *at) > 0.5
    del at
    col, row = mm.image_positions(field.through(sar.project), grid,
                                  np.where(np.isfinite(h), h, np.nanmedian(h_render)))
    sigma = 0.5 * grid.cell_m / mm.pixel_size_m(col, row, grid.cell_m)
    sar_g = mm.remap_lowpass(log_sar, col, row, sigma)
    pred_g = np.where(np.isfinite(sar_g), mm.remap_lowpass(log_pred, col, row, sigma), np.nan)
    holes = np.isfinite(sar_g) & ~np.isfinite(pred_g) & inside  # the surface's gaps
    return GroundImages(grid, h, pred_g, (col, row), sar_g, (col, row), holes)


def _match_predicted(g: GroundImages, optical: SensorModel, surface: Surface,
                     cfg: SarGcpConfig) -> SarOpticalMatches:
    """The predicted and the real SAR image matched (CFOG, no offset expected); each
    template centre's optical pixel on the surface."""
    desc = (mm.orientation_channels(g.optical), mm.orientation_channels(g.sar))
    m = template_matches(g, desc, mm.gradient_energy(g.optical), (0.0, 0.0), cfg)
    lon, lat = g.grid.lonlat(m.matches.i, m.matches.j)
    d = surface.height_m(lon, lat)
    oc, orow = optical.project(lon, lat, np.where(np.isfinite(d), d, np.nanmedian(g.h_m)))
    return replace(m, optical_col=np.asarray(oc, float), optical_row=np.asarray(orow, float))


MIN_MATCHED_SHARE = 0.5  # below it on the SAR's spacing, the grid's cells are doubled


def _pass_record(m: SarOpticalMatches, grid: mm.GroundGrid, before: OffsetField,
                 after: OffsetField) -> dict[str, Any]:
    ok = m.matches.ok
    lon, lat = grid.lonlat(m.matches.i[ok], m.matches.j[ok])
    (a0, b0), (a1, b1) = before.at(lon, lat), after.at(lon, lat)
    mx, my = metres_per_degree(float(np.mean(lat)))
    return {"cell_m": grid.cell_m, "templates": int(ok.size), "counts": m.matches.counts(),
            "moved_east_m": float(np.median(a1 - a0) * mx),
            "moved_north_m": float(np.median(b1 - b0) * my)}


def predicted_sar_matches(optical: SensorModel, optical_image: NDArray, sar: SensorModel,
                          sar_image: NDArray, reference: GeoDEM, surface: Surface,
                          corners: tuple[FloatArray, FloatArray], cfg: SarGcpConfig
                          ) -> tuple[SarOpticalMatches, Prediction]:
    """Conjugate points from the SAR image and the SAR image predicted from the optical
    pair's surface (see the module docstring). The prediction is first put where the
    optical model puts the ground and its offset searched as :func:`match_sar_optical`
    does (up to ``cfg.max_offset_m``, on cells twice the SAR's); then each pass renders it
    where the last one found it and matches again. Where fewer than
    :data:`MIN_MATCHED_SHARE` of the templates match on the first of those passes
    (speckle: a product of few looks), the matching grid's cells are doubled (up to 4
    times, unless ``cfg.cell_m`` fixes them)."""
    cell = cfg.cell_m or ground_spacing_m(sar, np.shape(sar_image), reference)
    finer = ground_spacing_m(sar, np.shape(sar_image), reference, coarser=False)
    sc_ = _scene(optical, optical_image, surface, mm.GroundGrid.covering(
        corners[0], corners[1], min(finer, cell)))
    log_sar = 2.0 * np.log(np.maximum(np.asarray(sar_image, dtype=np.float32), 1.0))
    start = OffsetField.zero(float(np.mean(corners[0])), float(np.mean(corners[1])))
    log_pred, h, plane = _predict(sc_, sar, log_sar, reference, start, cfg)
    coarse = mm.GroundGrid.covering(corners[0], corners[1], 2.0 * cell)
    m = match_sar_optical(_predicted_images(coarse, sc_, sar, log_pred, log_sar, h, start),
                          cfg)
    passes: list[dict[str, Any]] = []
    if m.matches.ok.sum() < MIN_POINTS:
        return m, Prediction(sc_.render.cell_m, tuple(float(v) for v in plane),
                             sc_.elevated, tuple(passes))
    field = OffsetField.of_matches(m, coarse, start)
    passes.append(_pass_record(m, coarse, start, field))
    grid = mm.GroundGrid.covering(corners[0], corners[1], cell)
    used = field
    for k in range(cfg.passes):
        used = field
        log_pred, h, plane = _predict(sc_, sar, log_sar, reference, field, cfg)
        m = _match_predicted(_predicted_images(grid, sc_, sar, log_pred, log_sar, h, field),
                             optical, surface, cfg)
        while (k == 0 and cfg.cell_m is None and grid.cell_m < 3.5 * cell
               and m.matches.ok.mean() < MIN_MATCHED_SHARE):
            grid = mm.GroundGrid.covering(corners[0], corners[1], 2.0 * grid.cell_m)
            m = _match_predicted(_predicted_images(grid, sc_, sar, log_pred, log_sar, h,
                                                   field), optical, surface, cfg)
        if m.matches.ok.sum() < MIN_POINTS:
            break
        field = OffsetField.of_matches(m, grid, used)
        passes.append(_pass_record(m, grid, used, field))
    # each point: its optical pixel (the template's centre on the surface), its SAR pixel,
    # the true place of its ground (where the last pass's field put its conjugate) and its
    # height on the surface, the datum put right: the altimetric control of the parallax
    ok = m.matches.ok
    tl, tb = grid.lonlat(m.matches.i + np.nan_to_num(m.matches.di),
                         m.matches.j + np.nan_to_num(m.matches.dj))
    a, b = used.at(tl, tb)
    lon, lat = np.where(ok, tl + a, m.lon_deg), np.where(ok, tb + b, m.lat_deg)
    m = replace(m, lon_deg=lon, lat_deg=lat)
    return m, Prediction(sc_.render.cell_m, tuple(float(v) for v in plane), sc_.elevated,
                         tuple(passes))
