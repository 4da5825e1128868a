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
from core.orientation import sar_matching as sgm
from core.orientation import sar_prediction as sgp

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
    cfg = sgm.SarGcpConfig(reference_sigma_m=3.0)
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
    cfg = sgm.SarGcpConfig(geolocation_sigma_m=3.0, reference_sigma_m=3.0)
    hts = sg.parallax_heights(optical, sar, opt_px, sar_px, h_ref, np.ones(lon.size, bool), cfg)
    n = lon.size
    m = sgm.SarOpticalMatches(
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
    # each GCP's stated precision is its own error's (the product's geolocation, common to
    # all, is their frame's prior: core.orientation.sar_gcps.sar_frame)
    stated = float(np.sqrt(np.mean([p.sigma_xy_m**2 for p in gcps])))
    assert 0.5 < np.sqrt(np.mean(dx**2 + dy**2)) / stated < 2.0


def test_a_blunder_across_the_parallax_is_rejected():
    sar, optical, opt_px, sar_px, (lon, lat, h_ref, _, _) = _setup(noise_m=1.0)
    bad_row = sar_px[1].copy()
    bad_row[:5] += 8.0  # 160 m along track, where no height can move a point
    hts = sg.parallax_heights(optical, sar, opt_px, (sar_px[0], bad_row), h_ref,
                              np.ones(lon.size, bool), sgm.SarGcpConfig())
    assert not hts.inlier[:5].any() and hts.inlier[5:].mean() > 0.97


def test_too_little_altimetric_control_is_refused():
    sar, optical, opt_px, sar_px, (lon, lat, h_ref, _, _) = _setup()
    reliable = np.zeros(lon.size, bool)
    reliable[:3] = True
    with pytest.raises(InputError, match="reliable reference"):
        sg.parallax_heights(optical, sar, opt_px, sar_px, h_ref, reliable, sgm.SarGcpConfig())


def test_reliable_reference_refuses_voids_and_steep_slopes():
    lon = np.linspace(5.4, 5.6, 41)
    lat = np.linspace(44.6, 44.4, 41)
    L, _ = np.meshgrid(lon, lat)
    h = np.where(L < 5.5, 500.0, 500.0 + (L - 5.5) * MX * 0.5)  # flat, then a 50 % slope
    h[30:, :5] = np.nan  # a void
    dem = GeoDEM(h, lon[0], lat[0], lon[1] - lon[0], lat[1] - lat[0])
    q_lon = np.array([5.45, 5.55, lon[2]])
    q_lat = np.array([44.5, 44.5, lat[35]])
    assert list(sgm.reliable_reference(dem, q_lon, q_lat, 0.15)) == [True, False, False]


def test_geolocation_sigma_follows_the_mission():
    assert sg.geolocation_sigma_m("S1A") == 3.0
    assert sg.geolocation_sigma_m("ERS2") == 10.0
    assert sg.geolocation_sigma_m("RADARSAT") == 10.0


def _ok_matches(n):
    from core.matching.multimodal import MultimodalMatches

    z = np.zeros(n)
    return MultimodalMatches(z, z, z, z, np.full(n, 0.6), np.full(n, 0.5), np.zeros(n, np.int8))


# ------------------------------------------------ a forest the radar lays over, end to end

INC = np.radians(23.0)
FINE = 5.0  # m: the world's cells
SIDE = 6000.0  # m: the world spans x in [0, SIDE] east and y in [-SIDE, 0] north of LON0, LAT0


def _forest_world(seed=11):
    """Flat ground at 500 m with 17.5 m forest stands on 30 % of it (cells of FINE m, rows
    going south): heights and the forest mask."""
    from scipy.ndimage import gaussian_filter

    n = int(SIDE / FINE)
    f = gaussian_filter(np.random.default_rng(seed).standard_normal((n, n)), 150.0 / FINE)
    forest = f > np.quantile(f, 0.7)
    return 500.0 + 17.5 * forest, forest


def _radar_image(sar, heights, forest, seed=12):
    """What the radar records, written here independently of the chain: each world cell
    (sigma0: forest 0.18, fields 0.12) at the pixel the SAR model puts it in, at its height
    (the canopy laid over the fields in front of it, a gap behind), summed per pixel
    (nearest), the ground the canopy hides from the radar (east) adding nothing; 50 looks."""
    n = heights.shape[0]
    i, j = np.mgrid[0:n, 0:n]
    x, y = (j + 0.5) * FINE, -(i + 0.5) * FINE
    hidden = np.zeros(heights.shape, bool)
    for k in (1, 2, 3):  # the line of sight climbs FINE / tan(INC) per cell towards the east
        ahead = np.pad(heights[:, k:], ((0, 0), (0, k)), mode="edge")
        hidden |= ahead - heights > k * FINE / np.tan(INC)
    col, row = sar.project(LON0 + x / MX, LAT0 + y / MY, heights)
    c, r = np.rint(col).astype(int), np.rint(row).astype(int)
    shape = (int(r.max()) + 2, int(c.max()) + 2)
    w = np.where(hidden, 0.0, np.where(forest, 0.18, 0.12))
    img = np.bincount((r * shape[1] + c).ravel(), w.ravel(), shape[0] * shape[1])
    img = img.reshape(shape) / (sar.gsd / FINE) ** 2
    looks = np.random.default_rng(seed).standard_gamma(50.0, shape) / 50.0
    return 1000.0 * np.sqrt((img + 1e-4) * looks)


def _optical_image(model_true, forest, shape, seed=13):
    """A nadir optical image (no relief displacement): dark forest, bright fields."""
    r, c = np.mgrid[0:shape[0], 0:shape[1]]
    lon, lat = model_true.localize(c.astype(float), r.astype(float), np.full(shape, 500.0))
    i = np.clip(((LAT0 - lat) * MY / FINE).astype(int), 0, forest.shape[0] - 1)
    j = np.clip(((lon - LON0) * MX / FINE).astype(int), 0, forest.shape[1] - 1)
    rng = np.random.default_rng(seed)
    return np.where(forest[i, j], 60.0, 140.0) + rng.normal(0.0, 8.0, shape)


def _grid_dem(values_at, cell_m):
    """A GeoDEM over the world (and 1 km around) from a function of (x, y) metres."""
    xs = np.arange(-1000.0, SIDE + 1000.0, cell_m)
    ys = np.arange(1000.0, -SIDE - 1000.0, -cell_m)
    X, Y = np.meshgrid(xs, ys)
    return GeoDEM(values_at(X, Y), LON0 + xs[0] / MX, LAT0 + ys[0] / MY, cell_m / MX,
                  -cell_m / MY)


def _sample(z, x, y):
    from core.dem import sample_bilinear

    return sample_bilinear(z, -y / FINE - 0.5, x / FINE - 0.5)


@pytest.fixture(scope="module")
def forest_scene():
    from scipy.ndimage import gaussian_filter

    heights, forest = _forest_world()
    sar = Ground(20.0, 1.0 / np.tan(INC))  # the radar to the east, its true model
    optical_true = Ground(10.0, 0.0)
    field = (150.0, 8.0, -5.0, -60.0, 6.0, 3.0)  # the delivered model: 150 m E, 60 m S off
    optical = Ground(10.0, 0.0, field)
    sar_img = _radar_image(sar, heights, forest)
    opt_img = _optical_image(optical_true, forest, (600, 600))
    # the reference: bare ground and half the canopy, smoothed (C band, 3" cells)
    canopy = gaussian_filter(17.5 * forest, 60.0 / FINE)
    reference = _grid_dem(lambda x, y: 500.0 + 0.5 * np.nan_to_num(_sample(canopy, x, y)),
                          90.0)
    # the pair's DSM in the delivered model's frame: the surface, crowns and all, blurred by
    # the matching window, where the delivered model puts it
    blurred = gaussian_filter(heights, 20.0 / FINE)

    def relative(x, y):
        ex, ey = optical._err(x, y)
        return np.where((x + ex > 0) & (x + ex < SIDE) & (y + ey < 0) & (y + ey > -SIDE),
                        _sample(blurred, x + ex, y + ey), np.nan)

    surface = _grid_dem(relative, 20.0)
    c, r = np.array([0.0, 599, 0, 599]), np.array([0.0, 0, 599, 599])
    corners = optical.localize(c, r, np.full(4, 500.0))
    return sar, optical, optical_true, sar_img, opt_img, reference, surface, corners


def _gcp_errors_px(gcps, optical_true):
    lon, lat, h = (np.array([getattr(p, k) for p in gcps]) for k in ("lon_deg", "lat_deg",
                                                                       "h_m"))
    col, row = optical_true.project(lon, lat, h)
    return (np.array([p.image_points["left"].col for p in gcps]) - col,
            np.array([p.image_points["left"].row for p in gcps]) - row)


def _sar_errors_px(gcps, sar, optical_true, heights):
    """The matched SAR pixel against the one that sees what the GCP's optical pixel sees
    (the nadir image's ground at the world's height there)."""
    col = np.array([p.image_points["left"].col for p in gcps])
    row = np.array([p.image_points["left"].row for p in gcps])
    lon, lat = optical_true.localize(col, row, np.full(col.size, 500.0))
    h = _sample(heights, (lon - LON0) * MX, (lat - LAT0) * MY)
    sc, sr = sar.project(lon, lat, h)
    return (np.array([p.provenance["sar_col"] for p in gcps]) - sc,
            np.array([p.provenance["sar_row"] for p in gcps]) - sr)


def test_matching_the_predicted_radar_image_removes_the_bias_of_forest_edges(forest_scene):
    sar, optical, optical_true, sar_img, opt_img, reference, surface, corners = forest_scene
    heights, _ = _forest_world()
    cfg = sgm.SarGcpConfig(geolocation_sigma_m=3.0)
    plain = sg.sar_gcps_of_image("left", optical, opt_img, sar, sar_img, reference, corners,
                                 cfg)
    pred = sg.sar_gcps_of_image("left", optical, opt_img, sar, sar_img, reference, corners,
                                cfg, surface=surface)
    assert plain.prediction is None and pred.prediction is not None
    assert len(pred.gcps) >= 150
    # matched on the optical image, the radar's forest edges sit towards the radar (the
    # canopy laid over the fields, 17.5 / tan(23 deg) = 41 m = 2 radar pixels, and the gap
    # behind it): the matches and the GCPs made of them are off
    sc0, _ = _sar_errors_px(plain.gcps, sar, optical_true, heights)
    ec0, _ = _gcp_errors_px(plain.gcps, optical_true)
    assert np.median(sc0) > 0.5 and np.median(ec0) < -1.5
    # against the radar image predicted from the pair's surface the matches are unbiased
    sc, sr = _sar_errors_px(pred.gcps, sar, optical_true, heights)
    assert abs(np.median(sc)) < 0.15 and abs(np.median(sr)) < 0.15
    ec, er = _gcp_errors_px(pred.gcps, optical_true)
    assert abs(np.median(ec)) < 0.5 and abs(np.median(er)) < 0.3
    # the surface's datum and its trees were found: the DSM's heights are the true ones
    # (offset 0), the darkest 30 % of the optical grey levels stand 17.5 m above the rest
    p = pred.prediction
    assert abs(p.vertical_plane_m[0]) < 1.0
    assert p.elevated.dark and p.elevated.height_m == pytest.approx(17.5, rel=0.1)
    assert p.elevated.percentile == pytest.approx(30.0, abs=5.0)


def test_offset_field_recovers_an_affine_offset_and_moves_a_projection():
    rng = np.random.default_rng(3)
    lon, lat = LON0 + rng.uniform(0, 0.08, 200), LAT0 - rng.uniform(0, 0.05, 200)
    dlon = 2e-3 + 0.01 * (lon - LON0) - 0.02 * (lat - LAT0)
    dlat = -5e-4 + 0.015 * (lon - LON0)
    dlon[:10] += 0.01  # a few blunders
    f = sgp.OffsetField.fit(lon, lat, dlon, dlat)
    got_lon, got_lat = f.at(lon[10:], lat[10:])
    # to centimetres (1e-6 degree is 8 cm; the blunders, Huber-weighted, move it a little)
    assert np.abs(got_lon - dlon[10:]).max() < 1e-6 and np.abs(got_lat - dlat[10:]).max() < 1e-6
    sar = Ground(20.0, 1.0)
    c, r = f.through(sar.project)(lon, lat, np.full(lon.size, 100.0))
    c2, r2 = sar.project(lon + f.at(lon, lat)[0], lat + f.at(lon, lat)[1], np.full(lon.size,
                                                                                    100.0))
    assert np.allclose(c, c2) and np.allclose(r, r2)


def test_looked_model_and_image_agree_on_where_a_looked_pixel_lies():
    """A SAR image whose intensity is a known plane of the ground: each looked pixel (the mean
    intensity of its block) is the plane at the ground its looked model localizes, so the
    looked model's pixel centres are the blocks' centres; project inverts localize."""
    sar = Ground(10.0, 1.0 / np.tan(np.radians(38.0)))
    nr, nc = 301, 402  # not multiples of the looks: the last partial block is left out
    r, c = np.mgrid[0:nr, 0:nc].astype(float)
    intensity = 5.0 + 0.02 * c + 0.03 * r  # linear in the pixel: a block's mean is its centre's
    ref = GeoDEM(np.full((50, 50), 700.0), LON0 - 0.05, LAT0 + 0.05, 0.01, -0.01)
    corners = sar.localize(np.array([0.0, nc - 1, 0, nc - 1]), np.array([0.0, 0, nr - 1, nr - 1]),
                           np.full(4, 700.0))
    used, img, looks = sgm.looked(sar, np.sqrt(intensity), ref, corners, max_cells=5000)
    # ~12 km2 over 5000 cells: 49 m cells at least, on 10 m pixels: 5 x 5 looks
    assert looks == (5, 5) and img.shape == (nr // 5, nc // 5)
    i, j = np.mgrid[0:img.shape[0], 0:img.shape[1]].astype(float)
    lon, lat = used.localize(j, i, np.full(i.shape, 700.0))
    fc, fr = sar.project(lon, lat, np.full(i.shape, 700.0))  # the product's own pixels
    np.testing.assert_allclose(img**2, 5.0 + 0.02 * fc + 0.03 * fr, rtol=1e-5)
    back = used.project(lon, lat, np.full(i.shape, 700.0))
    np.testing.assert_allclose(back[0], j, atol=1e-6)
    np.testing.assert_allclose(back[1], i, atol=1e-6)
    # a grid that fits is left alone
    same, img1, looks1 = sgm.looked(sar, np.sqrt(intensity), ref, corners)
    assert looks1 == (1, 1) and same is sar and img1.shape == (nr, nc)


def test_a_scene_too_large_for_memory_is_matched_on_looked_pixels(forest_scene, monkeypatch):
    """The forest scene with the grids' budget cut so that the radar image is looked 2 x 2:
    the GCPs' SAR pixels are still the product's own (unbiased against the true model, as on
    the full pixels) and the optical side as good."""
    sar, optical, optical_true, sar_img, opt_img, reference, surface, corners = forest_scene
    heights, _ = _forest_world()
    monkeypatch.setattr(sgm, "MAX_GRID_CELLS", 40_000)  # 6 km x 6 km: cells of 30 m
    # the first search on cells of 80 m: over the small world, +-500 m (the model is 160 m off)
    cfg = sgm.SarGcpConfig(geolocation_sigma_m=3.0, max_offset_m=500.0)
    res = sg.sar_gcps_of_image("left", optical, opt_img, sar, sar_img, reference, corners,
                               cfg, surface=surface)
    assert res.looks == (2, 2) and len(res.gcps) >= 40
    sc, sr = _sar_errors_px(res.gcps, sar, optical_true, heights)  # in the product's pixels
    assert abs(np.median(sc)) < 0.3 and abs(np.median(sr)) < 0.3
    ec, er = _gcp_errors_px(res.gcps, optical_true)
    assert abs(np.median(ec)) < 0.7 and abs(np.median(er)) < 0.5


def test_a_surface_with_scattered_gaps_still_gives_unbiased_gcps(forest_scene, monkeypatch):
    """The pair's DSM with gaps of 150-300 m over 15 % of the scene (shadows, changed ground,
    water: a spot scene's relative DEM on the Sentinel-1's 30 m looked cells left one whole
    template of 25): templates may hold a quarter of holes, left out of their scores, and
    the GCPs are as unbiased as on the whole surface; with none allowed, too few remain."""
    from scipy.ndimage import gaussian_filter

    sar, optical, optical_true, sar_img, opt_img, reference, surface, corners = forest_scene
    heights, _ = _forest_world()
    blobs = gaussian_filter(np.random.default_rng(5).standard_normal(surface.h_m.shape), 4.0)
    gaps = blobs > np.quantile(blobs, 0.85)
    holed = GeoDEM(np.where(gaps, np.nan, surface.h_m), *surface.axes)
    cfg = sgm.SarGcpConfig(geolocation_sigma_m=3.0)
    res = sg.sar_gcps_of_image("left", optical, opt_img, sar, sar_img, reference, corners,
                               cfg, surface=holed)
    assert len(res.gcps) >= 40
    sc, sr = _sar_errors_px(res.gcps, sar, optical_true, heights)
    assert abs(np.median(sc)) < 0.3 and abs(np.median(sr)) < 0.3
    ec, er = _gcp_errors_px(res.gcps, optical_true)
    assert abs(np.median(ec)) < 0.7 and abs(np.median(er)) < 0.5
    monkeypatch.setattr(sgm, "MAX_HOLE_SHARE", 0.0)  # whole templates only: few are left
    try:
        n_few = len(sg.sar_gcps_of_image("left", optical, opt_img, sar, sar_img, reference,
                                         corners, cfg, surface=holed).gcps)
    except InputError:  # no whole template on the first, coarse grid
        n_few = 0
    assert n_few < 0.5 * len(res.gcps)
