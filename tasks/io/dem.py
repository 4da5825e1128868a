"""Reference DEMs read as WGS84 ellipsoidal heights on a lon/lat grid (:class:`core.dem.GeoDEM`).

A window of any lon/lat GeoTIFF or SRTM ``.hgt`` around an area, with the vertical datum
resolved (EGM96 orthometric heights converted with ``h = H + N``) and voids as NaN; the one
datum rule applied to a file (:func:`dem_datum`) and to a set of tiles (:func:`tile_datum`).
Plain functions (no Prefect): the CLI checks inputs with them before any flow starts.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pyproj
from rasterio.errors import WindowError
from rasterio.windows import Window, from_bounds

from core.dem import GeoDEM
from core.errors import CoverageError, InputError
from core.geodesy import BBox
from core.heights import VERTICAL_CHOICES, DatumDecision, decide_datum
from tasks.io.dem_products import named_datum
from tasks.io.dem_tiles import TileSet
from tasks.io.geoid import load_geoid, proj_grid
from tasks.io.rasters import open_raster, read_window
from tasks.io.vertical_crs import split_crs

VERTICALS = VERTICAL_CHOICES
HINT = "give a GeoTIFF or .hgt file"
#: cells below this are voids when a DEM declares no nodata (SRTM -32768, Copernicus -32767)
VOID_BELOW_M = -32000.0


def dem_datum(path: str | Path, given: str = "auto", *, what: str = "reference DEM",
              option: str = "--reference-vertical", geoid: str | Path | None = None,
              geoid_option: str | None = None) -> DatumDecision:
    """The vertical datum of a DEM file, by the one rule of :func:`core.heights.decide_datum`
    (the option given, the ``vertical_datum`` tag, the CRS's vertical part, a product's name
    (SRTM, NASADEM: EGM96; Copernicus: EGM2008), a geoid grid given, else refused), with the
    geoid grid its orthometric heights go through. Every command that reads a DEM decides with
    this function; ``what`` and ``option`` name the file and the command-line option in the
    messages. A command that converts through a grid other than the bundled EGM96 names its
    ``geoid_option`` (``--geoid``) and gives its ``geoid``; PROJ's own grid is then looked for
    when the heights need one and none is given. Without ``geoid_option`` only EGM96 and
    ellipsoidal heights are accepted.

    Raises:
        InputError: the file cannot be read, or its datum cannot be told or converted.
    """
    path = Path(path)
    label = f"{what} {path}"
    grid = None if geoid is None else str(geoid)
    proj = None
    if geoid_option is not None and grid is None:
        found = proj_grid("egm2008")
        proj = None if found is None else str(found)
    if given != "auto":  # the option decides: no need to open the file
        return decide_datum(label, option, given=given, geoid=grid, geoid_option=geoid_option)
    if path.suffix.lower() == ".zip":  # a NASADEM zip as distributed: its name says
        return decide_datum(label, option, named=named_datum(path), geoid=grid,
                            proj_grid=proj, geoid_option=geoid_option)
    with open_raster(path, what, HINT) as src:
        tags = {k.lower(): v for k, v in src.tags().items()}
        crs = src.crs
    if crs is None:
        raise InputError(f"{label} has no CRS; give a georeferenced DEM (EPSG:4326 or a UTM "
                         "zone), e.g. gdal_edit.py -a_srs EPSG:4326")
    try:
        _, vert = split_crs(pyproj.CRS.from_wkt(crs.to_wkt()))
    except InputError as exc:
        raise InputError(f"{label}: {exc}") from None
    named = named_datum(path)
    return decide_datum(label, option, given=given, tag=tags.get("vertical_datum"),
                        crs_datum=None if vert is None else vert.datum,
                        crs_vertical_name=None if vert is None else vert.datum_name,
                        srtm_name=path.name if named is None and path.suffix.lower() == ".hgt"
                        else None, named=named, geoid=grid, proj_grid=proj,
                        geoid_option=geoid_option)


def tile_datum(tiles: TileSet, option: str = "--reference-vertical") -> TileSet:
    """The tiles with the vertical datum of their heights decided by the one rule, tile by
    tile (:func:`dem_datum`, through the source's ``--geoid`` grid or PROJ's), into one
    decision: the tiles of a named product as distributed (an SRTM or Copernicus tile that
    says its heights are ellipsoidal is refused: it is no longer as distributed), every tile
    in one datum through one grid. ``option`` is the command's ``--*-vertical`` option, which
    speaks for a DEM file or a folder of unnamed DEMs (named tiles say their own datum)."""
    src = tiles.source
    given = src.vertical if (src.path.is_file() or tiles.product.datum is None) else "auto"
    decisions = [dem_datum(t.path, given, what=f"{t.product.name} tile", option=option,
                           geoid=src.geoid, geoid_option="--geoid") for t in tiles]
    first = decisions[0]
    for t, d in zip(tiles, decisions, strict=True):
        if t.product.datum is not None and d.datum == "ellipsoidal":
            raise InputError(f"{t.product.name} tile {t.path} holds ellipsoidal heights "
                             f"({d.source}); tiles are read as distributed (heights above "
                             f"their geoid): give them as distributed, or this DEM as "
                             "--reference")
        if (d.datum, d.geoid) != (first.datum, first.geoid):
            raise InputError(f"{t.path}: {d.describe()}; but {tiles.tiles[0].path.name}: "
                             f"{first.describe()}: give tiles whose heights share one datum")
    if len(decisions) > 1:
        first = replace(first, source=f"{first.source}, and {len(decisions) - 1} more "
                                      "tile(s) alike")
    return replace(tiles, datum=first)


def check_reference(path: str | Path) -> None:
    """Fail early, in one line, on a reference DEM that cannot be read as lon/lat heights."""
    path = Path(path)
    with open_raster(path, "reference DEM", HINT + " in EPSG:4326") as src:
        crs = src.crs
    if crs is None or not crs.is_geographic:
        raise InputError(f"reference DEM {path} is not in geographic coordinates (CRS {crs}); "
                         "reproject it to EPSG:4326 (e.g. gdalwarp -t_srs EPSG:4326)")


def read_reference(path: str | Path, box: BBox, vertical: str) -> GeoDEM:
    """The part of a lon/lat DEM covering ``box``, as WGS84 ellipsoidal heights (NaN = void).

    ``vertical`` is ``egm96`` (converted with ``h = H + N``) or ``ellipsoidal``.

    Raises:
        CoverageError: the DEM does not reach the box.
    """
    path = Path(path)
    check_reference(path)
    with open_raster(path, "reference DEM", HINT) as src:
        f = from_bounds(*box.as_tuple(), transform=src.transform)
        c0, r0 = int(np.floor(f.col_off)) - 1, int(np.floor(f.row_off)) - 1  # one node more:
        c1 = int(np.ceil(f.col_off + f.width)) + 1  # the nodes (pixel centres) span the box
        r1 = int(np.ceil(f.row_off + f.height)) + 1
        try:
            win = Window(c0, r0, c1 - c0, r1 - r0).intersection(
                Window(0, 0, src.width, src.height))
        except WindowError:
            win = None
        if win is None or win.width < 2 or win.height < 2:
            b = src.bounds
            raise CoverageError(
                f"reference DEM {path} (lon {b.left:.3f}..{b.right:.3f}, lat {b.bottom:.3f}.."
                f"{b.top:.3f}) does not cover the image footprint (lon {box.lon_min:.3f}.."
                f"{box.lon_max:.3f}, lat {box.lat_min:.3f}..{box.lat_max:.3f}); give a DEM "
                "covering the scene")
        c0, r0 = int(win.col_off), int(win.row_off)
        heights = read_window(src, (c0, r0, c0 + int(win.width), r0 + int(win.height)),
                              nan_masked=True, what="reference DEM")
        tr = src.window_transform(win)
    heights[heights <= VOID_BELOW_M] = np.nan  # SRTM/Copernicus voids when no nodata is declared
    if vertical == "egm96":
        rows, cols = np.mgrid[0:heights.shape[0], 0:heights.shape[1]]
        lon = tr.c + (cols + 0.5) * tr.a
        lat = tr.f + (rows + 0.5) * tr.e
        heights = load_geoid().orthometric_to_ellipsoidal(lon, lat, heights)
    return GeoDEM.from_transform(heights, tuple(tr)[:6])
