"""``--dem-dir`` and ``--geoid`` through the pair commands (issue 45 item 2): the options every
pair command takes, the pair's inputs that carry them, and the relative orientation of the clean
tiny pair against a Copernicus GLO-30-named tile made from its truth DSM through a made EGM2008
grid (the whole orientation, ``orient --dem-dir``, was run by hand: see the issue's note)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyproj
import pytest
import rasterio
from rasterio.transform import from_origin
from scipy.ndimage import map_coordinates

from core.errors import InputError
from tasks.io.pair import PairInputs

ARC = 1.0 / 3600
GLO_N44 = "Copernicus_DSM_COG_10_N44_00_E005_00_DEM.tif"


@pytest.mark.parametrize("command", ["relative", "dsm", "orient", "pair", "archive", "serve"])
def test_every_pair_command_takes_dem_dir_and_geoid(command, tmp_path):
    from flows.cli import build_parser

    common = (["--catalog", "c.csv", "--out", "o"] if command in ("archive", "serve")
              else ["--left", "l.tif", "--right", "r.tif", "--out", "o"])
    for flag in ("--dem-dir", "--srtm-dir"):
        args = build_parser().parse_args([command, *common, flag, "tiles", "--geoid", "g.tif"])
        assert (args.srtm_dir, args.geoid) == (Path("tiles"), Path("g.tif"))


def test_a_reference_with_a_geoid_is_prepared_as_tiles_are():
    pair = PairInputs("l.tif", "r.tif", reference="glo.tif", geoid="egm08.tif")
    assert (pair.reference, pair.srtm_dir, pair.geoid) == (None, Path("glo.tif"),
                                                           Path("egm08.tif"))
    assert pair.dem_source.path == Path("glo.tif") and pair.dem_source.geoid == Path("egm08.tif")
    assert pair.to_dict()["geoid"] == "egm08.tif"
    with pytest.raises(InputError, match="drop --geoid"):
        PairInputs("l.tif", "r.tif", reference="x.tif", reference_vertical="ellipsoidal",
                   geoid="g.gtx")


def made_field_m(lon: np.ndarray, lat: np.ndarray) -> np.ndarray:
    """A made 'EGM2008' near EGM96's +50 m there, off it by metres."""
    return 50.0 + 4.0 * np.sin(np.radians(400.0 * lon)) + 3.0 * np.cos(np.radians(600.0 * lat))


def make_glo30(scene: Path, folder: Path) -> tuple[Path, Path]:
    """A GLO-30 crop of the scene's truth DSM on the N44E005 tile's 1" lattice, its heights
    above a made geoid grid (GTX; N there by PROJ): (tile, grid)."""
    folder.mkdir()
    lat, lon = np.mgrid[0:61, 0:61] * 0.05
    grid = folder.parent / "egm08_made.gtx"
    with grid.open("wb") as f:
        f.write(np.array([43.0, 4.0, 0.05, 0.05], ">f8").tobytes())
        f.write(np.array([61, 61], ">i4").tobytes())
        f.write(made_field_m(4.0 + lon, 43.0 + lat).astype(">f4").tobytes())
    with rasterio.open(scene / "truth" / "dsm.tif") as src:
        dsm = src.read(1, masked=True).filled(np.nan).astype(np.float64)
        t, crs = src.transform, src.crs
        b = src.bounds
    to_ll = pyproj.Transformer.from_crs(crs, "EPSG:4326", always_xy=True)
    lo, la = to_ll.transform([b.left, b.left, b.right, b.right],
                             [b.bottom, b.top, b.bottom, b.top])
    k0, k1 = int(np.ceil((max(lo[:2]) - 5) * 3600)) + 9, int((min(lo[2:]) - 5) * 3600) - 9
    i0, i1 = int(np.ceil((45 - min(la[1::2])) * 3600)) + 9, int((45 - max(la[::2])) * 3600) - 9
    ii, kk = np.mgrid[i0:i1 + 1, k0:k1 + 1]
    node_lon, node_lat = 5 + kk * ARC, 45 - ii * ARC
    x, y = pyproj.Transformer.from_crs("EPSG:4326", crs, always_xy=True).transform(node_lon,
                                                                                   node_lat)
    col, row = ~t * (x, y)
    h = map_coordinates(dsm, [row - 0.5, col - 0.5], order=1, mode="nearest")
    vgrid = pyproj.Transformer.from_pipeline(
        f"+proj=pipeline +step +proj=vgridshift +grids={grid} +multiplier=1")
    _, _, n = vgrid.transform(node_lon.ravel(), node_lat.ravel(), np.zeros(node_lon.size))
    H = (h - np.asarray(n).reshape(h.shape)).astype(np.float32)
    tile = folder / GLO_N44
    with rasterio.open(tile, "w", driver="GTiff", width=H.shape[1], height=H.shape[0], count=1,
                       dtype="float32", crs="EPSG:4326",
                       transform=from_origin(5 + (k0 - 0.5) * ARC, 45 - (i0 - 0.5) * ARC, ARC,
                                             ARC)) as dst:
        dst.update_tags(AREA_OR_POINT="Point")
        dst.write(H, 1)
    return tile, grid


def test_relative_against_a_glo30_tile_through_its_own_geoid(prefect_harness, tiny_clean_scene,
                                                             tmp_path):
    """``relative`` with the tile folder and the grid: the reference it makes holds the truth
    DSM's heights again (h = H + N through the same grid) on the tile's own nodes, rel.json says
    which product and geoid they went through, and the orientation holds (its y-parallax as with
    the scene's own reference, under half a pixel)."""
    from flows.relative import RelativeParams, relative_flow

    scene, _ = tiny_clean_scene
    tile, grid = make_glo30(scene, tmp_path / "glo")
    out = tmp_path / "rel" / "rel.json"
    outcome = relative_flow(RelativeParams(
        pair=PairInputs(scene / "left.tif", scene / "right.tif", srtm_dir=tile.parent,
                        geoid=grid), out=out))
    made = out.with_name("rel.reference.tif")
    assert Path(outcome.reference) == made
    with rasterio.open(made) as ref, rasterio.open(tile) as src:
        h, H = ref.read(1).astype(np.float64), src.read(1).astype(np.float64)
        rt, tt = ref.transform, src.transform
        assert "EGM2008, grid egm08_made.gtx" in ref.tags()["vertical_datum"]
    assert abs(rt.a - ARC) < 1e-15 and abs(rt.e + ARC) < 1e-15  # the tile's own lattice
    c0, r0 = (rt.c - tt.c) / ARC, (tt.f - rt.f) / ARC  # the made reference's first node
    assert abs(c0 - round(c0)) < 1e-6 and abs(r0 - round(r0)) < 1e-6  # on the tile's nodes
    c0, r0 = round(c0), round(r0)
    rows = slice(max(0, -r0), min(h.shape[0], H.shape[0] - r0))
    cols = slice(max(0, -c0), min(h.shape[1], H.shape[1] - c0))
    got = h[rows, cols]
    tile_H = H[rows.start + r0:rows.stop + r0, cols.start + c0:cols.stop + c0]
    ii, jj = np.mgrid[rows, cols]
    lon, lat = rt.c + (jj + 0.5) * ARC, rt.f - (ii + 0.5) * ARC
    vgrid = pyproj.Transformer.from_pipeline(
        f"+proj=pipeline +step +proj=vgridshift +grids={grid} +multiplier=1")
    _, _, n = vgrid.transform(lon.ravel(), lat.ravel(), np.zeros(lon.size))
    assert got.size > 0.5 * H.size and np.isfinite(got).all()
    # the tile + N from the same grid by PROJ: the truth DSM's heights again
    assert np.abs(got - tile_H - np.asarray(n).reshape(got.shape)).max() < 1e-3
    rel = json.loads(out.read_text())
    assert rel["reference"]["path"] == str(made) and rel["reference"]["srtm_dir"] == str(
        tile.parent)
    assert "Copernicus GLO-30 H + N, EGM2008, grid egm08_made.gtx" in rel["reference"][
        "vertical_source"]
    assert rel["parallax_rms_after_px"] <= 0.3, rel["parallax_rms_after_px"]
