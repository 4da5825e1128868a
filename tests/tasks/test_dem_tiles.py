"""References beyond SRTM (issue 45 item 2): Copernicus GLO-30 on its own lattice through a geoid
grid of its own, its masks, NASADEM and tagged DEMs, and the pixel-is-point trap.

The geoid grids here are made (the real EGM2008 grid is not reachable on these machines): a
known field written as GTX and as a north-up GeoTIFF like PROJ's ``us_nga_egm08_25.tif``, and
N is checked independently by PROJ's ``vgridshift`` on the very same file. The real GLO-30
tile is the crop of ``tests/data/copernicus_glo30`` (its README says how it was cut: its first
node is 164.75 W, 54.6 N, cells 1.5" x 1")."""

from __future__ import annotations

import json
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pyproj
import pytest
import rasterio
from rasterio.transform import from_origin

from core.errors import CoverageError, InputError
from core.geodesy import BBox
from tasks.io.dem_tiles import DemSource, find_tiles
from tasks.io.geoid import BUNDLED_SRTM_DIR, read_geoid
from tasks.io.reference import VOID_HEIGHT_ERROR, VOID_WATER, build_reference, locate_tiles

DATA = Path(__file__).resolve().parents[1] / "data"
GLO = DATA / "copernicus_glo30"
GLO_NAME = "Copernicus_DSM_COG_10_N54_00_W165_00_DEM.tif"
CROP_LON0, CROP_LAT0 = -164.75, 54.6  # the crop's first node (its README)
DX, DY = 1.5 / 3600, 1.0 / 3600  # GLO-30's cells between 50 and 60 N
HGT = BUNDLED_SRTM_DIR / "N44E005.hgt"
VENTOUX = DATA / "pleiades_ventoux"


def field_m(lon: np.ndarray, lat: np.ndarray) -> np.ndarray:
    """The made geoid: a known smooth field of some metres, nothing like EGM96 here."""
    return 8.0 + 3.0 * np.sin(np.radians(400.0 * lon)) + 2.0 * np.cos(np.radians(600.0 * lat))


def write_gtx(path: Path, lon0: float, lat0: float, n: int, step: float = 0.05) -> Path:
    """The field on an ``n`` x ``n`` GTX grid from (lon0, lat0) (row 0 south, as GTX is)."""
    lat, lon = np.mgrid[0:n, 0:n] * step
    values = field_m(lon0 + lon, lat0 + lat)
    with path.open("wb") as f:
        f.write(np.array([lat0, lon0, step, step], ">f8").tobytes())
        f.write(np.array(values.shape, ">i4").tobytes())
        f.write(values.astype(">f4").tobytes())
    return path


def write_geotiff_grid(path: Path, lon0: float, lat0: float, n: int, step: float = 0.05
                       ) -> Path:
    """The same field as a north-up pixel-is-point GeoTIFF, as PROJ's grids are."""
    lat, lon = np.mgrid[0:n, 0:n] * step
    north = lat0 + (n - 1) * step
    values = field_m(lon0 + lon, north - lat).astype(np.float32)
    with rasterio.open(path, "w", driver="GTiff", width=n, height=n, count=1, dtype="float32",
                       crs="EPSG:4326", transform=from_origin(lon0 - step / 2, north + step / 2,
                                                              step, step)) as dst:
        dst.update_tags(AREA_OR_POINT="Point")
        dst.write(values, 1)
    return path


def proj_n(grid: Path, lon: np.ndarray, lat: np.ndarray) -> np.ndarray:
    """N by PROJ's vgridshift from the same grid file: the independent oracle."""
    t = pyproj.Transformer.from_pipeline(
        f"+proj=pipeline +step +proj=vgridshift +grids={grid} +multiplier=1")
    assert "ballpark" not in t.description.lower()
    _, _, n = t.transform(np.ravel(lon), np.ravel(lat), np.zeros(np.size(lon)))
    return np.asarray(n).reshape(np.shape(lon))


def build(source: DemSource, box: BBox, out: Path, allow_missing: bool = False):
    return build_reference.fn(locate_tiles.fn(source, box, allow_missing), box, out)


def read(path: Path) -> tuple[np.ndarray, rasterio.Affine]:
    with rasterio.open(path) as src:
        return src.read(1).astype(np.float64), src.transform


@pytest.fixture(scope="module")
def crop() -> np.ndarray:
    with rasterio.open(GLO / GLO_NAME) as src:
        return src.read(1).astype(np.float64)


@pytest.mark.parametrize("kind", ["gtx", "geotiff"])
def test_a_glo30_reference_is_the_tile_plus_n_at_its_own_cell_centres(kind, crop, tmp_path):
    """The real GLO-30 crop through a made EGM2008 grid: the reference keeps the tile's own
    1.5" x 1" lattice, node for node (none moved by half a cell, none resampled), and its
    heights are the tile's plus N there, N by PROJ from the same file, to the millimetre."""
    make = write_gtx if kind == "gtx" else write_geotiff_grid
    grid = make(tmp_path / f"egm08_made.{'gtx' if kind == 'gtx' else 'tif'}", -166.0, 53.0, 61)
    box = BBox(-164.74, 54.51, -164.66, 54.59)
    s = build(DemSource(GLO, geoid=grid), box, tmp_path / "ref.tif")
    h, t = read(Path(s.path))
    assert (t.a, t.e) == (pytest.approx(DX, abs=1e-15), pytest.approx(-DY, abs=1e-15))
    j0 = (t.c + t.a / 2 - CROP_LON0) / DX  # the first node of the reference, in crop cells
    i0 = (CROP_LAT0 - (t.f + t.e / 2)) / DY
    assert abs(j0 - round(j0)) < 1e-6 and abs(i0 - round(i0)) < 1e-6, (j0, i0)
    j0, i0 = round(j0), round(i0)
    ii, jj = np.mgrid[0:h.shape[0], 0:h.shape[1]]
    lon, lat = CROP_LON0 + (jj + j0) * DX, CROP_LAT0 - (ii + i0) * DY
    assert lon.min() >= box.lon_min and lon.max() <= box.lon_max
    assert lon.min() - DX < box.lon_min and lon.max() + DX > box.lon_max  # every node in it
    expected = crop[i0:i0 + h.shape[0], j0:j0 + h.shape[1]] + proj_n(grid, lon, lat)
    assert np.abs(h - expected).max() < 1e-3
    assert np.ptp(expected - crop[i0:i0 + h.shape[0], j0:j0 + h.shape[1]]) > 1.0  # N varies
    doc = json.loads(Path(s.path).with_suffix(".json").read_text())
    assert doc["product"] == "Copernicus GLO-30"
    assert (doc["res_arcsec"], doc["res_lat_arcsec"]) == (1.5, 1.0)
    assert doc["heights"]["vertical"] == "egm2008" and doc["heights"]["geoid"] == str(grid)
    assert doc["heights"]["vertical_source"] == f"Copernicus GLO-30 file {GLO_NAME}: EGM2008"
    with rasterio.open(s.path) as src:
        assert src.tags()["vertical_datum"] == (
            f"WGS84 ellipsoid (h = Copernicus GLO-30 H + N, EGM2008, grid {grid.name})")


def test_a_geotiff_grid_reads_as_proj_reads_it(tmp_path):
    """A GeoTIFF geoid grid (north-up, pixel-is-point) read whole and over a box gives PROJ's N
    from the same file; a global grid whose last column repeats the first wraps."""
    grid = write_geotiff_grid(tmp_path / "g.tif", -166.0, 53.0, 61)
    rng = np.random.default_rng(3)
    lon, lat = rng.uniform(-166.0, -163.0, 500), rng.uniform(53.0, 56.0, 500)
    for g in (read_geoid(grid), read_geoid(grid, BBox(-165.5, 54.0, -164.0, 55.5))):
        inside = (lon >= g.lon0_deg) & (lon <= g.lon0_deg + (g.shape[1] - 1) * g.dlon_deg) & \
            (lat >= g.lat0_deg) & (lat <= g.lat0_deg + (g.shape[0] - 1) * g.dlat_deg)
        assert inside.sum() > 100
        np.testing.assert_allclose(g.undulation_m(lon[inside], lat[inside]),
                                   proj_n(grid, lon[inside], lat[inside]), atol=1e-4)
    text = tmp_path / "grid.txt"
    text.write_text("not a grid")
    with pytest.raises(InputError, match="GTX"):
        read_geoid(text)


def _write_dem(path: Path, z: np.ndarray, tr, kind: str, tags: dict[str, str] | None = None,
               dtype: str = "int16", nodata: float | None = -32768) -> Path:
    with rasterio.open(path, "w", driver="GTiff", width=z.shape[1], height=z.shape[0], count=1,
                       dtype=dtype, crs="EPSG:4326", transform=tr, nodata=nodata) as dst:
        dst.update_tags(AREA_OR_POINT=kind, **(tags or {}))
        dst.write(z.astype(dtype), 1)
    return path


def test_point_area_and_hgt_give_the_same_reference_to_the_millimetre(tmp_path):
    """One DEM (the bundled SRTM tile) as a ``.hgt`` (pixel-is-point by definition), a
    pixel-is-point GeoTIFF and a pixel-is-area GeoTIFF, as an SRTM-named tile and as a tagged
    DEM of its own extent, as tiles and read as a reference: one reference, to the millimetre.
    A file that falls in the trap (its point tiepoint written as the corner, the half-cell shift
    a peer library made) is off by metres: the comparison would see it."""
    from tasks.io.dem import read_reference

    with rasterio.open(HGT) as src:
        H, tr = src.read(1), src.transform
    win = (slice(600, 1141), slice(100, 701))  # a tagged DEM: lon 5.083-5.583, lat 44.05-44.5
    crop_tr = tr * rasterio.Affine.translation(100, 600)
    files = {"hgt": HGT}
    for kind in ("Point", "Area"):
        folder = tmp_path / f"srtm_{kind}"
        folder.mkdir()
        files[f"srtm_{kind}"] = _write_dem(folder / "N44E005.tif", H, tr, kind)
        folder = tmp_path / f"tagged_{kind}"
        folder.mkdir()
        files[f"tagged_{kind}"] = _write_dem(folder / "dem.tif", H[win], crop_tr, kind,
                                             {"vertical_datum": "EGM96 geoid"})
    trap = tmp_path / "trap"
    trap.mkdir()
    with rasterio.Env(GTIFF_POINT_GEO_IGNORE=True):  # the tiepoint written as the corner
        _write_dem(trap / "N44E005.tif", H, tr, "Point")
    box = BBox(5.1, 44.1, 5.4, 44.4)
    pts = np.meshgrid(np.linspace(5.11, 5.39, 23), np.linspace(44.11, 44.39, 19))
    refs = {}
    for name, path in {**files, "trap": trap / "N44E005.tif"}.items():
        s = build(DemSource(path.parent), box, tmp_path / f"ref_{name}.tif")
        refs[name] = read(Path(s.path))
    h0, t0 = refs["hgt"]
    assert h0.shape == (361, 361) and np.isfinite(h0).mean() > 0.99
    for name, path in files.items():
        h, t = refs[name]
        assert t.almost_equals(t0, precision=1e-12) and h.shape == h0.shape, name
        np.testing.assert_allclose(h, h0, atol=1e-3, err_msg=name)
        # read as a --reference, alike too
        np.testing.assert_allclose(read_reference(path, box, "egm96").height_m(*pts),
                                   read_reference(HGT, box, "egm96").height_m(*pts), atol=1e-3)
    h, _ = refs["trap"]
    assert np.nanmax(np.abs(h - h0)) > 5.0  # half a 3" cell on the Ventoux's slopes


def _glo_tile(folder: Path, name: str, z: np.ndarray, lon0: float, lat0: float, dx: float,
              dy: float, dtype: str = "float32") -> Path:
    """A GLO-30-named tile (or crop, or mask) on its lattice from its first node (lon0, lat0),
    pixel-is-point as distributed."""
    folder.mkdir(parents=True, exist_ok=True)
    return _write_dem(folder / name, z, from_origin(lon0 - dx / 2, lat0 + dy / 2, dx, dy),
                      "Point", dtype=dtype, nodata=None)


def test_copernicus_masks_beside_the_tiles_void_water_and_unreliable_cells(crop, tmp_path):
    """The ESA layout (``<tile>/DEM/`` and ``<tile>/AUXFILES/``): water (WBM 1-3), a height
    error above the limit (HEM) and a void of the editing mask (EDM 0) become voids, each
    counted; a looser limit keeps the unreliable cells."""
    stem = "Copernicus_DSM_10_N54_00_W165_00"
    root = tmp_path / "esa" / stem
    (root / "DEM").mkdir(parents=True)
    shutil.copy(GLO / GLO_NAME, root / "DEM" / f"{stem}_DEM.tif")
    wbm = np.zeros(crop.shape, np.uint8)
    wbm[10:40, 20:60] = 2  # a lake
    hem = np.full(crop.shape, 1.5, np.float32)
    hem[100:120, 100:130] = 25.0  # steep, incoherent
    edm = np.ones(crop.shape, np.uint8)
    edm[200:205, 50:55] = 0
    for kind, z, dtype in (("WBM", wbm, "uint8"), ("HEM", hem, "float32"), ("EDM", edm, "uint8")):
        _glo_tile(root / "AUXFILES", f"{stem}_{kind}.tif", z, CROP_LON0, CROP_LAT0, DX, DY,
                  dtype)
    grid = write_gtx(tmp_path / "g.gtx", -166.0, 53.0, 61)
    box = BBox(CROP_LON0, CROP_LAT0 - 359 * DY, CROP_LON0 + 239 * DX, CROP_LAT0)  # the crop
    s = build(DemSource(tmp_path / "esa", geoid=grid), box, tmp_path / "ref.tif")
    with rasterio.open(s.void_mask_path) as src:
        code = src.read(1)
    h, _ = read(Path(s.path))
    assert code.shape == crop.shape
    expected = np.zeros(crop.shape, np.uint8)
    expected[hem > 10] = VOID_HEIGHT_ERROR
    expected[wbm == 2] = VOID_WATER
    expected[edm == 0] = 1
    np.testing.assert_array_equal(code, expected)
    assert np.array_equal(np.isnan(h), expected > 0)
    n = crop.size
    assert s.water_pct == pytest.approx(100 * 1200 / n)
    assert s.void_pct == pytest.approx(100 * 25 / n)
    assert s.height_error_pct == pytest.approx(100 * 600 / n) and s.max_height_error_m == 10.0
    loose = build(DemSource(tmp_path / "esa", geoid=grid, max_height_error_m=30.0), box,
                  tmp_path / "loose.tif")
    assert loose.height_error_pct == 0.0 and loose.water_pct == s.water_pct


def test_tiles_are_checked_against_their_product(crop, tmp_path):
    """A GLO-30 tile above 50 N with 1" columns is not as distributed; two products over one
    box are refused (their geoids need not be one); NASADEM's zip is read as distributed,
    EGM96 by its name; a crop that misses
    part of the box says so unless voids are allowed."""
    from tasks.io.dem import tile_datum

    bad = tmp_path / "bad"
    _glo_tile(bad, GLO_NAME, crop, CROP_LON0, CROP_LAT0, DY, DY)
    with pytest.raises(InputError, match='1" x 1" cells.*its product puts 1.5" x 1"'):
        find_tiles(bad, BBox(-164.74, 54.51, -164.7, 54.55))
    srtm1, nasa = tmp_path / "srtm1", tmp_path / "nasa"
    srtm1.mkdir()
    nasa.mkdir()
    H3 = np.fromfile(HGT, ">i2").reshape(1201, 1201)
    H1 = np.pad(H3[:-1, :-1].repeat(3, 0).repeat(3, 1), ((0, 1), (0, 1)), mode="edge")  # 1"
    H1.astype(">i2").tofile(srtm1 / "N44E005.hgt")
    with zipfile.ZipFile(nasa / "NASADEM_HGT_n44e005.zip", "w") as z:  # as LP DAAC gives it
        z.write(srtm1 / "N44E005.hgt", "n44e005.hgt")
    box = BBox(5.1, 44.1, 5.2, 44.2)
    d = tile_datum(find_tiles(nasa, box)).datum
    assert (d.datum, d.geoid, d.source) == ("egm96", None,
                                            "NASADEM file NASADEM_HGT_n44e005.zip: EGM96")
    h_nasa, t = read(Path(build(DemSource(nasa), box, tmp_path / "nasa.tif").path))
    h_srtm, _ = read(Path(build(DemSource(srtm1), box, tmp_path / "srtm.tif").path))
    assert t.a == pytest.approx(DY) and h_nasa.shape == (361, 361)
    np.testing.assert_array_equal(h_nasa, h_srtm)  # the same heights inside the zip
    shutil.copy(HGT, nasa / "N44E005.hgt")
    with pytest.raises(InputError, match="more than one product.*SRTM.*NASADEM"):
        find_tiles(nasa, box)
    with pytest.raises(CoverageError, match="covers lon -164.75000..-164.65042.*only"):
        find_tiles(GLO, BBox(-164.8, 54.51, -164.7, 54.55))
    assert len(find_tiles(GLO, BBox(-164.8, 54.51, -164.7, 54.55), allow_missing=True)) == 1


def test_proj_own_egm2008_grid_is_used_when_proj_has_it(monkeypatch, tmp_path):
    """Without --geoid, EGM2008 heights go through PROJ's us_nga_egm08_25.tif when it is in
    PROJ's data (here the user's PROJ folder, where projsync puts it), and say so."""
    import pyproj.datadir

    from tasks.io.dem import dem_datum

    write_geotiff_grid(tmp_path / "us_nga_egm08_25.tif", -166.0, 53.0, 61)
    monkeypatch.setattr(pyproj.datadir, "get_user_data_dir", lambda *a, **k: str(tmp_path))
    d = dem_datum(GLO / GLO_NAME, geoid_option="--geoid")
    assert (d.datum, d.geoid, d.geoid_source) == (
        "egm2008", str(tmp_path / "us_nga_egm08_25.tif"), "PROJ's grid")
    with pytest.raises(InputError, match="does not convert"):  # a command without --geoid
        dem_datum(GLO / GLO_NAME, what="DEM", option="--dem-vertical")


def _main(argv: list[str], capsys) -> tuple[int, str, str]:
    from flows.cli import main

    rc = main(argv)
    cap = capsys.readouterr()
    return rc, cap.out, cap.err


def test_glo30_without_a_grid_is_refused_in_one_line_naming_geoid(crop, tmp_path, capsys):
    """prepare-reference, orient --dem-dir and orient --reference on EGM2008 heights with no
    grid: one line naming --geoid, exit 2, nothing written; never read as EGM96."""
    ventoux = _glo_tile(tmp_path / "glo_n44", "Copernicus_DSM_COG_10_N44_00_E005_00_DEM.tif",
                        np.full((900, 1200), 500.0), 5.0, 44.5, DY, DY)
    pair = ["--left", str(VENTOUX / "left_image.tif"), "--right",
            str(VENTOUX / "right_image.tif")]
    cases = [["prepare-reference", "--dem-dir", str(GLO), "--bbox", "-164.74", "54.51",
              "-164.7", "54.55", "--out", str(tmp_path / "out" / "ref.tif")],
             ["orient", *pair, "--dem-dir", str(ventoux.parent), "--out", str(tmp_path / "out")],
             ["orient", *pair, "--reference", str(ventoux), "--out", str(tmp_path / "out")]]
    for argv in cases:
        rc, _, err = _main(argv, capsys)
        lines = err.strip().splitlines()
        assert rc == 2 and len(lines) == 1, err
        assert "EGM2008" in lines[0] and "--geoid GRID" in lines[0], lines[0]
        assert "never read as EGM96" in lines[0]
        assert not (tmp_path / "out").exists()


def test_a_geoid_given_for_srtm_tiles_replaces_egm96(tmp_path):
    """Today's ``prepare-reference --geoid``: SRTM's EGM96 heights through the grid given
    instead of the bundled one (the reference is the tile + N of that grid, by PROJ)."""
    grid = write_gtx(tmp_path / "other.gtx", 4.0, 43.0, 61)
    box = BBox(5.1, 44.1, 5.3, 44.3)
    s = build(DemSource(BUNDLED_SRTM_DIR, geoid=grid), box, tmp_path / "ref.tif")
    h, t = read(Path(s.path))
    H = np.fromfile(HGT, ">i2").reshape(1201, 1201).astype(np.float64)
    i0, j0 = round((45.0 - (t.f + t.e / 2)) * 1200), round((t.c + t.a / 2 - 5.0) * 1200)
    ii, jj = np.mgrid[0:h.shape[0], 0:h.shape[1]]
    expected = H[i0:i0 + h.shape[0], j0:j0 + h.shape[1]] + proj_n(
        grid, 5.0 + (jj + j0) / 1200, 45.0 - (ii + i0) / 1200)
    ok = np.isfinite(h)
    assert ok.mean() > 0.99 and np.abs(h - expected)[ok].max() < 1e-3
    assert s.heights == {"vertical": "egm96", "vertical_source": "SRTM file N44E005.hgt: EGM96",
                         "geoid": str(grid), "geoid_source": "given: --geoid"}
