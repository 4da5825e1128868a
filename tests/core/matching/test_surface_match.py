"""Local surface matching on synthetic terrain with a degraded, SRTM-like reference: known
shifts recovered, precision estimates honest, flat or masked windows refused."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

from core.dem import GeoDEM
from core.matching.peaks import quadratic_peak
from core.matching.surface import (
    SurfaceMatchConfig,
    WindowMatch,
    WindowStatus,
    correlation_surface,
    match_window,
    shift_prior,
)
from core.simulation.fields import fbm

LON0, LAT0 = 5.25, 44.2
M_LON, M_LAT = 79_800.0, 111_130.0  # metres per degree near 44.2 N (the test's own frame)


def terrain(lon, lat, relief=400.0):
    x, y = (lon - LON0) * M_LON, (lat - LAT0) * M_LAT
    return 800.0 + relief * fbm(x, y, 7, 6000.0, 6)


def reference(relief=400.0, noise_m=4.0, seed=0, void_fraction=0.0) -> GeoDEM:
    """SRTM-like: 3" grid of the terrain with spatially correlated noise and voids."""
    rng = np.random.default_rng(seed)
    d = 3 / 3600
    lons = LON0 - 0.15 + np.arange(int(0.3 / d)) * d
    lats = LAT0 + 0.15 - np.arange(int(0.3 / d)) * d
    ll, pp = np.meshgrid(lons, lats)
    noise = gaussian_filter(rng.normal(0, 1, ll.shape), 3)
    h = terrain(ll, pp, relief) + noise * noise_m / noise.std()
    if void_fraction:  # SRTM voids come in patches (steep slopes, shadows, water)
        blobs = gaussian_filter(rng.normal(0, 1, ll.shape), 6)
        h[blobs > np.quantile(blobs, 1.0 - void_fraction)] = np.nan
    return GeoDEM(h, lons[0], lats[0], d, -d)


def relative_dem(shift, relief=400.0, seed=1, spacing_m=40.0, radius_m=4500.0):
    """The relative DEM around the centre: the terrain seen shifted by (dlon", dlat", dh m)."""
    rng = np.random.default_rng(seed)
    xs = np.arange(-radius_m, radius_m, spacing_m)
    x, y = np.meshgrid(xs, xs)
    lon, lat = LON0 + x / M_LON, LAT0 + y / M_LAT
    h = terrain(lon + shift[0] / 3600, lat + shift[1] / 3600, relief) - shift[2]
    return lon, lat, h + rng.normal(0, 2.0, h.shape)


@pytest.fixture(scope="module")
def ref():
    return reference()


@pytest.mark.parametrize("shift", [(7.3, -4.6, 12.0), (-13.8, 9.1, -25.0), (0.4, 0.2, 3.0)])
def test_known_shift_recovered(ref, shift):
    lon, lat, h = relative_dem(shift)
    w = match_window(lon, lat, h, (LON0, LAT0), ref)
    assert w.ok and w.correlation > 0.99
    err_e = (w.shift_lon_arcsec - shift[0]) / 3600 * M_LON
    err_n = (w.shift_lat_arcsec - shift[1]) / 3600 * M_LAT
    # the reference's correlated noise: 4 m (errors 2.1-3.5 m here; 2.1-3.1 m when the window
    # lattice used the approximate metres per degree: another sampling of the same noise)
    assert np.hypot(err_e, err_n) < 4.0
    assert abs(w.shift_h_m - shift[2]) < 1.0
    assert w.shift_east_m == pytest.approx(w.shift_lon_arcsec / 3600 * M_LON, rel=2e-3)
    # the precisions are of the size of the errors, and the prediction agrees with the measure
    assert 0.5 < w.precision_m < 6.0 and 0.5 < w.predicted_precision_m < 6.0
    assert 0.5 < w.precision_m / w.predicted_precision_m < 2.0


@pytest.mark.parametrize("detrend", [True, False])
def test_a_tilted_relative_dem_is_matched_about_its_plane(ref, detrend):
    """A relative DEM tilted by 5 m/km (an along-epipolar drift the tie points cannot see):
    comparing the surfaces about their planes recovers the shift, and the height at the
    centre; comparing them raw confuses the tilt with a slope and misplaces the window."""
    shift = (7.3, -4.6, 12.0)
    lon, lat, h = relative_dem(shift)
    x, y = (lon - LON0) * M_LON, (lat - LAT0) * M_LAT
    h = h + 5.0 * (x + 0.5 * y) / 1000.0
    w = match_window(lon, lat, h, (LON0, LAT0), ref, replace(SurfaceMatchConfig(),
                                                             detrend=detrend))
    err = np.hypot((w.shift_lon_arcsec - shift[0]) / 3600 * M_LON,
                   (w.shift_lat_arcsec - shift[1]) / 3600 * M_LAT)
    if detrend:
        assert w.ok and err < 3.5 and abs(w.shift_h_m - shift[2]) < 1.0
    else:
        assert err > 10.0


def test_a_curved_relative_dem_gives_its_height_at_the_centre(ref):
    """A relative DEM curved across the swath (the parallax a lens the delivered models lack
    leaves: simulated tiny with --lens, the windows' vertical shift +80 m at one end of the
    swath, 0 in the middle, -68 m at the other, 5 m/km2 of curvature near the ends): found
    curved, compared about their quadratic surfaces, the window finds the shift and the height
    at the centre.
    About their planes the curvature the terrain shares moved it 16.7 m (on that scene the
    swath's end GCPs were 6-14 m off east, their heights followed the vertical shift, and the
    lens terms extrapolated that to 0.45 px of check-point columns beyond the last GCP)."""
    shift = (7.3, -4.6, 12.0)
    lon, lat, h = relative_dem(shift)
    x, y = (lon - LON0) * M_LON / 1000.0, (lat - LAT0) * M_LAT / 1000.0
    h = h + 20.0 * x + 2.5 * x**2 + 1.0 * x * y
    w = match_window(lon, lat, h, (LON0, LAT0), ref)
    err = np.hypot((w.shift_lon_arcsec - shift[0]) / 3600 * M_LON,
                   (w.shift_lat_arcsec - shift[1]) / 3600 * M_LAT)
    assert w.ok and err < 3.5  # about a plane: 16.7 m (10.8 E, -12.7 N), the terrain sharing it
    # the quadratic's value at the centre has twice the standard error of a plane's (0.74 m
    # over 12 draws of the reference's noise, 0.34 m about a plane)
    assert abs(w.shift_h_m - shift[2]) < 2.0


def test_a_window_cut_by_the_dem_edge_says_where_its_shift_holds(ref):
    """The relative DEM deformed by 15 m/km east across the swath (the steepest part of the
    deformation a lens the delivered models miss leaves, simulated tiny with ``--lens``) and cut
    1 km east of the tie point (the stereo overlap's edge): all its cells matched, the window
    measures the deformation where they are, 1.17 km west of the tie point (the cut disk's
    centroid; 150 m at the tie point, 132 m there: placed at the tie point, the GCP would be
    17.5 m off), and says where that is, a relative point on its surface. Whole windows hold
    at their centre."""
    from core.matching.lattice import site, window_cells

    rng = np.random.default_rng(3)
    xs = np.arange(-4500.0, 4500.0, 40.0)
    x, y = np.meshgrid(xs, xs)
    east = 150.0 + 0.015 * x  # the deformation, m east: 150 m at the tie point
    lon, lat = LON0 + x / M_LON, LAT0 + y / M_LAT
    h = terrain(lon + east / M_LON, lat) - 12.0 + rng.normal(0, 2.0, x.shape)
    h[x > 1000.0] = np.nan
    w = match_window(lon, lat, h, (LON0, LAT0), ref)
    assert w.ok
    at_x, at_y = (w.at_lon_deg - LON0) * M_LON, (w.at_lat_deg - LAT0) * M_LAT
    assert -1300.0 < at_x < -1050.0 and abs(at_y) < 150.0  # the cut disk's centroid: -1.17 km
    assert abs(w.shift_east_m - (150.0 + 0.015 * at_x)) < 4.0 and abs(w.shift_north_m) < 4.0
    # the cells span 75 m of deformation, which one translation leaves in the height
    # differences where the terrain slopes: 2.2 m here (0.2 m with the window cut symmetric
    # about its tie point, 3454 of its 7316 cells, as it was before)
    assert abs(w.shift_h_m - 12.0) < 3.0
    assert abs(w.at_h_m - terrain(w.at_lon_deg + (150.0 + 0.015 * at_x) / M_LON, w.at_lat_deg)
               + 12.0) < 25.0  # a lattice cell's mean height (113 m cells over this relief)
    # holes scattered over a window (mismatches, voids) leave it at its centre
    h = terrain(lon, lat)
    h[rng.random(h.shape) < 0.2] = np.nan
    cells = window_cells(lon, lat, h, (LON0, LAT0), 4000.0, 90.0)
    assert np.hypot(cells.x_m[site(cells)], cells.y_m[site(cells)]) < 100.0


def test_a_coarse_relative_dem_is_placed_where_its_cells_are():
    """A relative DEM of 80 m cells (tiny's) averaged onto the window's lattice of 113 m: a
    lattice cell holds 1-4 of them, off its centre by up to half a cell, and by more at the
    DEM's edge, where only its inner part is covered. Against a reference without noise the
    window then finds the shift within a metre, whole or cut by the DEM's edge, once each
    lattice cell's height is placed where its cells are. Placed at the lattice cells' centres
    (before), the same windows were 1.2 m RMS off whole (0.8 m of it a bias east) and 2.9 m
    cut; over the eight tiny scenes of ``bench/validation/uncertainty_sweep.py`` the windows the DEM's
    edge cuts put their GCPs 1.8 m inwards on average, 0.6 m now."""
    ref = reference(noise_m=0.0)
    errors = []
    for seed in range(6):
        rng = np.random.default_rng(seed)
        xs = np.arange(-4500.0, 4500.0, 80.0)
        x, y = np.meshgrid(xs + rng.uniform(0, 80.0), xs + rng.uniform(0, 80.0))
        lon, lat = LON0 + x / M_LON, LAT0 + y / M_LAT
        inward = [(1.0, 0.0), (0.0, -1.0), (-1.0, 0.0)][seed % 3]
        for cut in (False, True):
            shift = rng.uniform(-8.0, 8.0, 2)
            h = terrain(lon + shift[0] / 3600, lat + shift[1] / 3600) + rng.normal(0, 1.0, x.shape)
            if cut:
                h[-(x * inward[0] + y * inward[1]) > rng.uniform(700.0, 1300.0)] = np.nan
            w = match_window(lon, lat, h, (LON0, LAT0), ref)
            assert w.ok
            errors.append(np.hypot((w.shift_lon_arcsec - shift[0]) / 3600 * M_LON,
                                   (w.shift_lat_arcsec - shift[1]) / 3600 * M_LAT))
    errors = np.array(errors)
    assert errors.max() < 1.6 and np.sqrt(np.mean(errors**2)) < 0.9


def test_precision_estimate_is_honest_over_many_noise_draws():
    """Over independent reference noise, the scatter of the recovered shift matches the stated
    precision within a factor of two."""
    shift = (5.0, -3.0, 0.0)
    errs, precs = [], []
    for seed in range(5):
        r = reference(seed=10 + seed)
        lon, lat, h = relative_dem(shift, seed=seed)
        w = match_window(lon, lat, h, (LON0, LAT0), r, SurfaceMatchConfig(refine_step_arcsec=None))
        errs.append(((w.shift_lon_arcsec - shift[0]) / 3600 * M_LON,
                     (w.shift_lat_arcsec - shift[1]) / 3600 * M_LAT))
        precs.append(w.precision_m)
    spread = float(np.sqrt(np.mean(np.square(errs))))
    assert 0.4 < spread / float(np.mean(precs)) < 2.5


def test_voids_are_tolerated_and_counted():
    r = reference(void_fraction=0.15)
    lon, lat, h = relative_dem((3.0, 2.0, 5.0))
    h[::7, ::3] = np.nan  # mismatched cells of the relative DEM
    w = match_window(lon, lat, h, (LON0, LAT0), r)
    assert w.ok and 0.05 < w.masked_share < 0.5
    assert abs((w.shift_lon_arcsec - 3.0) / 3600 * M_LON) < 4.0


def test_flat_terrain_is_refused_with_its_relief():
    r = reference(relief=2.0)
    lon, lat, h = relative_dem((3.0, 2.0, 5.0), relief=2.0)
    w = match_window(lon, lat, h, (LON0, LAT0), r, SurfaceMatchConfig(max_precision_m=5.0))
    assert w.status == WindowStatus.LOW_RELIEF
    assert w.relief_m < 5.0 and w.predicted_precision_m > 5.0
    _round_trips_through_windows_json(w)


def _round_trips_through_windows_json(*windows: WindowMatch) -> None:
    """Each window written into windows.json and read back has every field it had: NaN
    (written as null: a refused window's shifts) back as NaN, the status by name, the
    integers as integers. Compares field by field with NaN equal to NaN: a dataclass's ``==``
    is False on a NaN, which let the test this replaces pass whatever came back."""
    from dataclasses import fields

    from core.jsonio import parse_json, to_json
    from core.matching.surface_file import WindowsFile
    from tasks.io.products import WINDOWS

    text = to_json(WINDOWS.dump(WindowsFile.of(range(len(windows)), windows, ())))
    back = WINDOWS.load(parse_json(text, "windows.json"))
    assert len(back.windows) == len(windows)
    for w, got in zip(windows, back.windows, strict=True):
        for f in fields(WindowMatch):
            a, b = getattr(w, f.name), getattr(got.match, f.name)
            assert type(b) is (float if isinstance(a, float) else type(a)), f.name
            assert a == b or (np.isnan(a) and np.isnan(b)), f"{f.name}: {a!r} came back {b!r}"
    nans = [f.name for w in windows for f in fields(w) if f.name != "status"
            and np.isnan(getattr(w, f.name))]
    assert text.count("null") == len(nans)


def test_a_matched_window_round_trips_through_windows_json():
    r = reference()
    w = match_window(*relative_dem((3.0, 2.0, 5.0)), (LON0, LAT0), r)
    assert w.ok and np.isfinite(w.shift_h_m)
    _round_trips_through_windows_json(w, replace(w, status=WindowStatus.EDGE_PEAK))


def test_window_outside_the_reference_is_refused():
    lon, lat, h = relative_dem((0.0, 0.0, 0.0))
    far = reference()
    w = match_window(lon + 1.0, lat, h, (LON0 + 1.0, LAT0), far)
    assert not w.ok and w.status in (WindowStatus.MASKED, WindowStatus.TOO_FEW_CELLS)


def with_blunders(lon, lat, h, seed, share=0.08):
    """The relative DEM with the gross blunders dense matching leaves, as measured on a
    simulated low-relief pair's relative DEM against its truth (80 m cells): 8 % of the cells,
    in clusters of 3 (median) to 58 cells (up to about 170 m across), 30-300 m off either way,
    three times more frequent next to mismatched cells (a ring of NaN around each here)."""
    rng = np.random.default_rng(seed)
    x, y = (lon - LON0) * M_LON, (lat - LAT0) * M_LAT
    h, hit = h.copy(), np.zeros(h.shape, dtype=bool)
    while hit.mean() < share:
        cx, cy = rng.uniform(-4500.0, 4500.0, 2)
        r = rng.uniform(40.0, 170.0)
        d = np.hypot(x - cx, y - cy)
        h[d < r] += rng.choice([-1.0, 1.0]) * rng.uniform(30.0, 300.0)
        hit |= d < r
        h[(d >= r) & (d < r + 60.0)] = np.nan
    return h


@pytest.mark.parametrize("seed", [2, 3, 5])
def test_blunders_of_the_relative_dem_do_not_move_the_window(seed):
    """Low relief (26 m about the plane) with 8 % of clustered blunders: the least-squares
    correlation follows the blunders (correlation 0.35-0.45 and 60-120 m off without their
    rejection); despiked, and matched again without the cells far from the reference at the
    peak, the window finds the shift the clean relative DEM gives, with the clean relief."""
    shift = (7.3, -4.6, 12.0)
    r = reference(relief=220.0, seed=seed)
    lon, lat, h = relative_dem(shift, relief=220.0, seed=seed)
    cfg = SurfaceMatchConfig(max_precision_m=50.0)
    clean = match_window(lon, lat, h, (LON0, LAT0), r, cfg)
    w = match_window(lon, lat, with_blunders(lon, lat, h, seed), (LON0, LAT0), r, cfg)
    assert clean.ok and w.ok and w.correlation > 0.95
    moved = np.hypot((w.shift_lon_arcsec - clean.shift_lon_arcsec) / 3600 * M_LON,
                     (w.shift_lat_arcsec - clean.shift_lat_arcsec) / 3600 * M_LAT)
    # the blunders and their rings of NaN take a fifth of the cells, another sample of the
    # reference's noise: moved 1.4-5.6 m over seeds 2-7 for a precision of 4.9-5.6 m
    assert moved < 1.2 * clean.precision_m
    assert w.relief_m == pytest.approx(clean.relief_m, rel=0.05)
    assert abs(w.shift_h_m - shift[2]) < 1.0 and w.precision_m < 1.5 * clean.precision_m


def test_despike_removes_spikes_and_keeps_the_terrain():
    """Isolated spikes of 50 m in a noisy window are all removed; the clean window keeps 98 %
    of its cells (a Gaussian's 3-sigma tails and the sharpest curvature)."""
    from core.matching.lattice import despike, window_cells

    lon, lat, h = relative_dem((0.0, 0.0, 0.0))
    cells = window_cells(lon, lat, h, (LON0, LAT0), 4000.0, 90.0)
    kept = np.isfinite(despike(cells).h_m)
    assert kept.sum() > 0.98 * np.isfinite(cells.h_m).sum()
    rng = np.random.default_rng(0)
    spiky = cells.h_m.copy()
    idx = rng.choice(np.flatnonzero(np.isfinite(spiky)), 60, replace=False)
    spiky[idx] += rng.choice([-50.0, 50.0], idx.size)
    out = despike(replace(cells, h_m=spiky))
    assert np.isnan(out.h_m[idx]).all()
    assert np.isfinite(out.h_m).sum() > 0.97 * np.isfinite(cells.h_m).sum()


def test_correlation_surface_peaks_at_the_known_shift(ref):
    """The report's figure (Goncalves's Fig. 5): terrain seen shifted by (6.3", -4.2") against
    the noisy reference. The surface's maximum is the grid node nearest the true shift, with
    the correlation match_window reports there; a quadratic through its 3x3 neighbourhood
    lands on the true shift; an empty window gives no correlation at all."""
    shift = (6.3, -4.2, 10.0)
    lon, lat, h = relative_dem(shift)
    cfg = SurfaceMatchConfig()
    shifts, rho = correlation_surface(lon, lat, h, (LON0, LAT0), ref, cfg)
    np.testing.assert_array_equal(shifts, np.arange(-20.0, 21.0))
    assert rho.shape == (41, 41) and np.isfinite(rho).all() and np.all(np.abs(rho) <= 1.0)
    iy, ix = np.unravel_index(np.argmax(rho), rho.shape)
    assert (shifts[ix], shifts[iy]) == (6.0, -4.0)  # rows are dlat, columns dlon
    w = match_window(lon, lat, h, (LON0, LAT0), ref, cfg)
    assert w.ok
    assert (round(w.shift_lon_arcsec), round(w.shift_lat_arcsec)) == (6, -4)
    assert rho[iy, ix] == pytest.approx(w.correlation, abs=1e-12)  # the same correlation
    (dx,), (dy,) = quadratic_peak(rho[iy - 1:iy + 2, ix - 1:ix + 2])
    assert abs(shifts[ix] + dx - shift[0]) < 0.15 and abs(shifts[iy] + dy - shift[1]) < 0.15
    # a single peak: every shift 5" or more from it correlates less (smooth terrain: slowly)
    gx, gy = np.meshgrid(shifts, shifts)
    far = np.hypot(gx - shifts[ix], gy - shifts[iy]) >= 5.0
    assert rho[far].max() < rho[iy, ix] - 0.005
    empty = correlation_surface(lon, lat, np.full_like(h, np.nan), (LON0, LAT0), ref, cfg)
    assert empty[1].shape == (41, 41) and np.isnan(empty[1]).all()


def test_search_prior_follows_the_scene_wide_misplacement(ref):
    """Windows misplaced by an offset plus a tilt across the scene: the affine fit of some
    windows' shifts predicts another's within a few tenths of an arcsecond, and a window
    searched only around that prediction finds the shift a full search finds."""
    rng = np.random.default_rng(3)
    lon = LON0 + rng.uniform(-0.2, 0.2, 12)
    lat = LAT0 + rng.uniform(-0.2, 0.2, 12)

    def shift(lo, la):
        return 4.0 + 10.0 * (lo - LON0), -3.0 + 6.0 * (la - LAT0)

    found = [WindowMatch(WindowStatus.OK, *shift(a, b), 0.0) for a, b in zip(lon, lat)]
    found[0] = WindowMatch(WindowStatus.LOW_CORRELATION, 15.0, 15.0, 0.0)  # not used
    prior = shift_prior(lon, lat, found, [LON0 + 0.1], [LAT0 - 0.1])
    assert prior.shape == (1, 3) and prior[0, 2] == pytest.approx(6.0)  # no scatter: minimum
    assert prior[0, :2] == pytest.approx(shift(LON0 + 0.1, LAT0 - 0.1), abs=1e-9)
    assert shift_prior(lon[:4], lat[:4], found[:4], [LON0], [LAT0]) is None  # too few
    truth = (7.3, -4.6, 12.0)
    lo, la, h = relative_dem(truth)
    full = match_window(lo, la, h, (LON0, LAT0), ref)
    near = match_window(lo, la, h, (LON0, LAT0), ref, prior=(6.0, -3.0, 4.0))
    assert near.ok and near.shift_lon_arcsec == pytest.approx(full.shift_lon_arcsec, abs=1e-6)
    assert near.shift_lat_arcsec == pytest.approx(full.shift_lat_arcsec, abs=1e-6)
    # a prior box that misses the peak says so instead of returning its border
    off = match_window(lo, la, h, (LON0, LAT0), ref, prior=(-6.0, 6.0, 4.0))
    assert off.status == WindowStatus.EDGE_PEAK


def test_two_pass_search_and_the_gcps_it_makes():
    """The first-pass windows are searched over the whole range, the others around the shift
    their affine fit predicts, and a window whose peak is on its prior box's border again
    over the whole range; every good window makes one GCP: its tie point moved by the shift,
    measured where the tie point is in each image, or where the window says its shift holds,
    measured where the tie point is moved as the models move that point from it."""
    from core.matching.surface import (
        MIN_GCP_SIGMA_H_M,
        first_pass_mask,
        gcps_from_windows,
        search_windows,
    )

    n = 30
    rng = np.random.default_rng(5)
    lon, lat = LON0 + rng.uniform(-0.2, 0.2, n), LAT0 + rng.uniform(-0.2, 0.2, n)
    first = first_pass_mask(n, 24)
    assert first.sum() == 24 and first[0] and first[-1]
    calls = []

    def match(idx, priors):
        calls.append((list(idx), None if priors is None else priors.copy()))
        out = []
        for k, i in enumerate(idx):
            edge = priors is not None and i == idx[0]  # the first prior-searched one
            out.append(WindowMatch(WindowStatus.EDGE_PEAK if edge else WindowStatus.OK,
                                   2.0 + lon[i] - LON0, -1.0, 3.0, precision_m=4.0,
                                   precision_h_m=0.1))
        return out

    found = search_windows(lon, lat, match)
    assert [len(c[0]) for c in calls] == [24, 6, 1]
    assert calls[0][1] is None and calls[1][1].shape == (6, 3) and calls[2][1] is None
    assert calls[2][0] == [calls[1][0][0]] and all(m.ok for m in found)
    np.testing.assert_allclose(calls[1][1][:, 0], 2.0 + lon[calls[1][0]] - LON0, atol=1e-9)
    h = np.full(n, 500.0)
    found[3] = replace(found[3], status=WindowStatus.MASKED)
    gcps = gcps_from_windows(np.arange(n), found, lon, lat, h,
                             {"left": (np.arange(n), np.zeros(n)), "right": (np.ones(n), h)})
    assert len(gcps) == n - 1 and [g.id for g in gcps[:3]] == [1, 2, 3]
    g = gcps[3]  # tie point 4 (3 was refused)
    assert g.lon_deg == pytest.approx(lon[4] + found[4].shift_lon_arcsec / 3600, abs=1e-12)
    assert g.lat_deg == pytest.approx(lat[4] - 1.0 / 3600, abs=1e-12) and g.h_m == 503.0
    assert g.image_points["left"].col == 4.0 and g.image_points["right"].row == 500.0
    assert g.sigma_xy_m == 4.0 and g.sigma_h_m == MIN_GCP_SIGMA_H_M
    assert g.source == "srtm_surface_match" and g.provenance["tie_point"] == 4
    # a window that says where its shift holds: its GCP is there, measured where the tie
    # point was, moved as the models move the point from the tie point to there
    at = replace(found[4], at_lon_deg=lon[4] + 0.01, at_lat_deg=lat[4], at_h_m=620.0)
    g = gcps_from_windows([4], [at], lon, lat, h,
                          {"left": (np.arange(n), np.zeros(n)), "right": (np.ones(n), h)},
                          lambda lo, la, hh: {"left": (lo * 100.0, hh), "right": (la, 7.0)})[0]
    assert g.lon_deg == pytest.approx(lon[4] + 0.01 + at.shift_lon_arcsec / 3600, abs=1e-12)
    assert g.h_m == 623.0 and g.image_points["left"].row == pytest.approx(120.0)
    assert g.image_points["left"].col == pytest.approx(5.0)  # 4 + 0.01 * 100
    assert g.image_points["right"].col == 1.0 and g.image_points["right"].row == 500.0
    assert g.provenance["tie_point"] == 4
