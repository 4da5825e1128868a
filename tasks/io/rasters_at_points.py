"""Rasters ``gcpfree evaluate`` reads (rasterio): the DEM and the land cover checked, then
sampled at the points window by window, and the DSM's mask counted block by block.

The DEM is interpolated bilinearly at the points (:func:`core.dem.sample_bilinear`), the land
cover read at the nearest cell, over windows of at most :data:`WINDOW_CELLS` cells on a side
(:func:`core.grid_points.window_groups`), so memory stays bounded whatever the spread of the
points. Vertical datum and height unit of the DEM follow the rules in :mod:`tasks.evaluation.lidar`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyproj
import rasterio

from core.dem import sample_bilinear
from core.errors import InputError
from core.evaluation.evaluation_report import (
    NO_CODE,
    NO_LANDCOVER,
    DemInfo,
    LandcoverInfo,
    MaskSummary,
    mask_summary,
)
from core.grid_points import affine_nodes, inside_grid, sample_nearest, window_groups
from core.heights import Z_UNITS, HeightFrame, unit_key
from core.jsonio import parse_json
from tasks.io.dem import dem_datum
from tasks.io.rasters import open_raster, read_window
from tasks.io.vertical_crs import crs_info, existing_file, split_crs

#: DEM windows are read at most this many cells on a side (8 MB of float64)
WINDOW_CELLS = 1024


@dataclass(frozen=True, eq=False)
class RasterSource:
    """A north-up or rotated raster (DEM or land cover) and its horizontal CRS."""

    path: Path
    horizontal: pyproj.CRS
    transform: tuple[float, ...]
    shape: tuple[int, int]


def _raster_source(src: rasterio.io.DatasetReader, path: Path,
                   what: str) -> tuple[RasterSource, pyproj.CRS]:
    if src.crs is None:
        raise InputError(f"{what} {path} has no CRS; georeference it (e.g. gdal_edit.py "
                         "-a_srs EPSG:...)")
    full = pyproj.CRS.from_wkt(src.crs.to_wkt())
    horizontal, _ = split_crs(full)
    return RasterSource(path, horizontal, tuple(src.transform)[:6], (src.height, src.width)), full


def inspect_dem(path: Path, vertical: str = "auto") -> tuple[RasterSource, DemInfo, HeightFrame]:
    """Read a DEM's georeferencing, vertical datum and height unit (rules in
    :mod:`tasks.evaluation.lidar`)."""
    path = existing_file(path, "DEM", "give the DSM as a GeoTIFF")
    with open_raster(path, "DEM") as src:
        raster, full = _raster_source(src, path, "DEM")
        tags = {k.lower(): v for k, v in src.tags().items()}
        band_unit = src.units[0] if src.units else None
        bounds = tuple(src.bounds)
        width, height = src.width, src.height
    _, vert = split_crs(full)
    decision = dem_datum(path, vertical, what="DEM", option="--dem-vertical")
    datum, v_src = decision.datum, decision.source
    if vert is not None:
        z_factor, z_name, z_src = vert.z_factor_m, vert.z_unit, "vertical CRS"
    else:
        key = unit_key(band_unit, f"DEM {path} band") or unit_key(tags.get("units"),
                                                                   f"DEM {path} tag units")
        z_src = "band unit or units tag" if key else "assumed"
        key = key or "m"
        z_factor, z_name = Z_UNITS[key], key
    info = DemInfo(path=str(path), crs=crs_info(full), vertical=datum, vertical_source=v_src,
                   z_unit=z_name, z_factor_m=z_factor, z_unit_source=z_src, width=width,
                   height=height, transform=raster.transform,
                   bounds=bounds)  # type: ignore[arg-type]
    return raster, info, HeightFrame(datum, z_factor)


def parse_landcover_names(spec: str) -> dict[int, str]:
    """``{"1": "bare_soil"}`` (JSON, either way round) or ``1=bare_soil,2=forest`` -> codes."""
    text = spec.strip()
    if text.startswith("{"):
        pairs = [(str(k), str(v)) for k, v in parse_json(text, "--landcover-names").items()]
    else:
        pairs = []
        for item in filter(None, (s.strip() for s in text.split(","))):
            if "=" not in item:
                raise InputError(f"--landcover-names item {item!r} is not CODE=NAME; write e.g. "
                                 "1=bare_soil,2=forest")
            k, v = item.split("=", 1)
            pairs.append((k.strip(), v.strip()))
    names: dict[int, str] = {}
    for k, v in pairs:
        code, name = (k, v) if k.lstrip("-").isdigit() else (v, k)
        if not code.lstrip("-").isdigit() or not name:
            raise InputError(f"--landcover-names pair {k!r}: {v!r} needs an integer code and a "
                             "name")
        names[int(code)] = name
    if len(set(names.values())) != len(names) or NO_LANDCOVER in names.values():
        raise InputError(f"--landcover-names must give distinct names (and not "
                         f"{NO_LANDCOVER!r}), got {names}")
    return names


def inspect_landcover(path: Path, names: str | None) -> tuple[RasterSource, LandcoverInfo]:
    """The land-cover raster; names from ``names`` or from its tags (``NAME=code``)."""
    path = existing_file(path, "land-cover raster", "give a GeoTIFF of class codes")
    with open_raster(path, "land-cover raster") as src:
        raster, full = _raster_source(src, path, "land-cover raster")
        tags = src.tags()
        nodata = None if src.nodata is None or not math.isfinite(src.nodata) else int(src.nodata)
        if np.dtype(src.dtypes[0]).kind not in "iu":
            raise InputError(f"land-cover raster {path} holds {src.dtypes[0]} values; give "
                             "integer class codes")
    if names is not None:
        codes, source = parse_landcover_names(names), "--landcover-names"
    else:
        codes = {int(v): k.lower() for k, v in tags.items() if v.strip().isdigit()
                 and k.lower() not in {"seed", "version"}}
        source = "raster tags NAME=code" if codes else "codes (no names in the raster tags)"
    info = LandcoverInfo(str(path), crs_info(full), tuple(sorted(codes.items())), source,
                         nodata)
    return raster, info


def sample_dem(src: rasterio.io.DatasetReader, raster: RasterSource, x: np.ndarray,
               y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Bilinear DEM values at points in the DEM's CRS, reading only the windows they need;
    (values with NaN off the grid or next to voids, inside-the-grid flags)."""
    fi, fj = affine_nodes(raster.transform, x, y)
    z = np.full(fi.shape, np.nan)
    for g in window_groups(fi, fj, raster.shape, WINDOW_CELLS):
        win = read_window(src, (g.col0, g.row0, g.col1, g.row1), nan_masked=True,
                          what="DEM")
        z[g.index] = sample_bilinear(win, fi[g.index] - g.row0, fj[g.index] - g.col0)
    return z, inside_grid(fi, fj, raster.shape)


def sample_classes(src: rasterio.io.DatasetReader, raster: RasterSource, nodata: int | None,
                   x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Class codes of the cells holding points in the raster's CRS, reading only the windows
    they need; :data:`core.evaluation.evaluation_report.NO_CODE` off the raster and on its ``nodata``."""
    fi, fj = affine_nodes(raster.transform, x, y)
    codes = np.full(fi.shape, NO_CODE, dtype=np.int64)
    for g in window_groups(fi, fj, raster.shape, WINDOW_CELLS, nearest=True):
        win = read_window(src, (g.col0, g.row0, g.col1, g.row1), what="land cover")
        codes[g.index] = sample_nearest(win.astype(np.int64), fi[g.index] - g.row0,
                                        fj[g.index] - g.col0, NO_CODE)
    if nodata is not None:
        codes[codes == nodata] = NO_CODE
    return codes


def summarize_mask(path: Path) -> MaskSummary:
    """Count the mask's codes block by block (0 valid, 1 mismatch, 2 occluded/outside)."""
    with open_raster(Path(path), "mask") as src:
        return mask_summary(str(path), (src.read(1, window=win)
                                        for _, win in src.block_windows(1)))
