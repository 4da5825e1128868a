"""``gcpfree coregister``: read two DEM rasters, align one onto the other (Nuth & Kaab), write
the translation. The maths is :func:`core.evaluation.coregister.nuth_kaab`.

Both DEMs' vertical datums are decided by the one rule (:func:`tasks.io.dem.dem_datum`); when
they differ, the DEM's heights are brought to the reference's datum with the EGM96 geoid
(``h = H + N``) before the fit, so ``shift_up_m`` is a shift, not the geoid undulation.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyproj
import rasterio
from rasterio.warp import Resampling, reproject

from core.dem import GeoDEM, SurfaceGrid
from core.errors import InputError
from core.evaluation.coregister import CoregConfig, CoregResult, DemGrid, nuth_kaab
from core.heights import DatumDecision
from tasks.io.dem import dem_datum
from tasks.io.geoid import load_geoid
from tasks.io.rasters import atomic_write_json, open_raster, read_window
from tasks.io.srtm import SRTM_VOID

HINT = "give a GeoTIFF or .hgt"


def read_grid(path: str | Path, crs: object | None = None,
              like: rasterio.io.DatasetReader | None = None) -> tuple[DemGrid, object]:
    """A DEM raster as a grid (:class:`~core.dem.GeoDEM` or :class:`~core.dem.SurfaceGrid`,
    NaN voids), reprojected onto ``like``'s CRS and grid when given and different."""
    path = Path(path)
    with open_raster(path, "DEM", HINT) as src:
        if src.crs is None:
            raise InputError(f"DEM {path} has no CRS; give a georeferenced DEM")
        z = read_window(src, (0, 0, src.width, src.height), nan_masked=True, what="DEM")
        z[z <= SRTM_VOID + 0.5] = np.nan
        transform, src_crs = src.transform, src.crs
    if like is not None and (src_crs != like.crs):
        out = np.full((like.height, like.width), np.nan)
        reproject(z, out, src_transform=transform, src_crs=src_crs, dst_transform=like.transform,
                  dst_crs=like.crs, resampling=Resampling.cubic, src_nodata=np.nan,
                  dst_nodata=np.nan)
        z, transform, src_crs = out, like.transform, like.crs
    if transform.b != 0 or transform.d != 0:
        raise InputError(f"DEM {path} is rotated; warp it north-up first")
    grid = (GeoDEM if src_crs.is_geographic else SurfaceGrid).from_transform(z, transform)
    return grid, src_crs


def datums(reference: str | Path, dem: str | Path, reference_vertical: str = "auto",
           dem_vertical: str = "auto") -> tuple[DatumDecision, DatumDecision]:
    """The vertical datums of the reference and of the DEM (one-line InputError when one
    cannot be told)."""
    return (dem_datum(reference, reference_vertical),
            dem_datum(dem, dem_vertical, what="DEM", option="--dem-vertical"))


def _to_datum(grid: DemGrid, crs: object, src: str, dst: str) -> DemGrid:
    """The grid's heights brought from datum ``src`` to ``dst`` with the EGM96 geoid."""
    if src == dst:
        return grid
    x, y = grid.nodes()
    if not grid.geographic:
        t = pyproj.Transformer.from_crs(pyproj.CRS.from_wkt(crs.to_wkt()), 4326,  # type: ignore[attr-defined]
                                        always_xy=True)
        x, y = t.transform(x, y)
    n_m = load_geoid().undulation_m(x, y)
    z = grid.values + n_m if src == "egm96" else grid.values - n_m
    return grid.with_values(z)


def coregister(reference: str | Path, dem: str | Path, out: str | Path | None = None,
               config: CoregConfig = CoregConfig(), reference_vertical: str = "auto",
               dem_vertical: str = "auto") -> CoregResult:
    """The translation that, added to ``dem``'s coordinates, aligns it with ``reference``
    (heights compared in the reference's vertical datum); written as JSON to ``out`` when
    given."""
    ref_datum, dem_d = datums(reference, dem, reference_vertical, dem_vertical)
    ref, crs = read_grid(reference)
    with open_raster(reference, "reference DEM", HINT) as like:
        grid, grid_crs = read_grid(dem, like=like)
    grid = _to_datum(grid, grid_crs, dem_d.datum, ref_datum.datum)
    result = nuth_kaab(ref, grid, config)
    if out is not None:
        doc = {"format": "gcpfree.coregister", "version": 1, "reference": str(reference),
               "reference_vertical": ref_datum.to_dict(), "dem": str(dem),
               "dem_vertical": dem_d.to_dict(), "heights_compared_in": ref_datum.datum,
               "crs": str(crs),
               "convention": "adding the shift to the DEM's coordinates aligns it with the "
                             "reference: ref(x + dx, y + dy) = dem(x, y) + dz",
               **result.to_dict()}
        atomic_write_json(out, doc)
    return result
