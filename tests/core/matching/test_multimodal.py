"""The SAR-optical matcher (core/matching/multimodal.py): descriptor, score, search, lattice."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

from core.errors import InputError
from core.matching import multimodal as mm

UP = 4  # the world is drawn 4 times finer than the images, then averaged


def _classes(shape=(160, 160), seed=0):
    """A land-cover-like field of patches (4 classes, smooth boundaries), UP times finer."""
    rng = np.random.default_rng(seed)
    field = gaussian_filter(rng.standard_normal((shape[0] * UP, shape[1] * UP)), 4.0 * UP)
    return np.digitize(field, np.quantile(field, [0.3, 0.6, 0.85]))


def _image(values, classes, di=0.0, dj=0.0):
    """The class values moved by (+di, +dj) image cells (multiples of 1/UP), averaged to
    image cells: edges land where they should to a small fraction of a cell."""
    fine = np.roll(values[classes], (round(di * UP), round(dj * UP)), axis=(0, 1))
    n, m = fine.shape[0] // UP, fine.shape[1] // UP
    return fine.reshape(n, UP, m, UP).mean(axis=(1, 3))


def _optical(classes, rng, di=0.0, dj=0.0):
    img = _image(np.array([0.2, 0.8, 0.5, 0.35]), classes, di, dj)
    return img + 0.02 * rng.standard_normal(img.shape)


def _sar(classes, rng, di=0.0, dj=0.0, looks=16.0):
    # another radiometry: the order of the classes' brightness differs (contrast reversed)
    sigma0 = _image(np.array([0.05, 0.02, 0.3, 0.12]), classes, di, dj)
    return np.log(sigma0 * rng.standard_gamma(looks, sigma0.shape) / looks)


def test_channel_ncc_is_the_correlation_of_the_descriptor_vectors():
    rng = np.random.default_rng(3)
    t = rng.random((5, 9, 9)).astype(np.float32)
    s = rng.random((5, 15, 15)).astype(np.float32)
    got = mm.channel_ncc(t, s)
    assert got.shape == (7, 7)
    for a in range(7):
        for b in range(7):
            w = s[:, a:a + 9, b:b + 9]
            tv = (t - t.mean(axis=(1, 2), keepdims=True)).ravel()
            wv = (w - w.mean(axis=(1, 2), keepdims=True)).ravel()
            ref = tv @ wv / np.sqrt((tv @ tv) * (wv @ wv))
            assert got[a, b] == pytest.approx(ref, abs=2e-5)


def test_descriptor_is_blind_to_contrast_reversal_and_gain():
    img = _optical(_classes(), np.random.default_rng(0))
    a = mm.orientation_channels(img)
    b = mm.orientation_channels(-3.0 * img + 7.0)
    assert np.allclose(a, b, atol=1e-4)
    norm = np.linalg.norm(a, axis=0)
    assert np.median(norm) == pytest.approx(1.0, abs=1e-5) and norm.max() <= 1.0 + 1e-5


@pytest.mark.parametrize("di, dj", [(2.25, -1.5), (-4.75, 3.25)])
def test_a_known_shift_is_found_across_modalities(di, dj):
    rng = np.random.default_rng(1)
    classes = _classes()
    opt = _optical(classes, rng)
    sar = _sar(classes, rng, di, dj)
    # the optical image's grey levels do not correlate with the SAR's
    assert abs(np.corrcoef(opt.ravel(), _sar(classes, rng).ravel())[0, 1]) < 0.5
    da, db = mm.orientation_channels(opt), mm.orientation_channels(sar)
    valid = np.ones(opt.shape, bool)
    ci, cj = mm.template_centres(valid, 16, 20)
    ci, cj = ci[(ci > 30) & (ci < 130) & (cj > 30) & (cj < 130)], \
        cj[(ci > 30) & (ci < 130) & (cj > 30) & (cj < 130)]
    m = mm.match_points(da, db, valid, valid, mm.gradient_energy(opt), (ci, cj), (0.0, 0.0),
                        mm.MultimodalConfig(radius_cells=7))
    assert m.ok.sum() >= 0.8 * ci.size
    assert np.median(m.di[m.ok]) == pytest.approx(di, abs=0.1)
    assert np.median(m.dj[m.ok]) == pytest.approx(dj, abs=0.1)


def test_flat_and_off_image_templates_are_refused():
    rng = np.random.default_rng(2)
    opt = _optical(_classes(), rng)
    opt[:60, :60] = 0.5 + 0.001 * rng.standard_normal((60, 60))  # a featureless lake
    valid = np.ones(opt.shape, bool)
    valid_b = valid.copy()
    valid_b[:, 120:] = False  # the second image stops there
    d = mm.orientation_channels(opt)
    m = mm.match_points(d, d, valid, valid_b, mm.gradient_energy(opt),
                        ([30, 80, 80], [30, 80, 130]), (0, 0), mm.MultimodalConfig())
    assert list(m.status) == [mm.MatchStatus.FLAT, mm.MatchStatus.OK, mm.MatchStatus.NO_DATA]
    assert m.di[1] == pytest.approx(0, abs=0.05) and np.isnan(m.di[0])


def test_image_positions_interpolate_the_exact_projection():
    # a smooth, non-linear model with a height term
    def project(lon, lat, h):
        return (1e4 * (lon - 5.0) + 30 * np.sin(3 * lat) + 0.02 * h,
                -1.2e4 * (lat - 44.0) + 5 * (lon - 5.0) ** 2 - 0.001 * h * (lon - 5))

    g = mm.GroundGrid.covering([5.0, 5.1], [44.0, 44.08], 50.0)
    lon, lat = g.nodes()
    h = 800 + 600 * np.sin(lon * 40) * np.cos(lat * 30)
    col, row = mm.image_positions(project, g, h)
    c_ref, r_ref = project(lon, lat, h)
    assert np.abs(col - c_ref).max() < 1e-3 and np.abs(row - r_ref).max() < 1e-3
    i, j = g.indices(lon[3, 7], lat[3, 7])
    assert (i, j) == pytest.approx((3, 7))


def test_bad_settings_are_refused():
    with pytest.raises(InputError):
        mm.MultimodalConfig(min_score=1.5)
    with pytest.raises(InputError):
        mm.GroundGrid.covering([5.0, np.nan], [44.0, 44.1], 20.0)


def test_splat_keeps_the_sum_and_the_centroid_and_drops_what_is_off_the_image():
    rng = np.random.default_rng(5)
    col, row = rng.uniform(2, 37, 500), rng.uniform(2, 27, 500)
    w = rng.uniform(0.5, 2.0, 500)
    img = mm.splat(col, row, w, (30, 40)).astype(np.float64)
    assert img.sum() == pytest.approx(w.sum(), rel=1e-5)
    r, c = np.mgrid[0:30, 0:40]
    assert (img * c).sum() / img.sum() == pytest.approx((w * col).sum() / w.sum(), abs=1e-4)
    assert (img * r).sum() / img.sum() == pytest.approx((w * row).sum() / w.sum(), abs=1e-4)
    one = mm.splat(np.array([3.0, 3.25, 99.0]), np.array([4.0, 4.0, 1.0]),
                   np.ones(3), (10, 10))
    # an integer position lands whole in its pixel, a quarter pixel splits 3:1, off: nothing
    assert one[4, 3] == pytest.approx(1.75) and one[4, 4] == pytest.approx(0.25)
    assert one.sum() == pytest.approx(2.0)


def test_radar_shadow_is_the_wall_height_over_the_rise_behind_the_wall():
    h = np.zeros((20, 60))
    h[:, 30:35] = 20.0  # a 20 m wall, the radar to the east (towards +columns)
    # the line of sight climbs 2.5 m per cell (a 5 m cell at cot(incidence) = 0.5... any):
    # behind the wall (west of column 30) the ground is hidden over 20 / 2.5 = 8 cells
    hidden = mm.radar_shadow(h, (0.0, 1.0), 2.5)
    row = hidden[10]
    assert not row[30:].any()  # the wall and the ground in front of it see the radar
    assert row[23:30].all() and not row[:21].any()
    # the radar to the west: the shadow falls east of the wall
    hidden_w = mm.radar_shadow(h, (0.0, -1.0), 2.5)[10]
    assert hidden_w[35:42].all() and not hidden_w[:35].any() and not hidden_w[44:].any()


def test_quantile_lut_learns_a_non_monotonic_grey_level_mapping():
    rng = np.random.default_rng(6)
    v = rng.uniform(0, 100, 20000)
    truth = np.where(v < 30, 2.0, np.where(v < 70, -1.0, 0.5))  # dark bright, mid dark...
    edges, lut = mm.quantile_lut(v, truth + rng.normal(0, 0.3, v.size), 20)
    got = mm.apply_lut(v, edges, lut)
    inside = (np.abs(v - 30) > 6) & (np.abs(v - 70) > 6)  # away from the bins astride a step
    assert np.abs(got - truth)[inside].max() < 0.1
    assert np.isnan(mm.apply_lut(np.array([np.nan]), edges, lut)[0])


def _patches(n=256, seed=7, cover=0.3, scale=6.0):
    rng = np.random.default_rng(seed)
    f = gaussian_filter(rng.standard_normal((n, n)), scale)
    return f > np.quantile(f, 1 - cover)


def test_sharpening_gives_the_blurred_dsm_back_its_steps():
    rng = np.random.default_rng(8)
    forest = _patches()
    truth = 500.0 + 0.01 * np.arange(256)[None, :] + 15.0 * forest  # 15 m trees on ground
    dsm = gaussian_filter(truth, 2.0) + rng.normal(0, 1.0, truth.shape)  # seen through a
    optical = np.where(forest, 60.0, 140.0) + rng.normal(0, 15.0, truth.shape)  # window
    dsm[:20, :20] = np.nan  # a hole stays a hole
    sharp, cls, ground = mm.sharpened_surface(dsm, optical, 20.0, 20.0)
    assert cls.dark and cls.height_m == pytest.approx(15.0, rel=0.15)
    assert cls.blur_m == pytest.approx(40.0, abs=10.0) and cls.r2 > 0.3
    assert cls.percentile == pytest.approx(30.0, abs=5.0)  # the darkest 30 %: the trees
    inner = (slice(25, -25), slice(25, -25))
    before = np.sqrt(np.nanmean((dsm - truth)[inner] ** 2))
    after = np.sqrt(np.nanmean((sharp - truth)[inner] ** 2))
    assert after < 0.6 * before
    assert np.isnan(sharp[:20, :20]).all()
    # the bare ground: the other class, away from the trees
    assert not (ground & forest).any() and 0.2 < ground.mean() < 0.7
    # a DSM the grey levels do not explain is left as it is
    noise = 500.0 + rng.normal(0, 3.0, truth.shape)
    same, none, everywhere = mm.sharpened_surface(noise, optical, 20.0, 20.0)
    assert none.height_m == 0.0 and np.array_equal(same, noise) and everywhere.all()


def test_trees_on_hills_are_found_though_the_relief_dwarfs_them():
    # 450 m of relief over 10 km (slopes of 9 degrees), shaded by the sun: the DSM's detail
    # at the kilometre is the terrain's, 17 m trees are a few percent of it; within a few
    # hundred metres they are the detail. A high-pass of 1 km found no class here.
    rng = np.random.default_rng(10)
    hills = gaussian_filter(rng.standard_normal((512, 512)), 15.0)
    hills = 800.0 + hills * 450.0 / np.ptp(hills)
    forest = _patches(512, seed=11, cover=0.3, scale=8.0)
    truth = hills + 17.0 * forest
    dsm = gaussian_filter(truth, 2.0) + rng.normal(0, 1.0, truth.shape)
    optical = (np.where(forest, 40.0, 120.0) + 150.0 * np.gradient(hills, axis=1) / 20.0
               + rng.normal(0, 10.0, truth.shape))
    sharp, cls, ground = mm.sharpened_surface(dsm, optical, 20.0, 20.0)
    assert cls.dark and cls.percentile == pytest.approx(30.0, abs=5.0)
    assert 12.0 < cls.height_m < 20.0 and cls.blur_m <= 50.0
    inner = (slice(25, -25), slice(25, -25))
    before = np.sqrt(np.mean((dsm - truth)[inner] ** 2))
    assert np.sqrt(np.mean((sharp - truth)[inner] ** 2)) < 0.85 * before
    assert (ground & forest).mean() < 0.01 * ground.mean()


def test_the_shading_of_hills_is_no_class_of_trees():
    rng = np.random.default_rng(9)
    hills = 200.0 * gaussian_filter(rng.standard_normal((256, 256)), 12.0) / 0.02
    hills = 800.0 + hills * 150.0 / np.ptp(hills)  # 150 m of relief over 5 km
    dsm = gaussian_filter(hills, 2.0) + rng.normal(0, 1.0, hills.shape)
    sun_east = np.gradient(hills, axis=1) / 20.0  # slopes facing the sun are bright
    optical = 120.0 + 300.0 * sun_east + rng.normal(0, 5.0, hills.shape)
    same, cls, ground = mm.sharpened_surface(dsm, optical, 20.0, 20.0)
    assert cls.height_m == 0.0 and np.array_equal(same, dsm) and ground.all()
