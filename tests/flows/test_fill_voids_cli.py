"""``gcpfree fill-voids`` end to end on the simulator (issue 12, item 5): voids punched into an
SRTM tile of the tiny scene's truth terrain are filled from the scene's DSM (``gcpfree dsm
--no-orient`` with the truth models) within the DSM's LE68 against the truth; the command's
parser, its printed summary and JSON, and bad input stopped before Prefect starts."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pytest
import rasterio

from core.dem import sample_bilinear
from core.errors import InputError
from core.evaluation.evaluation import DzAccumulator, StatsConfig
from core.grid_points import affine_nodes
from flows.commands import dsm, fill_voids
from tasks.io.crs import Projection
from tasks.io.geoid import BUNDLED_SRTM_DIR, load_geoid
from tasks.io.srtm import SRTM_VOID

SRTM = BUNDLED_SRTM_DIR / "N44E005.hgt"
N = 1201
RES = 1.0 / 1200.0


def parse(command, name: str, *argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="gcpfree")
    command.add_parser(parser.add_subparsers(dest="command"))
    return parser.parse_args([name, *argv])


def raster_at(path: Path, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Bilinear values of a raster at points in its CRS (NaN outside and next to NaN)."""
    with rasterio.open(path) as src:
        z = src.read(1).astype(np.float64)
        fi, fj = affine_nodes(tuple(src.transform)[:6], x, y)
    return sample_bilinear(z, fi, fj)


def le68(dz: np.ndarray) -> float:
    acc = DzAccumulator(StatsConfig(n_bootstrap=0))
    acc.add(dz[np.isfinite(dz)])
    return acc.stats().le68_m


@pytest.fixture(scope="module")
def scene_dsm(prefect_harness, tiny_clean_scene, tmp_path_factory):
    """The tiny scene's DSM by ``gcpfree dsm --no-orient`` with the truth models (80 m)."""
    scene_dir, scene = tiny_clean_scene
    out = tmp_path_factory.mktemp("fill_dsm") / "dsm.tif"
    args = parse(dsm, "dsm", "--left", str(scene_dir / "left.tif"),
                 "--right", str(scene_dir / "right.tif"),
                 "--left-model", str(scene_dir / "truth" / "left_truth.json"),
                 "--right-model", str(scene_dir / "truth" / "right_truth.json"),
                 "--reference", str(SRTM), "--no-orient", "--no-progress", "--workers", "1",
                 "--out", str(out))
    assert dsm.run(args) == 0
    return scene_dir, scene, out


@pytest.fixture(scope="module")
def punched_tile(scene_dsm, tmp_path_factory):
    """A full-size N44E005.hgt: the scene's truth terrain (orthometric, whole metres) where it
    is known, the real tile elsewhere (with its own voids); voids punched on a lattice over the
    DSM (radius 2, 4, 6 cells every 24 cells) and one far from it.
    (tile, truth H, punched, the far void, epsg)."""
    scene_dir, _scene, dsm_path = scene_dsm
    r, c = np.mgrid[0:N, 0:N]
    lon, lat = 5.0 + c * RES, 45.0 - r * RES
    with rasterio.open(scene_dir / "truth" / "dtm.tif") as src:
        epsg = src.crs.to_epsg()
    proj = Projection(epsg)
    near = (np.abs(lon - 5.25) < 0.3) & (np.abs(lat - 44.2) < 0.25)
    x, y = proj.to_xy(lon[near], lat[near])
    geoid = load_geoid()
    truth = np.full((N, N), np.nan)
    truth[near] = geoid.ellipsoidal_to_orthometric(
        lon[near], lat[near], raster_at(scene_dir / "truth" / "dtm.tif", x, y))
    under_dsm = np.zeros((N, N), dtype=bool)
    under_dsm[near] = np.isfinite(raster_at(dsm_path, x, y))
    assert np.isfinite(truth[under_dsm]).all()
    real = np.fromfile(SRTM, dtype=">i2").reshape(N, N)
    H = np.where(np.isfinite(truth), np.rint(truth), real)
    punched = np.zeros((N, N), dtype=bool)
    rows, cols = np.nonzero(under_dsm)
    k = 0
    for i in range(rows.min(), rows.max(), 24):
        for j in range(cols.min(), cols.max(), 24):
            rad = (2, 4, 6)[k % 3]
            box = (slice(i - rad - 1, i + rad + 2), slice(j - rad - 1, j + rad + 2))
            d = (r[box] - i) ** 2 + (c[box] - j) ** 2 <= rad ** 2
            if under_dsm[box][d].all():
                punched[box] |= d
                k += 1
    far = (lon - 5.8) ** 2 + (lat - 44.8) ** 2 <= (5 * RES) ** 2
    H = np.where(punched | far, SRTM_VOID, H)
    folder = tmp_path_factory.mktemp("fill_tile")
    tile = folder / "N44E005.hgt"
    H.astype(">i2").tofile(tile)
    assert k > 60
    return tile, truth, punched, far, epsg


def test_punched_voids_are_filled_within_the_dsm_le68(scene_dsm, punched_tile, tmp_path,
                                                      capsys):
    scene_dir, _scene, dsm_path = scene_dsm
    tile, truth, punched, far, epsg = punched_tile
    out = tmp_path / "filled" / "N44E005.hgt"
    out.parent.mkdir()
    args = parse(fill_voids, "fill-voids", "--srtm", str(tile), "--dem", str(dsm_path),
                 "--out", str(out))
    assert fill_voids.run(args) == 0
    printed = capsys.readouterr().out
    assert "filled" in printed and "still void" in printed and "NMAD" in printed

    before = np.fromfile(tile, dtype=">i2").reshape(N, N)
    after = np.fromfile(out, dtype=">i2").reshape(N, N)
    assert out.stat().st_size == tile.stat().st_size
    void = before == SRTM_VOID
    assert (after[~void] == before[~void]).all()
    filled = void & (after != SRTM_VOID)
    doc = json.loads(out.with_suffix(".json").read_text())
    assert doc["n_void"] == void.sum() and doc["n_filled"] == filled.sum()
    assert doc["n_still_void"] == (after == SRTM_VOID).sum()
    assert (after[far] == SRTM_VOID).all()  # no DSM there
    assert filled[punched].mean() > 0.99  # the DSM is complete under the punched voids
    assert not (filled & ~punched).any()  # the tile's own voids lie outside the scene

    # the DSM's own LE68 against the truth surface, over all its cells
    with rasterio.open(dsm_path) as src:
        z = src.read(1).astype(np.float64)
        t = src.transform
    rr, cc = np.nonzero(np.isfinite(z))
    x, y = t.c + (cc + 0.5) * t.a, t.f + (rr + 0.5) * t.e
    dsm_le68 = le68(z[rr, cc] - raster_at(scene_dir / "truth" / "dsm.tif", x, y))
    # the filled cells against the truth terrain the tile holds
    m = filled & punched
    fill_le68 = le68(after[m] - truth[m])
    # the DSM alone on those cells (resampled and made orthometric as the fill does)
    lon, lat = 5.0 + np.nonzero(m)[1] * RES, 45.0 - np.nonzero(m)[0] * RES
    px, py = Projection(epsg).to_xy(lon, lat)
    raw = load_geoid().ellipsoidal_to_orthometric(lon, lat, raster_at(dsm_path, px, py))
    raw_le68 = le68(raw - truth[m])
    print(f"DSM LE68 {dsm_le68:.2f} m, fill LE68 {fill_le68:.2f} m on {m.sum()} cells, "
          f"DSM alone there {raw_le68:.2f} m; ring {doc['ring']}")
    # measured: DSM 12.15 m, fill 9.92 m, the DSM alone on the filled cells 13.71 m
    assert fill_le68 <= dsm_le68
    assert fill_le68 < raw_le68 - 1.0  # the delta surface takes out the DSM's local offset
    ring = doc["ring"]
    assert ring["count"] > 1000 and 0.0 < ring["mean"] < 15.0  # the DSM holds the canopy
    assert 0.0 < ring["nmad"] < 20.0


def test_bad_input_stops_before_prefect(tmp_path, punched_tile, scene_dsm):
    tile, *_ = punched_tile
    _, _, dsm_path = scene_dsm
    far = tmp_path / "far"
    far.mkdir()
    (far / "N10E010.hgt").write_bytes(tile.read_bytes())
    files = set(tmp_path.rglob("*"))
    cases = [
        ("format", tile, tmp_path / "x.tif", ()),
        ("does not exist", tmp_path / "N1E1.hgt", tmp_path / "N1E1.hgt", ()),
        ("--border-cells", tile, tmp_path / "N44E005.hgt", ("--border-cells", "0")),
        ("name it N44E005.hgt", tile, tmp_path / "filled.hgt", ()),
        ("does not overlap", far / "N10E010.hgt", tmp_path / "N10E010.hgt", ()),
    ]
    for match, srtm, out, extra in cases:
        with pytest.raises(InputError, match=match) as exc:
            fill_voids.run(parse(fill_voids, "fill-voids", "--srtm", str(srtm), "--dem",
                                 str(dsm_path), "--out", str(out), *extra))
        assert "\n" not in str(exc.value)
    assert set(tmp_path.rglob("*")) == files  # nothing written
