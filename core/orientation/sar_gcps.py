"""SAR-optical ground control (Goncalves 2002): GCPs for an optical image from a SAR scene of
the same ground, whose geolocation does not depend on attitude.

**Conjugate points**: on a common ground grid at the reference's heights
(:func:`core.orientation.sar_matching.match_sar_optical`), or, when the pair's relative DEM
is given (the chain's case), against the SAR image predicted from it
(:func:`core.orientation.sar_prediction.predicted_sar_matches`), which removes the bias of
height steps (forest edges) the first has.

**Heights from the SAR-optical parallax** (:func:`parallax_heights`). At a height ``h`` the SAR
pixel's ground point and the optical pixel's ground point differ by ``d(h)``; raising ``h``
moves them apart along one direction ``v`` (metres per metre: the SAR point moves away from the
radar by ``1 / tan(incidence)``, the optical one towards its sensor), so
``d(h) = d(h_ref) + (h - h_ref) v``. The optical model's error adds a field ``a(x)`` smooth
across the scene (affine in the ground coordinates: attitude biases and drifts). Calibrated on
altimetric control, the points where the control heights can be trusted (the reference's, or
the surface's with the datum put right; not a void, a gentle slope), ``a`` is the robust fit
of ``d(h_ref)`` there; every point's height is then the one that brings its ``d(h)`` onto
``a``, known to ``sigma_match / |v|``. The component of ``d`` across ``v`` does not depend on
height: a point whose cross component leaves the field by more than ``reject_k`` robust sigmas
is a blunder. Where the control agrees with the parallax height (within 3 sigma of both) the
two are combined (inverse variance), elsewhere (canopy, a void, a steep slope: where SRTM is
wrong) the parallax height stands alone. A metre of error in the control's datum moves the
GCPs by ``1 / tan(incidence)`` metres along the range (2.4 m at 23 degrees).

**The GCP** (:func:`sar_control_points`): the SAR pixel localised at that height (the SAR model:
orbit and two times, no attitude), with the optical pixel as its image measurement;
``sigma_xy_m`` from the matching and the height's uncertainty through the radar's
``1 / tan(incidence)`` (the product's geolocation, common to all of them, is their frame's);
``source: "sar"``.

A common error of the SAR product (its orbit, azimuth time and range delay) is the SAR GCPs'
frame (:func:`sar_frame`, :mod:`core.orientation.frames`): estimated in the adjustment with its
prior, as the reference DEM's misregistration is for SRTM GCPs.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from core.dem import GeoDEM
from core.errors import InputError
from core.geodesy import metres_per_degree
from core.orientation.frames import REFERENCE, FramePrior
from core.orientation.sar_matching import (
    MIN_POINTS,
    LookedModel,
    SarGcpConfig,
    SarOpticalMatches,
    Surface,
    ground_images,
    ground_spacing_m,
    looked,
    match_sar_optical,
    reliable_reference,
)
from core.orientation.sar_prediction import Prediction, predicted_sar_matches
from core.points import ControlPoint, ImagePoint
from core.robust import nmad, robust_fit
from core.sensors.base import SensorModel

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class ParallaxHeights:
    """Per matched point: the height from the parallax (``h_parallax_m``, its 1-sigma
    ``sigma_parallax_m``), the height kept (``h_m``, ``sigma_h_m``; ``from_reference``: the
    reference's height took part), ``inlier`` (not a blunder), ``control`` (used to
    calibrate), ``cross_m`` (the cross-parallax residual), the parallax's sensitivity
    ``m_per_m``, the SAR point's own (``sar_m_per_m``, 1 / tan(incidence)), the ground
    direction towards the radar (``range_direction_en``, east, north) and the matching's
    noise ``sigma_match_m`` (robust, from the cross residuals)."""

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
    # one SAR pixel's ground point at a greater height lies further from the radar
    towards = np.median(sar0 - sar1, axis=0)
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


def sar_control_points(name: str, sar: SensorModel, m: SarOpticalMatches, hts: ParallaxHeights,
                       cfg: SarGcpConfig, first_id: int = 1) -> tuple[ControlPoint, ...]:
    """The GCPs of one optical image (named ``name``): each inlier SAR pixel localised at its
    height (see the module docstring)."""
    ok = m.matches.ok
    idx = np.flatnonzero(ok)[hts.inlier]
    sel = hts.inlier
    lon, lat = sar.localize(m.sar_col[idx], m.sar_row[idx], hts.h_m[sel])
    # the product's geolocation is common to every point: the frame's (sar_frame), not here
    sigma_xy = np.sqrt(hts.sigma_match_m**2
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
    little altimetric control; ``heights`` is then None); ``prediction``: how the SAR image
    was predicted from the pair's surface (None: matched on the reference's heights);
    ``looks``: the SAR pixels averaged per matched pixel (rows, cols; :func:`looked`: a scene
    whose grids would not fit in memory otherwise); the SAR pixels recorded are the
    product's own."""

    name: str
    matches: SarOpticalMatches
    heights: ParallaxHeights | None
    gcps: tuple[ControlPoint, ...]
    refused: str = ""
    prediction: Prediction | None = None
    looks: tuple[int, int] = (1, 1)

    def counts(self) -> dict[str, int]:
        c = self.matches.matches.counts()
        if self.heights is not None:
            c["BLUNDER"] = int((~self.heights.inlier).sum())
        return c


def sar_gcps_of_image(name: str, optical: SensorModel, optical_image: NDArray,
                      sar: SensorModel, sar_image: NDArray, reference: GeoDEM,
                      corners: tuple[FloatArray, FloatArray], cfg: SarGcpConfig,
                      first_id: int = 1, surface: Surface | None = None) -> SarImageResult:
    """The whole method for one optical image (see the module docstring); ``corners``: the
    lon/lat of the image's footprint; ``surface``: the optical pair's DSM in the frame of
    ``optical`` (the relative DEM), whence the SAR image is predicted
    (:func:`predicted_sar_matches`); without it, the images are matched on the reference's
    heights. No GCP (``refused`` says why) where the images match at fewer than
    :data:`MIN_POINTS` places or too few of them lie on reliable reference heights (steep
    terrain, where the radar's and the sun's shading differ most)."""
    prediction = None
    looks = (1, 1)
    if cfg.cell_m is None:  # a grid too large for memory: matched on multilooked pixels
        used, sar_image, looks = looked(sar, sar_image, reference, corners)
    else:
        used = sar
    if surface is None:
        g = ground_images(optical, optical_image, used, sar_image, reference, corners,
                          cfg.cell_m or ground_spacing_m(used, np.shape(sar_image), reference))
        m = match_sar_optical(g, cfg)
    else:
        m, prediction = predicted_sar_matches(optical, optical_image, used, sar_image,
                                              reference, surface, corners, cfg)
    if isinstance(used, LookedModel):  # the SAR pixels of the product itself from here on
        m = replace(m, **dict(zip(("sar_col", "sar_row"), used.to_full(m.sar_col, m.sar_row),
                                  strict=True)))
    ok = m.matches.ok
    if ok.sum() < MIN_POINTS:
        return SarImageResult(name, m, None, (), f"{int(ok.sum())} conjugate points "
                              f"({MIN_POINTS} needed): {m.matches.counts()}", prediction,
                              looks)
    reliable = reliable_reference(reference, m.lon_deg[ok], m.lat_deg[ok], cfg.max_slope)
    if reliable.sum() < MIN_POINTS:
        return SarImageResult(name, m, None, (), f"{int(reliable.sum())} of {int(ok.sum())} "
                              f"conjugate points on reliable reference heights (slope under "
                              f"{cfg.max_slope:g}, no void; {MIN_POINTS} needed)", prediction,
                              looks)
    hts = parallax_heights(optical, sar, (m.optical_col[ok], m.optical_row[ok]),
                           (m.sar_col[ok], m.sar_row[ok]), m.h_ref_m[ok], reliable, cfg)
    return SarImageResult(name, m, hts, sar_control_points(name, sar, m, hts, cfg, first_id),
                          prediction=prediction, looks=looks)


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


# the matching's bias at height steps, in radar pixels of the matching grid along the range:
# against the optical image on the reference's heights, measured 0.7-1.0 on the simulator's
# forest edges; against the SAR image predicted from the pair's surface, 0.0-0.2 while the
# troposphere's 2.3 m were left in the range (bench/validation/sar_gcps.py on the flat tiny and
# spot scenes), which hid part of it: with the hydrostatic delay taken out
# (core.sensors.troposphere) the SAR GCPs of the flat tiny scene (seed 3, ERS, 80.9 m radar
# cells) sit 27 and 34 m towards the radar in the two images, 0.3-0.4 radar pixel
MATCHING_BIAS_PX = {False: 1.0, True: 0.4}
# and along the azimuth: against the predicted SAR image of the spot scene (seed 2, Sentinel-1
# IW GRD of 10 m multilooked 3x3 and 5x5, 30 and 50 m cells), the matched SAR pixels sit 0.24
# and 0.33 product pixel (2.4-3.3 m, 0.08 and 0.07 cell) along the azimuth from the true SAR
# model's, beside 1.05-1.26 pixel (0.35 and 0.25 cell) along the range
# (bench/validation/sar_gcps.py --orient --looks 3 / 5, 2026-12-02); the reference-height
# matching is not measured along the azimuth: the same share is taken
MATCHING_AZIMUTH_BIAS_PX = 0.1


#: the frame of SAR-optical GCPs (:mod:`core.orientation.frames`)
SAR_FRAME = "sar"


def sar_frame(results: Sequence[SarImageResult], geolocation_sigma_m: float,
              up_sigma_m: float, up_of: str = REFERENCE) -> FramePrior:
    """The prior of the SAR GCPs' frame: the product's geolocation and the matching's bias at
    height steps (:func:`registration_sigma_m`, from the first image with GCPs), its
    vertical the reference's (``up_of``; the heights are calibrated on the reference's; alone,
    ``up_sigma_m``)."""
    ok = next((r for r in results if r.heights is not None), None)
    if ok is None:
        raise InputError("no SAR GCPs: no image was matched to the SAR scene")
    e, n, u = registration_sigma_m(geolocation_sigma_m, ok.matches.cell_m,
                                   ok.heights.range_direction_en, up_sigma_m,
                                   predicted=ok.prediction is not None)
    return FramePrior(SAR_FRAME, (e, n, u), up_of,
                      f"SAR geolocation {geolocation_sigma_m:g} m and the matching's bias at "
                      f"height steps ({MATCHING_BIAS_PX[ok.prediction is not None]:g} radar "
                      f"pixel of {ok.matches.cell_m:.1f} m along the range, "
                      f"{MATCHING_AZIMUTH_BIAS_PX:g} along the azimuth)")


def registration_sigma_m(geolocation_sigma_m: float, radar_pixel_m: float,
                         range_direction_en: tuple[float, float], up_m: float,
                         predicted: bool = False) -> tuple[float, float, float]:
    """What an orientation on SAR GCPs alone cannot see, as the reference registration
    sigma (east, north, up; m) its predicted uncertainty adds: the SAR product's geolocation
    error, and the matching's bias at height steps along the ground direction of the range
    (:data:`MATCHING_BIAS_PX` radar pixels of ``radar_pixel_m``, ``predicted``: matched
    against the SAR image predicted from the surface) and across it, along the azimuth
    (:data:`MATCHING_AZIMUTH_BIAS_PX`), split over east and north; ``up_m`` as given."""
    e, n = (abs(float(v)) for v in range_direction_en)
    along = MATCHING_BIAS_PX[predicted] * radar_pixel_m
    across = MATCHING_AZIMUTH_BIAS_PX * radar_pixel_m  # the azimuth: (n, e) on the ground
    return (float(np.sqrt(geolocation_sigma_m ** 2 + (along * e) ** 2 + (across * n) ** 2)),
            float(np.sqrt(geolocation_sigma_m ** 2 + (along * n) ** 2 + (across * e) ** 2)),
            float(up_m))
