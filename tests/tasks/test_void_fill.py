"""``fill-voids`` tasks on a synthetic terrain: a tile (.hgt or GeoTIFF, EGM96 heights) with
voids, a UTM DSM of the same terrain in ellipsoidal or EGM96 heights with a datum error; the
voids come back in the tile's format and grid, and bad input is refused in one line. Then the
real Ventoux tile (bundled) with voids punched on its steep slopes and a DSM made from its own
heights + EGM96 + a bias (+ noise): the original heights come back."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import rasterio

from core.errors import CoverageError, InputError
from core.evaluation.void_fill import FillConfig
from core.geodesy import metres_per_degree
from tasks.evaluation.void_fill import (
    FillOptions,
    fill_tile_voids,
    plan_fill,
    read_tile,
    write_fill_report,
)
from tasks.io.crs import Projection
from tasks.io.geoid import BUNDLED_SRTM_DIR, load_geoid
from tasks.io.srtm import SRTM_VOID

RES = 1.0 / 1200.0  # 3"
UTM31 = 32631
DSM_BOX = (5.15, 44.15, 5.30, 44.25)  # lon/lat the DSM covers (roughly)
BIAS_M = 6.0  # the DSM's datum error: the fill must not keep it


def terrain_H(lon: np.ndarray, lat: np.ndarray) -> np.ndarray:
    """Smooth orthometric terrain (metres): relief of a few hundred metres over kilometres."""
    return 600.0 + 250.0 * np.sin((lon - 5.0) * 40.0) * np.cos((lat - 44.0) * 30.0)


def voids_at(lon: np.ndarray, lat: np.ndarray) -> np.ndarray:
    """Three voids under the DSM (radius 3-6 cells) and one outside it."""
    out = np.zeros(lon.shape, dtype=bool)
    for lo, la, r in ((5.20, 44.20, 6), (5.25, 44.18, 3), (5.22, 44.23, 4), (5.60, 44.60, 5)):
        out |= ((lon - lo) / RES) ** 2 + ((lat - la) / RES) ** 2 <= r ** 2
    return out


def write_dsm(path: Path, vertical: str = "ellipsoidal", cell_m: float = 30.0) -> Path:
    """The terrain as a UTM DSM with a +6 m error, NaN outside a rotated footprint."""
    proj = Projection(UTM31)
    x0, y0 = proj.to_xy(np.array([DSM_BOX[0]]), np.array([DSM_BOX[1]]))
    x1, y1 = proj.to_xy(np.array([DSM_BOX[2]]), np.array([DSM_BOX[3]]))
    xs = np.arange(float(x0[0]), float(x1[0]), cell_m) + cell_m / 2
    ys = np.arange(float(y1[0]), float(y0[0]), -cell_m) - cell_m / 2
    x, y = np.meshgrid(xs, ys)
    lon, lat = proj.to_lonlat(x, y)
    z = terrain_H(lon, lat) + BIAS_M
    if vertical == "ellipsoidal":
        z = load_geoid().orthometric_to_ellipsoidal(lon, lat, z)
    z[(x - xs[0]) + (y - ys[-1]) < 1500.0] = np.nan  # a corner without DSM
    tag = "WGS84 ellipsoid (EPSG:4979 heights)" if vertical == "ellipsoidal" else \
        "EGM96 geoid (EPSG:5773), H = h - N"
    profile = {"driver": "GTiff", "width": xs.size, "height": ys.size, "count": 1,
               "dtype": "float32", "crs": f"EPSG:{UTM31}", "nodata": np.nan,
               "transform": rasterio.Affine(cell_m, 0, xs[0] - cell_m / 2, 0, -cell_m,
                                            ys[0] + cell_m / 2)}
    with rasterio.open(path, "w", **profile) as dst:
        dst.write(z.astype(np.float32), 1)
        dst.update_tags(vertical_datum=tag, units="m")
    return path


def hgt_tile(folder: Path) -> tuple[Path, np.ndarray, np.ndarray]:
    """A full N44E005.hgt of the terrain with voids; (path, truth H, void mask)."""
    n = 1201
    r, c = np.mgrid[0:n, 0:n]
    lon, lat = 5.0 + c * RES, 45.0 - r * RES
    H = terrain_H(lon, lat)
    void = voids_at(lon, lat)
    path = folder / "N44E005.hgt"
    np.where(void, SRTM_VOID, np.rint(H)).astype(">i2").tofile(path)
    return path, H, void


def tif_tile(folder: Path, dtype: str = "int16") -> tuple[Path, np.ndarray, np.ndarray]:
    """A 241 x 181 node GeoTIFF tile (lon 5.1-5.3, lat 44.1-44.25) with SRTM conventions."""
    lon0, lat0, w, h = 5.1, 44.25, 241, 181
    r, c = np.mgrid[0:h, 0:w]
    lon, lat = lon0 + c * RES, lat0 - r * RES
    H = terrain_H(lon, lat)
    void = voids_at(lon, lat)
    nodata = SRTM_VOID if dtype == "int16" else np.nan
    values = np.where(void, nodata, np.rint(H) if dtype == "int16" else H).astype(dtype)
    path = folder / f"n44_e005_{dtype}.tif"  # named as USGS names its SRTM GeoTIFFs: EGM96
    with rasterio.open(path, "w", driver="GTiff", width=w, height=h, count=1, dtype=dtype,
                       crs="EPSG:4326", nodata=nodata, compress="deflate",
                       transform=rasterio.Affine(RES, 0, lon0 - RES / 2, 0, -RES,
                                                 lat0 + RES / 2)) as dst:
        dst.write(values, 1)
        dst.update_tags(AREA_OR_POINT="Point")
    return path, H, void


@pytest.fixture(scope="module")
def dsm(tmp_path_factory) -> Path:
    return write_dsm(tmp_path_factory.mktemp("dsm") / "dsm.tif")


def test_an_hgt_tile_is_filled_in_its_own_format(tmp_path, dsm):
    tile, H, void = hgt_tile(tmp_path)
    before = np.fromfile(tile, dtype=">i2").reshape(1201, 1201)
    out = tmp_path / "filled" / "N44E005.hgt"
    out.parent.mkdir()
    options = FillOptions(tile, dsm, out)
    s = fill_tile_voids.fn(options)
    assert out.stat().st_size == tile.stat().st_size
    after = np.fromfile(out, dtype=">i2").reshape(1201, 1201)
    assert (after[~void] == before[~void]).all()  # valid cells are the same bytes
    filled = void & (after != SRTM_VOID)
    assert s.n_void == void.sum() and s.n_filled == filled.sum()
    assert s.n_still_void == s.n_void - s.n_filled > 0  # the void outside the DSM
    assert s.n_voids_under_dem == 3
    # the 6 m datum error is measured on the ring and taken out; rounding to whole metres
    assert s.ring["mean"] == pytest.approx(BIAS_M, abs=0.3)
    err = after[filled] - H[filled]
    assert np.abs(err).max() <= 1.0, np.abs(err).max()
    # the tile read back by GDAL, as a .hgt named like the tile
    with rasterio.open(out) as src:
        assert src.read(1)[filled].tolist() == after[filled].tolist()
    path = write_fill_report.fn(s)
    doc = json.loads(Path(path).read_text())
    assert path == out.with_suffix(".json") and doc["format"] == "gcpfree.fill_voids"
    assert doc["n_filled"] == s.n_filled and doc["ring"]["count"] == s.ring["count"]
    assert any("still void" in line for line in s.lines())


@pytest.mark.parametrize("dtype", ["int16", "float32"])
def test_a_geotiff_tile_keeps_its_profile(tmp_path, dsm, dtype):
    tile, H, void = tif_tile(tmp_path, dtype)
    out = tmp_path / "filled.tif"
    s = fill_tile_voids.fn(FillOptions(tile, dsm, out))
    with rasterio.open(tile) as a, rasterio.open(out) as b:
        assert (a.profile | {"nodata": None}) == (b.profile | {"nodata": None})
        assert a.tags() == b.tags() and a.transform == b.transform
        assert (a.nodata == b.nodata) or (np.isnan(a.nodata) and np.isnan(b.nodata))
        before, after = a.read(1), b.read(1)
    filled = void & np.isfinite(after) & (after != SRTM_VOID)
    assert s.n_filled == filled.sum() > 0 and s.n_still_void == void.sum() - filled.sum()
    assert np.array_equal(after[~void], before[~void])
    assert np.abs(after[filled] - H[filled]).max() <= (1.0 if dtype == "int16" else 0.6)


def test_an_egm96_dsm_gives_the_same_fill(tmp_path, dsm):
    tile, _, _ = tif_tile(tmp_path, "float32")
    egm = write_dsm(tmp_path / "dsm_egm96.tif", vertical="egm96")
    a = fill_tile_voids.fn(FillOptions(tile, dsm, tmp_path / "a.tif"))
    b = fill_tile_voids.fn(FillOptions(tile, egm, tmp_path / "b.tif"))
    assert "EGM96" in b.dem_vertical_source and b.dem_vertical == "egm96"
    with rasterio.open(tmp_path / "a.tif") as fa, rasterio.open(tmp_path / "b.tif") as fb:
        np.testing.assert_allclose(fa.read(1), fb.read(1), atol=0.01)
    assert a.n_filled == b.n_filled


def test_reading_the_dsm_in_row_blocks_changes_nothing(tmp_path, dsm, monkeypatch):
    tile, _, _ = tif_tile(tmp_path, "float32")
    fill_tile_voids.fn(FillOptions(tile, dsm, tmp_path / "one.tif"))
    monkeypatch.setattr("tasks.evaluation.void_fill.BLOCK_ROWS", 7)
    fill_tile_voids.fn(FillOptions(tile, dsm, tmp_path / "blocks.tif"))
    with rasterio.open(tmp_path / "one.tif") as a, rasterio.open(tmp_path / "blocks.tif") as b:
        np.testing.assert_allclose(a.read(1), b.read(1), rtol=0, atol=1e-4)


def test_a_coarse_tile_averages_a_fine_dsm(tmp_path):
    """A 10 m DSM under 3" nodes is read averaged (decimation 6), never whole."""
    fine = write_dsm(tmp_path / "fine.tif", cell_m=10.0)
    tile, H, void = tif_tile(tmp_path, "float32")
    options = FillOptions(tile, fine, tmp_path / "out.tif")
    plan = plan_fill(options)
    assert plan.decimation == 6 and plan.dem_cell_m == pytest.approx(10.0)
    fill_tile_voids.fn(options)
    with rasterio.open(tmp_path / "out.tif") as src:
        after = src.read(1)
    filled = void & np.isfinite(after)
    assert np.abs(after[filled] - H[filled]).max() < 1.5


def test_bad_input_is_refused_in_one_line(tmp_path, dsm):
    tile, _, _ = hgt_tile(tmp_path)
    with pytest.raises(InputError, match="format"):
        plan_fill(FillOptions(tile, dsm, tmp_path / "out.tif"))
    with pytest.raises(InputError, match="does not exist; create it first"):
        plan_fill(FillOptions(tile, dsm, tmp_path / "no" / "N44E005.hgt"))
    renamed = tmp_path / "tile.hgt"
    renamed.write_bytes(tile.read_bytes())
    with pytest.raises(InputError, match="e.g. N44E005.hgt"):
        read_tile(renamed)
    short = tmp_path / "N45E005.hgt"
    short.write_bytes(b"\0" * 1000)
    with pytest.raises(InputError, match="truncated"):
        read_tile(short)
    far = tmp_path / "far"
    far.mkdir()
    (far / "N10E010.hgt").write_bytes(tile.read_bytes())
    with pytest.raises(CoverageError, match="does not overlap"):
        plan_fill(FillOptions(far / "N10E010.hgt", dsm, tmp_path / "N10E010.hgt"))
    with pytest.raises(InputError, match="is the input tile"):
        plan_fill(FillOptions(tile, dsm, tile))
    png = tmp_path / "N44E005.png"
    png.write_bytes(tile.read_bytes())
    with pytest.raises(InputError, match=r"give a \.hgt or a GeoTIFF"):
        read_tile(png)
    with pytest.raises(InputError, match="geographic"):
        read_tile(dsm)
    with pytest.raises(InputError, match="--srtm-vertical"):
        FillOptions(tile, dsm, tmp_path / "o.hgt", srtm_vertical="navd88")
    with pytest.raises(InputError, match="--border-cells"):
        FillConfig(border_cells=0)
    odd, _, _ = tif_tile(tmp_path, "float32")
    with rasterio.open(odd, "r+") as dst:
        dst.update_tags(vertical_datum="NAVD88")
    with pytest.raises(InputError, match="cannot convert"):
        read_tile(odd)
    navd = tmp_path / "dsm_navd88.tif"
    navd.write_bytes(dsm.read_bytes())
    with rasterio.open(navd, "r+") as dst:
        dst.update_tags(vertical_datum="NAVD88")
    with pytest.raises(InputError, match="cannot convert.*--dem-vertical"):
        plan_fill(FillOptions(tile, navd, far / "N44E005.hgt"))


# ---- the real Ventoux tile: voids punched on its steep slopes, a DSM made from its heights -----

REAL_TILE = BUNDLED_SRTM_DIR / "N44E005.hgt"  # real SRTM 3" tile, EGM96, with its own voids
CROP = (slice(900, 1100), slice(230, 450))  # nodes under the DSM: Mont Ventoux, 272-1898 m
N_REAL = 1201


def real_voids(H: np.ndarray, seed: int = 5) -> np.ndarray:
    """Voids of radius 2-5 cells centred on slopes steeper than 30 degrees inside the crop
    (where SRTM's own voids are: radar shadow and layover), and three outside it."""
    sub = H[CROP].astype(np.float64)
    m_lon, m_lat = metres_per_degree(44.17)
    gy, gx = np.gradient(sub, m_lat * RES, m_lon * RES)
    steep = np.degrees(np.arctan(np.hypot(gx, gy))) > 30.0
    steep[:10] = steep[-10:] = steep[:, :10] = steep[:, -10:] = False
    rng = np.random.default_rng(seed)
    seeds = np.argwhere(steep)[rng.choice(int(steep.sum()), 30, replace=False)]
    seeds += (CROP[0].start, CROP[1].start)
    seeds = np.vstack([seeds, [[500, 500], [700, 1000], [1150, 100]]])  # outside the DSM
    r, c = np.mgrid[0:N_REAL, 0:N_REAL]
    void = np.zeros(H.shape, dtype=bool)
    for (i, j), rad in zip(seeds, rng.integers(2, 6, len(seeds)), strict=True):
        box = (slice(i - rad, i + rad + 1), slice(j - rad, j + rad + 1))
        void[box] |= (r[box] - i) ** 2 + (c[box] - j) ** 2 <= rad ** 2
    return void


def real_case(folder: Path, bias_m: float, noise_m: float) -> tuple[Path, Path, np.ndarray,
                                                                       np.ndarray]:
    """The real tile with voids punched, as ``folder/N44E005.hgt``, and a lon/lat DSM on the
    tile's nodes under :data:`CROP`: the original heights + EGM96 N (ellipsoidal) + a bias +
    Gaussian noise, NaN where the tile is void. (tile, dsm, original heights, punched)."""
    H = np.fromfile(REAL_TILE, dtype=">i2").reshape(N_REAL, N_REAL)
    punched = real_voids(H) & (H != SRTM_VOID)
    tile = folder / "N44E005.hgt"
    np.where(punched, SRTM_VOID, H).astype(">i2").tofile(tile)
    r, c = np.mgrid[CROP]
    lon, lat = 5.0 + c * RES, 45.0 - r * RES
    z = H[CROP].astype(np.float64)
    z = load_geoid().orthometric_to_ellipsoidal(lon, lat, z) + bias_m
    z += np.random.default_rng(3).normal(0.0, noise_m, z.shape) if noise_m else 0.0
    z[H[CROP] == SRTM_VOID] = np.nan
    dsm = folder / "dsm_lonlat.tif"
    with rasterio.open(dsm, "w", driver="GTiff", width=z.shape[1], height=z.shape[0], count=1,
                       dtype="float32", crs="EPSG:4326", nodata=np.nan,
                       transform=rasterio.Affine(RES, 0, lon[0, 0] - RES / 2, 0, -RES,
                                                 lat[0, 0] + RES / 2)) as dst:
        dst.write(z.astype(np.float32), 1)
        dst.update_tags(vertical_datum="WGS84 ellipsoid (EPSG:4979 heights)")
    return tile, dsm, H, punched


def test_real_tile_a_biased_dsm_restores_the_original_bytes(tmp_path):
    """No noise, an 8 m bias: the delta surface takes the bias out exactly, so every punched
    void under the DSM gets its original height back; the rest stays void and is counted; the
    .hgt written is the tile GDAL reads, on the same grid."""
    tile, dsm, H, punched = real_case(tmp_path, bias_m=8.0, noise_m=0.0)
    out = tmp_path / "filled" / "N44E005.hgt"
    out.parent.mkdir()
    s = fill_tile_voids.fn(FillOptions(tile, dsm, out))
    after = np.fromfile(out, dtype=">i2").reshape(N_REAL, N_REAL)
    under = np.zeros(H.shape, dtype=bool)
    under[CROP] = True
    assert (after[punched & under] == H[punched & under]).all()  # the original heights
    assert (after[~(punched & under)] == np.where(punched, SRTM_VOID, H)[~(punched & under)]).all()
    real_void = H == SRTM_VOID
    assert s.n_filled == (punched & under).sum() > 500
    assert s.n_void == (punched | real_void).sum()
    assert s.n_still_void == (punched & ~under).sum() + real_void.sum() == (after == -32768).sum()
    assert s.ring["mean"] == pytest.approx(8.0, abs=1e-3) and s.ring["nmad"] < 1e-3
    assert s.srtm_vertical == "egm96" and s.dem_vertical == "ellipsoidal"
    assert out.stat().st_size == tile.stat().st_size
    # GDAL's SRTMHGT driver reads both on the same grid; the JSON holds the same counts
    with rasterio.open(tile) as a, rasterio.open(out) as b:
        assert b.driver == "SRTMHGT" and b.crs == a.crs and b.transform == a.transform
        assert (b.width, b.height, b.dtypes, b.nodata) == (a.width, a.height, a.dtypes, a.nodata)
        assert np.array_equal(b.read(1), after)
        assert tuple(read_tile(tile).transform) == tuple(a.transform)[:6]
    doc = json.loads(Path(write_fill_report.fn(s)).read_text())
    assert (doc["n_filled"], doc["n_still_void"]) == (s.n_filled, s.n_still_void)


def test_real_tile_a_noisy_biased_dsm_is_filled_to_its_noise(tmp_path):
    """An 8 m bias and 3 m of noise: the fill is unbiased and its error is the DSM's noise
    (plus a part of the ring's, and the rounding to whole metres), not the bias."""
    sigma = 3.0
    tile, dsm, H, punched = real_case(tmp_path, bias_m=8.0, noise_m=sigma)
    out = tmp_path / "filled.hgt"
    with pytest.raises(InputError, match="name it N44E005.hgt"):
        plan_fill(FillOptions(tile, dsm, out))
    out = tmp_path / "filled" / "N44E005.hgt"
    out.parent.mkdir()
    s = fill_tile_voids.fn(FillOptions(tile, dsm, out))
    after = np.fromfile(out, dtype=">i2").reshape(N_REAL, N_REAL)
    filled = punched & (after != SRTM_VOID)
    err = after[filled] - H[filled].astype(np.float64)
    rms = float(np.sqrt(np.mean(err ** 2)))
    assert abs(err.mean()) < 0.3 and 0.9 * sigma < rms < 1.4 * sigma, (err.mean(), rms)
    assert s.ring["mean"] == pytest.approx(8.0, abs=0.3)
    assert s.ring["nmad"] == pytest.approx(sigma, rel=0.1)
    assert s.n_ring_rejected < 0.001 * s.ring["count"]  # Gaussian noise: nothing is a blunder
