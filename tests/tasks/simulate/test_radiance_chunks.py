"""The simulator's radiance does not depend on how the truth grid is chunked (issue 21.6): each
block's cells are the grid's own. (Computed with ``map_overlap``, a block's position was taken
in the halo-padded array, which moved the texture by two cells per block index: a seam every
chunk, 1024 cells.)"""

from __future__ import annotations

import numpy as np
import pytest
import rasterio

from core.simulation.landcover import LandCover
from core.simulation.render import ground_radiance
from core.simulation.scene import ErrorConfig
from tasks.simulate import scene as S
from tasks.simulate.io import ScenePaths
from tests.scenes import CENTRE, DEM


def test_halo_cells_repeat_the_edge():
    np.testing.assert_array_equal(S.halo_cells(0, 4, 10), [0, 0, 1, 2, 3, 4])
    np.testing.assert_array_equal(S.halo_cells(4, 8, 10), [3, 4, 5, 6, 7, 8])
    np.testing.assert_array_equal(S.halo_cells(8, 10, 10), [7, 8, 9, 9])
    np.testing.assert_array_equal(S.halo_cells(0, 3, 3, halo=2), [0, 0, 0, 1, 2, 2, 2])


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    out = tmp_path_factory.mktemp("radiance_scene")
    return out, S.define_scene.fn(DEM, out, "tiny", 11, ErrorConfig(), centre_lonlat=CENTRE,
                                  date_change=0.1)


def surface(shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """A smooth hilly DSM (float32, as the truth raster, a few nodata cells) and a land cover
    of every class."""
    r, c = np.mgrid[0:shape[0], 0:shape[1]].astype(np.float64)
    dsm = (900.0 + 80.0 * np.sin(r / 17.0) * np.cos(c / 23.0) + 0.3 * c).astype(np.float32)
    dsm[100:103, 7:9] = np.nan
    classes = np.full(shape, LandCover.BARE_SOIL, dtype=np.uint8)
    classes[(r // 20 + c // 30) % 4 == 1] = LandCover.FOREST
    classes[(r // 20 + c // 30) % 4 == 2] = LandCover.URBAN
    classes[(r // 41) % 5 == 3] = LandCover.WATER
    return dsm, classes


def write_truth(out, scene, dsm: np.ndarray, classes: np.ndarray) -> ScenePaths:
    paths = ScenePaths(out)
    paths.truth.mkdir(parents=True, exist_ok=True)
    for path, a, nodata in ((paths.dsm, dsm, np.nan), (paths.landcover, classes, 0)):
        with rasterio.open(path, "w", driver="GTiff", width=a.shape[1], height=a.shape[0],
                           count=1, dtype=a.dtype, nodata=nodata, crs=f"EPSG:{scene.epsg}",
                           transform=rasterio.Affine(*scene.grid.geotransform())) as dst:
            dst.write(a, 1)
    return paths


def whole(scene, dsm: np.ndarray, classes: np.ndarray, image_index: int) -> np.ndarray:
    """The radiance of the whole grid in one piece: the reference the blocks must give."""
    h, w = dsm.shape
    xx, yy = scene.grid.cell_centres(-1, h + 1, -1, w + 1)
    sun = scene.preset_spec.images[image_index]
    rad = ground_radiance(xx, yy, np.pad(classes, 1, mode="edge"),
                          np.pad(dsm, 1, mode="edge").astype(np.float64), scene.grid.res_m,
                          sun.sun_azimuth_deg, sun.sun_elevation_deg, scene.seed,
                          scene.date_change if image_index == 1 else 0.0)
    return rad[1:-1, 1:-1].astype(np.float32)


@pytest.mark.parametrize("image_index", [0, 1])  # the second date has changes and clouds
def test_radiance_task_is_the_same_whatever_the_chunks(scene, monkeypatch, image_index):
    out, sc = scene
    dsm, classes = surface((150, 130))
    paths = write_truth(out, sc, dsm, classes)
    want = whole(sc, np.where(np.isnan(dsm), np.nanmean(dsm), dsm), classes, image_index)
    for chunk in (40, 64, 150):
        monkeypatch.setattr(S, "CHUNK", chunk)
        name = sc.image_names[image_index]
        paths.radiance(name).unlink(missing_ok=True)
        S.build_radiance.fn(sc, out, image_index)
        with rasterio.open(paths.radiance(name)) as src:
            got = src.read(1)
        ok = np.ones(dsm.shape, bool)
        ok[99:104, 6:10] = False  # NaN heights take their block's mean: not the whole one's
        np.testing.assert_array_equal(got[ok], want[ok], err_msg=f"chunks of {chunk}")


def test_blocks_in_memory_are_the_grids_cells(scene):
    """A block read from the rasters with its halo is ground_radiance of exactly those cells."""
    out, sc = scene
    dsm, classes = surface((90, 70))
    paths = write_truth(out, sc, dsm, classes)
    got = S.radiance(sc, 0, paths.dsm, paths.landcover, chunks=(30, 35)).compute(
        scheduler="sync")
    np.testing.assert_array_equal(got, whole(sc, dsm, classes, 0))
