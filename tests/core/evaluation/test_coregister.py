"""Nuth & Kaab coregistration on the real SRTM tile against shifted copies of itself."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
import rasterio
from affine import Affine
from scipy.ndimage import shift as nd_shift

from core.dem import GeoDEM, SurfaceGrid
from core.errors import InputError, InsufficientDataError
from core.evaluation.coregister import _Sampler, _weighted_median, nuth_kaab
from core.geodesy import metres_per_degree
from tasks.io.geoid import BUNDLED_SRTM_DIR, load_geoid

D = 1 / 1200


@pytest.fixture(scope="module")
def srtm() -> np.ndarray:
    z = np.fromfile(BUNDLED_SRTM_DIR / "N44E005.hgt", dtype=">i2").reshape(1201, 1201)
    z = z.astype(np.float64)
    z[z < -1000] = np.nan
    return z[300:800, 300:800]  # Mont Ventoux and its valleys, 500 x 500 cells


def shifted(z, col_px, row_px, dz, noise_m=0.0, seed=0):
    """A DEM whose content is the reference moved by (col, row) pixels (bicubic), dz lower."""
    filled = np.where(np.isnan(z), np.nanmean(z), z)
    out = nd_shift(filled, (-row_px, -col_px), order=3, mode="nearest") - dz
    out += np.random.default_rng(seed).normal(0, noise_m, z.shape)
    out[np.isnan(z)] = np.nan
    return out


@pytest.mark.parametrize(("col", "row", "dz", "noise"),
                         [(0.3, -0.45, 0.0, 0.0), (-0.27, 0.61, 12.5, 0.5), (1.3, 0.2, -3.0, 1.0)])
def test_known_subpixel_shift_recovered(srtm, col, row, dz, noise):
    ref = GeoDEM(srtm, 5.25, 44.75, D, -D)
    r = nuth_kaab(ref, GeoDEM(shifted(srtm, col, row, dz, noise), 5.25, 44.75, D, -D))
    assert r.shift_col_px == pytest.approx(col, abs=0.01)
    assert r.shift_row_px == pytest.approx(row, abs=0.01)
    assert r.shift_up_m == pytest.approx(dz, abs=0.05)
    me, mn = metres_per_degree(44.5)
    assert r.shift_east_m == pytest.approx(col * D * float(me), rel=0.01)
    assert r.shift_north_m == pytest.approx(-row * D * float(mn), rel=0.01)
    assert r.nmad_after_m < max(noise, 0.01) * 1.6


def test_translated_samples_are_the_general_lookups(srtm):
    """The separable resampling of a grid with the reference's steps gives what
    ``map_coordinates`` gives at the same points, voids, borders and beyond included."""
    z = srtm.copy()
    z[100:104, 200:203] = np.nan
    z[0:2, 50:60] = np.nan
    ref = GeoDEM(z, 5.25, 44.75, D, -D)
    sample = _Sampler(ref)
    for row0, col0, shape in [(0.3, -0.45, (500, 500)), (-2.7, 5.2, (300, 400)),
                              (10.0, 3.0, (50, 60)), (490.2, -3.5, (30, 30)),
                              (97.5, 196.25, (10, 10)), (600.0, 0.0, (5, 5))]:
        i, j = np.mgrid[0:shape[0], 0:shape[1]]
        general = sample(5.25 + (col0 + j) * D, 44.75 - (row0 + i) * D)
        fast = sample.translated(row0, col0, shape)
        np.testing.assert_array_equal(np.isnan(fast), np.isnan(general))
        np.testing.assert_allclose(fast, general, rtol=0, atol=1e-6, equal_nan=True)
    assert np.isnan(sample.translated(97.5, 196.25, (10, 10))[3:6, 3:6]).all()  # the void


@pytest.mark.parametrize("seed", range(5))
def test_weighted_median_is_the_median_of_the_repeated_values(seed):
    rng = np.random.default_rng(seed)
    values = rng.normal(size=int(rng.integers(1, 30)))
    counts = rng.integers(0, 6, size=values.size).astype(float)
    counts[0] += 1  # at least one value
    assert _weighted_median(values, counts) == np.median(np.repeat(values, counts.astype(int)))


def test_a_dem_on_another_grid_with_voids(srtm):
    """A DEM with twice the reference's step (the general look-up) and voids: the shift is
    still recovered to 0.01 reference pixels."""
    moved = shifted(srtm, 0.42, -0.31, 5.0, noise_m=0.3)[::2, ::2].copy()
    moved[40:60, 100:130] = np.nan
    r = nuth_kaab(GeoDEM(srtm, 5.25, 44.75, D, -D), GeoDEM(moved, 5.25, 44.75, 2 * D, -2 * D))
    assert r.shift_col_px == pytest.approx(0.42, abs=0.01)
    assert r.shift_row_px == pytest.approx(-0.31, abs=0.01)
    assert r.shift_up_m == pytest.approx(5.0, abs=0.05)


def test_projected_grids(srtm):
    ref = SurfaceGrid(srtm, 650_000.0, 4_950_000.0, 30.0, -30.0)
    r = nuth_kaab(ref, SurfaceGrid(shifted(srtm, -0.4, 0.25, 2.0), 650_000.0, 4_950_000.0, 30.0,
                                   -30.0))
    assert r.shift_east_m == pytest.approx(-0.4 * 30.0, abs=0.3)
    assert r.shift_north_m == pytest.approx(-0.25 * 30.0, abs=0.3)


def test_bad_inputs(srtm):
    ref = GeoDEM(srtm, 5.25, 44.75, D, -D)
    with pytest.raises(InputError, match="both be geographic"):
        nuth_kaab(ref, SurfaceGrid(srtm, 0.0, 0.0, 30.0, -30.0))
    with pytest.raises(InsufficientDataError, match="overlap"):
        nuth_kaab(ref, GeoDEM(srtm, 9.25, 44.75, D, -D))


def test_cli_on_geotiffs(srtm, tmp_path):
    """The reference in EGM96 heights (its tag says so), the DEM in ellipsoidal heights
    h = H + N (about 50 m more here): the heights are compared in one datum, so the vertical
    shift is the 4 m put in, not the geoid undulation."""
    tr = Affine(D, 0, 5.25 - D / 2, 0, -D, 44.75 + D / 2)
    rows, cols = np.mgrid[0:srtm.shape[0], 0:srtm.shape[1]]
    n_m = load_geoid().undulation_m(tr.c + (cols + 0.5) * D, tr.f - (rows + 0.5) * D)
    assert n_m.min() > 48.0
    for name, z, datum in (("ref.tif", srtm, "EGM96 geoid"),
                           ("dem.tif", shifted(srtm, 0.35, -0.2, 4.0) + n_m, "WGS84 ellipsoid")):
        with rasterio.open(tmp_path / name, "w", driver="GTiff", width=z.shape[1],
                           height=z.shape[0], count=1, dtype="float32", crs="EPSG:4326",
                           transform=tr, nodata=np.nan) as dst:
            dst.write(z.astype(np.float32), 1)
            dst.update_tags(vertical_datum=datum)
    out = tmp_path / "result.json"
    r = subprocess.run([sys.executable, "-m", "flows.cli", "coregister", "--reference",
                        str(tmp_path / "ref.tif"), "--dem", str(tmp_path / "dem.tif"), "--out",
                        str(out)], capture_output=True, text=True, timeout=120, check=False)
    assert r.returncode == 0, r.stderr
    assert "EGM96 orthometric heights" in r.stdout and "WGS84 ellipsoidal heights" in r.stdout
    doc = json.loads(out.read_text())
    assert doc["shift_col_px"] == pytest.approx(0.35, abs=0.01)
    assert doc["shift_row_px"] == pytest.approx(-0.2, abs=0.01)
    assert doc["shift_up_m"] == pytest.approx(4.0, abs=0.05)
    assert doc["reference_vertical"]["vertical"] == "egm96"
    assert doc["dem_vertical"]["vertical"] == "ellipsoidal"
    r = subprocess.run([sys.executable, "-m", "flows.cli", "coregister", "--ref",
                        str(tmp_path / "none.tif"), "--dem", str(tmp_path / "dem.tif"), "--out",
                        str(out)], capture_output=True, text=True, timeout=60, check=False)
    assert r.returncode == 2 and "does not exist" in r.stderr and "Traceback" not in r.stderr
