"""Reading for the ortho tasks (:mod:`tasks.ortho.orthorectify`): what a DEM is (lon/lat reference or
projected DSM, vertical datum), its window under one output tile, and an image window.

Plain functions (no Prefect): the CLI checks inputs with them before any flow starts, and the
per-tile function calls them in Dask workers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyproj
import rasterio
import rasterio.warp
from rasterio.enums import Resampling
from rasterio.windows import Window

from core.errors import CoverageError, InputError
from core.geodesy import BBox, metres_per_degree
from core.ortho.ortho import SourceWindow, TileDEM
from tasks.io.crs import Projection
from tasks.io.dem import VERTICALS, dem_datum, read_reference
from tasks.io.geoid import load_geoid
from tasks.io.rasters import open_raster, read_surface_window

DEM_VERTICALS = VERTICALS


@dataclass(frozen=True)
class DemSource:
    """A DEM as the ortho reads it: ``geographic`` (lon/lat, read as :class:`GeoDEM` through
    :func:`tasks.io.dem.read_reference`) or projected (EPSG ``epsg``, square cells of
    ``res``); ``vertical`` ``"ellipsoidal"`` or ``"egm96"`` and ``vertical_source`` what
    decided it (:func:`tasks.io.dem.dem_datum`); ``bounds`` (left, bottom, right, top) in its
    own CRS; ``nodata`` its nodata value."""

    path: str
    geographic: bool
    epsg: int
    vertical: str
    bounds: tuple[float, float, float, float]
    res: float
    nodata: float | None
    vertical_source: str = "given"

    @property
    def crs(self) -> str:
        return f"EPSG:{self.epsg}"


def describe_dem(path: str | Path, vertical: str = "auto") -> DemSource:
    """Open a DEM and tell how to read it; one-line InputError when it cannot be used.

    ``vertical`` ``auto``: the one rule of :func:`tasks.io.dem.dem_datum` (the file's
    ``vertical_datum`` tag, its CRS's vertical part, an SRTM name, else refused: give
    ``--dem-vertical``).
    """
    path = Path(path)
    if vertical not in DEM_VERTICALS:
        raise InputError(f"DEM vertical {vertical!r} unknown; use one of {DEM_VERTICALS}")
    with open_raster(path, "DEM", "give a GeoTIFF or .hgt file") as src:
        crs_r, t, nodata, b = src.crs, src.transform, src.nodata, src.bounds
    if crs_r is None:
        raise InputError(f"DEM {path} has no CRS; give a georeferenced DEM (EPSG:4326 or UTM)")
    if t.b != 0 or t.d != 0:
        raise InputError(f"DEM {path} is rotated; warp it north-up (gdalwarp) first")
    crs = pyproj.CRS.from_wkt(crs_r.to_wkt())
    horizontal = crs.sub_crs_list[0] if crs.is_compound else crs
    decision = dem_datum(path, vertical, what="DEM", option="--dem-vertical")
    if horizontal.is_geographic:
        return DemSource(str(path), True, 4326, decision.datum, tuple(b), abs(t.a), nodata,
                         decision.source)
    epsg = horizontal.to_epsg()
    if epsg is None:
        raise InputError(f"DEM {path}: its CRS has no EPSG code; warp it to a UTM zone or "
                         "EPSG:4326 first")
    if abs(abs(t.a) - abs(t.e)) > 1e-9 * abs(t.a):
        raise InputError(f"DEM {path} has non-square cells ({t.a} x {-t.e}); resample it to "
                         "square cells first")
    if horizontal.axis_info and horizontal.axis_info[0].unit_name not in ("metre", "meter"):
        raise InputError(f"DEM {path} is in {horizontal.axis_info[0].unit_name}s; warp it to a "
                         "CRS in metres (UTM) or EPSG:4326")
    return DemSource(str(path), False, int(epsg), decision.datum, tuple(b), abs(t.a), nodata,
                     decision.source)


def bounds_in(dem: DemSource, epsg: int) -> tuple[float, float, float, float]:
    """The DEM's extent in EPSG ``epsg`` (densified edges)."""
    return tuple(rasterio.warp.transform_bounds(dem.crs, f"EPSG:{epsg}", *dem.bounds,
                                                densify_pts=21))


def dem_height_range(dem: DemSource, box: BBox) -> tuple[float, float] | None:
    """Lowest and highest ellipsoidal heights of the DEM over a lon/lat box (a decimated read
    for a projected DEM, with a 5 % + 5 m margin); None when it has none there."""
    if dem.geographic:
        try:
            z = read_reference(dem.path, box, dem.vertical).h_m
        except CoverageError:
            return None
        pad = 0.0
    else:
        with rasterio.open(dem.path) as src:
            f = max(1, math.ceil(max(src.width, src.height) / 1024))
            z = src.read(1, out_shape=(max(1, src.height // f), max(1, src.width // f)),
                         masked=True).astype(np.float64).filled(np.nan)
        if dem.vertical == "egm96":
            n = load_geoid().undulation_m(0.5 * (box.lon_min + box.lon_max),
                                          0.5 * (box.lat_min + box.lat_max))
            z = z + float(n)
        pad = 5.0
    if not np.isfinite(z).any():
        return None
    lo, hi = float(np.nanmin(z)), float(np.nanmax(z))
    pad += 0.05 * (hi - lo) if pad else 0.0
    return lo - pad, hi + pad


def read_tile_dem(dem: DemSource, bounds_m: tuple[float, float, float, float], epsg: int,
                  margin_m: float) -> TileDEM | None:
    """The DEM under an output tile (``bounds_m`` in EPSG ``epsg``) widened by ``margin_m``
    and two DEM cells; None when the DEM has no height there."""
    if dem.geographic:
        lon0, lat0, lon1, lat1 = rasterio.warp.transform_bounds(
            f"EPSG:{epsg}", "EPSG:4326", *bounds_m, densify_pts=21)
        m_lon, _ = metres_per_degree(min(max(abs(lat0), abs(lat1)), 89.0))  # the smaller step
        pad = margin_m / float(m_lon) + 2 * dem.res
        try:
            box = BBox(max(lon0 - pad, -180.0), max(lat0 - pad, -90.0), min(lon1 + pad, 180.0),
                       min(lat1 + pad, 90.0))
            grid = read_reference(dem.path, box, dem.vertical)
        except CoverageError:
            return None
        return TileDEM(grid) if np.isfinite(grid.h_m).any() else None
    xmin, ymin, xmax, ymax = (bounds_m if epsg == dem.epsg else rasterio.warp.transform_bounds(
        f"EPSG:{epsg}", dem.crs, *bounds_m, densify_pts=21))
    pad = margin_m + 2 * dem.res
    grid = read_surface_window(dem.path, (xmin - pad, ymin - pad, xmax + pad, ymax + pad), 0)
    if min(grid.values.shape) < 2 or not np.isfinite(grid.values).any():
        return None  # the tile lies beyond the DEM
    return TileDEM(grid, Projection(dem.epsg).to_xy,
                   load_geoid() if dem.vertical == "egm96" else None)


def read_image_window(path: str | Path, win: SourceWindow) -> np.ndarray:
    """Band 1 over ``win`` (averaged ``factor x factor`` when decimated), its own type."""
    c0, r0, c1, r1 = win.bounds
    with open_raster(path, "image") as src:
        window = Window(c0, r0, min(c1, src.width) - c0, min(r1, src.height) - r0)
        if win.factor == 1:
            return src.read(1, window=window)
        return src.read(1, window=window, out_shape=(win.n_rows, win.n_cols),
                        resampling=Resampling.average)
