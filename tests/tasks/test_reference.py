"""SRTM reference preparation: exactness against PROJ, tiling, mosaics, errors, atomic writes."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pyproj
import pytest
import rasterio
from rasterio.transform import from_origin

from core.errors import CoverageError, InputError
from core.geodesy import BBox
from tasks.io.dem_tiles import find_tiles, mosaic_grid, required_tiles
from tasks.io.geoid import BUNDLED_SRTM_DIR, EGM96_GTX
from tasks.io.reference import build_reference, locate_tiles

HGT = BUNDLED_SRTM_DIR / "N44E005.hgt"


def proj_undulation(lon: np.ndarray, lat: np.ndarray) -> np.ndarray:
    """EGM96 N computed independently by PROJ from the same grid file."""
    t = pyproj.Transformer.from_pipeline(
        f"+proj=pipeline +step +proj=vgridshift +grids={EGM96_GTX} +multiplier=1"
    )
    _, _, n = t.transform(lon, lat, np.zeros_like(lon))
    return np.asarray(n)


def build(tmp_path: Path, bbox: BBox, srtm_dir: Path = BUNDLED_SRTM_DIR, allow_missing=False):
    tiles = locate_tiles.fn(srtm_dir, bbox, allow_missing)
    return build_reference.fn(tiles, bbox, tmp_path / "ref.tif")


@pytest.fixture(scope="module")
def ventoux(tmp_path_factory):
    return build(tmp_path_factory.mktemp("ref"), BBox(5.0, 44.0, 6.0, 45.0))


def test_cog_equals_srtm_plus_egm96_everywhere(ventoux):
    H = np.fromfile(HGT, dtype=">i2").reshape(1201, 1201).astype(np.float64)
    lat, lon = np.mgrid[0:1201, 0:1201]
    lon = 5.0 + lon / 1200.0
    lat = 45.0 - lat / 1200.0
    expected = H + proj_undulation(lon.ravel(), lat.ravel()).reshape(H.shape)
    expected[H == -32768] = np.nan
    with rasterio.open(ventoux.path) as src:
        got = src.read(1)
        assert src.crs.to_epsg() == 4326
        # node (0, 0) is at 5E 45N: the pixel-is-area corner sits half a cell to the NW
        assert src.transform.c == pytest.approx(5.0 - 0.5 / 1200, abs=1e-12)
        assert src.transform.f == pytest.approx(45.0 + 0.5 / 1200, abs=1e-12)
    assert got.shape == (1201, 1201) and got.dtype == np.float32
    np.testing.assert_array_equal(np.isnan(got), np.isnan(expected))
    ok = ~np.isnan(expected)
    assert np.abs(got[ok] - expected[ok]).max() < 0.01


def test_cog_is_tiled_with_overviews(ventoux):
    with rasterio.open(ventoux.path) as src:
        assert src.profile["tiled"]
        assert src.overviews(1)
        assert np.isnan(src.nodata)
        assert src.tags(ns="IMAGE_STRUCTURE").get("LAYOUT") == "COG"


def test_summary_and_void_mask(ventoux):
    H = np.fromfile(HGT, dtype=">i2")
    assert ventoux.void_pct == pytest.approx(100.0 * np.mean(H == -32768), rel=1e-9)
    assert ventoux.coverage_pct == 100.0
    assert (ventoux.H_min_m, ventoux.H_max_m) == (float(H[H > -32768].min()), float(H.max()))
    with rasterio.open(ventoux.void_mask_path) as src:
        m = src.read(1)
    assert np.array_equal(m.ravel() == 1, H == -32768)
    assert Path(ventoux.path).with_suffix(".json").exists()


def plane(lon: np.ndarray, lat: np.ndarray) -> np.ndarray:
    """A smooth analytic surface, identical along shared tile edges."""
    return np.round(500 + 300 * np.sin(3 * lon) + 200 * np.cos(2 * lat) + 50 * lon * lat / 10)


def write_hgt(folder: Path, lon0: int, lat0: int, size: int = 1201) -> None:
    j = np.arange(size)
    lon = lon0 + j / (size - 1)
    lat = lat0 + 1 - j / (size - 1)
    H = plane(lon[None, :], lat[:, None]).astype(">i2")
    name = f"N{lat0:02d}E{lon0:03d}.hgt"
    H.tofile(folder / name)


def test_mosaic_of_four_tiles_is_seamless(tmp_path):
    srtm = tmp_path / "srtm"
    srtm.mkdir()
    for lo in (10, 11):
        for la in (20, 21):
            write_hgt(srtm, lo, la)
    box = BBox(10.6, 20.7, 11.3, 21.2)  # straddles both tile seams
    s = build(tmp_path, box, srtm)
    with rasterio.open(s.path) as src:
        h = src.read(1).astype(np.float64)
        t = src.transform
    rows, cols = np.mgrid[0 : h.shape[0], 0 : h.shape[1]]
    lon = t.c + (cols + 0.5) * t.a
    lat = t.f + (rows + 0.5) * t.e
    exp = plane(lon, lat) + proj_undulation(lon.ravel(), lat.ravel()).reshape(h.shape)
    assert np.abs(h - exp).max() < 0.01
    assert lon.min() >= 10.6 - 1e-9 and lon.max() <= 11.3 + 1e-9
    assert s.coverage_pct == 100.0 and s.void_pct == 0.0


def test_one_arcsecond_geotiff_tile(tmp_path):
    srtm = tmp_path / "srtm"
    srtm.mkdir()
    n = 3601
    j = np.arange(n)
    lon = 7 + j / 3600.0
    lat = 46 - j / 3600.0
    H = plane(lon[None, :], lat[:, None]).astype(np.int16)
    H[100:110, 200:230] = -32768
    tr = from_origin(7 - 0.5 / 3600, 46 + 0.5 / 3600, 1 / 3600, 1 / 3600)
    with rasterio.open(srtm / "n45_e007_1arc_v3.tif", "w", driver="GTiff", width=n, height=n,
                       count=1, dtype="int16", crs="EPSG:4326", transform=tr, nodata=-32768) as d:
        d.write(H, 1)
    s = build(tmp_path, BBox(7.0, 45.9, 7.1, 46.0), srtm)
    assert s.res_arcsec == pytest.approx(1.0)
    assert (s.width, s.height) == (361, 361)
    assert s.void_pct == pytest.approx(100 * 300 / 361**2)


def test_required_tiles_and_grid():
    assert required_tiles(BBox(5.0, 44.0, 6.0, 45.0)) == [(5, 44)]
    assert required_tiles(BBox(-0.5, -0.5, 0.5, 0.5)) == [(-1, -1), (0, -1), (-1, 0), (0, 0)]


def test_bbox_outside_tiles_names_missing(tmp_path):
    with pytest.raises(CoverageError, match="N44E006.*N45E006|N45E005"):
        find_tiles(BUNDLED_SRTM_DIR, BBox(5.5, 44.5, 6.5, 45.5))
    tiles = find_tiles(BUNDLED_SRTM_DIR, BBox(5.5, 44.5, 6.5, 45.5), allow_missing=True)
    assert [t.path.name for t in tiles] == ["N44E005.hgt"]
    s = build_reference.fn(tiles, BBox(5.5, 44.5, 6.5, 45.5), tmp_path / "r.tif")
    assert s.coverage_pct == pytest.approx(25.0, abs=0.2)


def test_truncated_hgt_is_rejected(tmp_path):
    (tmp_path / "N44E005.hgt").write_bytes(HGT.read_bytes()[:100_000])
    with pytest.raises(InputError, match="malformed SRTM tile.*100000 bytes"):
        find_tiles(tmp_path, BBox(5.1, 44.1, 5.2, 44.2))


def test_unreadable_geotiff_is_rejected(tmp_path):
    (tmp_path / "N44E005.tif").write_bytes(b"not a tiff at all")
    with pytest.raises(InputError, match="cannot read SRTM tile"):
        find_tiles(tmp_path, BBox(5.1, 44.1, 5.2, 44.2))


def test_bad_bbox_is_rejected():
    with pytest.raises(InputError, match="LON_MIN < LON_MAX"):
        BBox(6.0, 44.0, 5.0, 45.0)


def test_failed_write_keeps_previous_product(tmp_path, monkeypatch):
    box = BBox(5.0, 44.0, 5.2, 44.2)
    first = build(tmp_path, box)
    before = Path(first.path).read_bytes()

    def boom(*a, **k):
        raise OSError("disk full")

    monkeypatch.setattr("rasterio.shutil.copy", boom)
    with pytest.raises(OSError, match="disk full"):
        build(tmp_path, BBox(5.0, 44.0, 5.3, 44.3))
    assert Path(first.path).read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        ["ref.tif", "ref.voids.tif", "ref.json"]
    )


def run_cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "flows.cli", *args], capture_output=True, text=True, timeout=120, check=False
    )


@pytest.mark.parametrize(
    "make_args, message",
    [
        (lambda d: ["--srtm-dir", str(d / "nope")], "does not exist"),
        (lambda d: ["--bbox", "8", "44", "9", "45"], "missing tile\\(s\\) N44E008"),
        (lambda d: ["--srtm-dir", str(d)], "malformed SRTM tile"),
    ],
)
def test_cli_errors_are_one_line(tmp_path, make_args, message):
    (tmp_path / "N44E005.hgt").write_bytes(HGT.read_bytes()[:5000])
    args = ["prepare-reference", "--bbox", "5.1", "44.1", "5.2", "44.2", "--out",
            str(tmp_path / "o.tif")]
    extra = make_args(tmp_path)
    if extra[0] == "--bbox":
        args[2:6] = extra[1:]
    else:
        args += extra
    r = run_cli(*args)
    assert r.returncode != 0
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, r.stderr
    assert "Traceback" not in r.stderr
    import re

    assert re.search(message, lines[0])
    assert not (tmp_path / "o.tif").exists()


def test_cli_help_describes_every_option():
    r = run_cli("prepare-reference", "--help")
    assert r.returncode == 0
    for opt in ("--bbox", "--srtm-dir", "--out", "--margin-deg", "--allow-missing-tiles",
                "--geoid", "--hillshade"):
        assert opt in r.stdout
    top = run_cli("--help")
    assert "prepare-reference" in top.stdout


def test_grid_of_tiny_box_is_rejected():
    tiles = find_tiles(BUNDLED_SRTM_DIR, BBox(5.1, 44.1, 5.2, 44.2))
    with pytest.raises(InputError, match="smaller than one SRTM cell"):
        mosaic_grid(tiles, BBox(5.10001, 44.10001, 5.10002, 44.10002))
