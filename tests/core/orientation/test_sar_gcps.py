"""Goncalves's heights and the SAR GCPs (core/orientation/sar_gcps.py) on analytic models whose
truth is known by construction: a SAR seeing the ground in range from the east, an optical
sensor looking the other way, its delivered model off by an affine field."""

from __future__ import annotations

import numpy as np
import pytest

from core.dem import GeoDEM
from core.errors import InputError
from core.geodesy import metres_per_degree
from core.orientation import sar_gcps as sg

LON0, LAT0 = 5.5, 44.5
MX, MY = (float(v) for v in metres_per_degree(LAT0))


class Ground:
    """A model whose pixel is ground metres east/north of (LON0, LAT0) shifted in x by the
    height: ``x_img = (x + k_h h + a(x, y)) / gsd``; a SAR looking from the east puts a raised
    point nearer the radar (east, k_h = +1/tan(inc)); an optical sensor looking from the
    east sees it moved west (k_h = -tan(view))."""

    def __init__(self, gsd, k_h, field=(0.0, 0.0, 0.0, 0.0, 0.0, 0.0)):
        self.gsd, self.k_h, self.f = gsd, k_h, field

    def _err(self, x, y):
        f = self.f
        return f[0] + f[1] * x / 1e4 + f[2] * y / 1e4, f[3] + f[4] * x / 1e4 + f[5] * y / 1e4

    def project(self, lon, lat, h):
        x, y = (np.asarray(lon) - LON0) * MX, (np.asarray(lat) - LAT0) * MY
        ex, ey = self._err(x, y)
        return (x + self.k_h * np.asarray(h) + ex) / self.gsd, -(y + ey) / self.gsd

    def localize(self, col, row, h):
        u, v = np.asarray(col) * self.gsd, -np.asarray(row) * self.gsd
        x, y = u - self.k_h * np.asarray(h), v
        for _ in range(20):  # the error field depends on the ground: fixed point
            ex, ey = self._err(x, y)
            x, y = u - self.k_h * np.asarray(h) - ex, v - ey
        return LON0 + x / MX, LAT0 + y / MY


def _points(n=300, seed=0):
    rng = np.random.default_rng(seed)
    x, y = rng.uniform(-8000, 8000, n), rng.uniform(-8000, 8000, n)
    h = 900 + 0.002 * x + rng.normal(0, 2, n)  # a gentle tilt
    canopy = rng.random(n) < 0.25  # a quarter of the points on 18 m trees the reference lacks
    h_true = h + np.where(canopy, 18.0, 0.0)
    return x, y, h, h_true, canopy


def _setup(noise_m=3.0, seed=0):
    x, y, h_ref, h_true, canopy = _points(seed=seed)
    rng = np.random.default_rng(seed + 1)
    sar = Ground(20.0, 1.0 / np.tan(np.radians(23.0)))
    optical_true = Ground(10.0, -np.tan(np.radians(20.0)))
    # the delivered optical model: 150 m off east, 60 m south, with a scale and a rotation
    optical = Ground(10.0, -np.tan(np.radians(20.0)), (150.0, 8.0, -5.0, -60.0, 6.0, 3.0))
    lon, lat = LON0 + x / MX, LAT0 + y / MY
    opt_px = optical_true.project(lon, lat, h_true)
    sc, sr = sar.project(lon, lat, h_true)
    sar_px = (sc + rng.normal(0, noise_m, x.size) / sar.gsd,
              sr + rng.normal(0, noise_m, x.size) / sar.gsd)
    return sar, optical, opt_px, sar_px, (lon, lat, h_ref, h_true, canopy)


def test_parallax_heights_recover_the_canopy_the_reference_lacks():
    sar, optical, opt_px, sar_px, (lon, lat, h_ref, h_true, canopy) = _setup()
    cfg = sg.SarGcpConfig(reference_sigma_m=3.0)
    hts = sg.parallax_heights(optical, sar, opt_px, sar_px, h_ref, np.ones(lon.size, bool), cfg)
    # the heights are the true ones (trees included) to their stated precision
    err = hts.h_parallax_m - h_true
    assert np.median(np.abs(err[canopy])) < 2.0 and abs(np.median(err)) < 0.5
    assert np.std(err) == pytest.approx(np.median(hts.sigma_parallax_m), rel=0.3)
    # where the reference misses the trees, the parallax alone is kept
    assert not hts.from_reference[canopy].any() or \
        hts.from_reference[canopy].mean() < 0.05
    assert hts.from_reference[~canopy].mean() > 0.9
    # the calibration used the points where the reference holds
    assert hts.control[canopy].mean() < 0.05 and hts.control[~canopy].mean() > 0.8
    # the SAR moves 1/tan(23 deg) per metre of height, the parallax that plus tan(20 deg)
    assert np.median(hts.sar_m_per_m) == pytest.approx(1 / np.tan(np.radians(23)), rel=1e-3)
    assert np.median(hts.m_per_m) == pytest.approx(1 / np.tan(np.radians(23))
                                                   + np.tan(np.radians(20)), rel=1e-3)


def test_gcps_land_on_the_true_ground_whatever_the_optical_model_error():
    sar, optical, opt_px, sar_px, (lon, lat, h_ref, h_true, canopy) = _setup(noise_m=1.0)
    cfg = sg.SarGcpConfig(geolocation_sigma_m=3.0, reference_sigma_m=3.0)
    hts = sg.parallax_heights(optical, sar, opt_px, sar_px, h_ref, np.ones(lon.size, bool), cfg)
    n = lon.size
    m = sg.SarOpticalMatches(
        matches=_ok_matches(n), optical_col=opt_px[0], optical_row=opt_px[1],
        sar_col=sar_px[0], sar_row=sar_px[1], lon_deg=lon, lat_deg=lat, h_ref_m=h_ref,
        offset_cells=(0.0, 0.0), cell_m=20.0)
    gcps = sg.sar_control_points("left", sar, m, hts, cfg, first_id=7)
    assert len(gcps) == hts.inlier.sum() >= 0.97 * n and gcps[0].id == 7
    glon = np.array([p.lon_deg for p in gcps])
    glat = np.array([p.lat_deg for p in gcps])
    sel = hts.inlier
    dx, dy = (glon - lon[sel]) * MX, (glat - lat[sel]) * MY
    # 150 m of optical model error does not reach the GCPs: metres, as the SAR's noise
    assert np.sqrt(np.mean(dx**2)) < 3.0 and np.sqrt(np.mean(dy**2)) < 2.0
    assert all(p.source == "sar" and set(p.image_points) == {"left"} for p in gcps)
    assert np.median([p.sigma_xy_m for p in gcps]) >= 3.0


def test_a_blunder_across_the_parallax_is_rejected():
    sar, optical, opt_px, sar_px, (lon, lat, h_ref, _, _) = _setup(noise_m=1.0)
    bad_row = sar_px[1].copy()
    bad_row[:5] += 8.0  # 160 m along track, where no height can move a point
    hts = sg.parallax_heights(optical, sar, opt_px, (sar_px[0], bad_row), h_ref,
                              np.ones(lon.size, bool), sg.SarGcpConfig())
    assert not hts.inlier[:5].any() and hts.inlier[5:].mean() > 0.97


def test_too_little_altimetric_control_is_refused():
    sar, optical, opt_px, sar_px, (lon, lat, h_ref, _, _) = _setup()
    reliable = np.zeros(lon.size, bool)
    reliable[:3] = True
    with pytest.raises(InputError, match="reliable reference"):
        sg.parallax_heights(optical, sar, opt_px, sar_px, h_ref, reliable, sg.SarGcpConfig())


def test_reliable_reference_refuses_voids_and_steep_slopes():
    lon = np.linspace(5.4, 5.6, 41)
    lat = np.linspace(44.6, 44.4, 41)
    L, _ = np.meshgrid(lon, lat)
    h = np.where(L < 5.5, 500.0, 500.0 + (L - 5.5) * MX * 0.5)  # flat, then a 50 % slope
    h[30:, :5] = np.nan  # a void
    dem = GeoDEM(h, lon[0], lat[0], lon[1] - lon[0], lat[1] - lat[0])
    q_lon = np.array([5.45, 5.55, lon[2]])
    q_lat = np.array([44.5, 44.5, lat[35]])
    assert list(sg.reliable_reference(dem, q_lon, q_lat, 0.15)) == [True, False, False]


def test_geolocation_sigma_follows_the_mission():
    assert sg.geolocation_sigma_m("S1A") == 3.0
    assert sg.geolocation_sigma_m("ERS2") == 10.0
    assert sg.geolocation_sigma_m("RADARSAT") == 10.0


def _ok_matches(n):
    from core.matching.multimodal import MultimodalMatches

    z = np.zeros(n)
    return MultimodalMatches(z, z, z, z, np.full(n, 0.6), np.full(n, 0.5), np.zeros(n, np.int8))
