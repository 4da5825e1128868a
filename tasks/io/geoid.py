"""Read geoid grids into :class:`core.geoid.GeoidGrid`: GTX files, or any grid GDAL reads (a
GeoTIFF such as PROJ's ``us_nga_egm08_25.tif``), whole or over a box; locate the bundled EGM96
grid and the grids PROJ has of a geoid model."""

from __future__ import annotations

import functools
import math
import os
from pathlib import Path

import numpy as np
from rasterio.windows import Window

from core.errors import InputError
from core.geodesy import BBox
from core.geoid import GeoidGrid
from tasks.io.rasters import open_raster

DATA_DIR = Path(__file__).resolve().parents[1] / "data"
EGM96_GTX = DATA_DIR / "egm96_15.gtx"
BUNDLED_SRTM_DIR = DATA_DIR
#: the file names PROJ gives a geoid model's grid (PROJ-data's, then the older GTX names)
PROJ_GRID_NAMES = {"egm2008": ("us_nga_egm08_25.tif", "egm08_25.gtx"),
                   "egm96": ("us_nga_egm96_15.tif", "egm96_15.gtx")}
GRID_HINT = "give a geoid grid GDAL reads: a GTX file or a GeoTIFF (e.g. us_nga_egm08_25.tif)"


def read_gtx(path: str | Path) -> GeoidGrid:
    """Read a GTX vertical grid: big-endian header ``>4d`` (lat0, lon0, dlat, dlon), ``>2i``
    (rows, cols), then rows*cols ``>f4`` values, row 0 at the south. -88.8888 marks no data."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise InputError(f"cannot read geoid grid {path}: {exc.strerror}; check the path") from exc
    if len(raw) < 40:
        raise InputError(f"geoid grid {path} is too short ({len(raw)} bytes) to be a GTX file")
    lat0, lon0, dlat, dlon = np.frombuffer(raw[:32], dtype=">f8")
    nrows, ncols = (int(v) for v in np.frombuffer(raw[32:40], dtype=">i4"))
    expected = 40 + 4 * nrows * ncols
    if nrows <= 0 or ncols <= 0 or len(raw) != expected:
        raise InputError(
            f"geoid grid {path} is malformed: header says {nrows}x{ncols} values "
            f"({expected} bytes) but the file has {len(raw)} bytes; use an intact GTX file"
        )
    values = np.frombuffer(raw[40:], dtype=">f4").astype(np.float64).reshape(nrows, ncols)
    values[np.abs(values + 88.8888) < 1e-3] = np.nan  # GTX no-data value
    lon0 = float(lon0)
    if lon0 >= 180.0:
        lon0 -= 360.0
    return GeoidGrid(values, float(lat0), lon0, float(dlat), float(dlon), name=path.name)


def read_geoid(path: str | Path, box: BBox | None = None) -> GeoidGrid:
    """The geoid grid at ``path``: a ``.gtx`` read by :func:`read_gtx`, any other grid through
    GDAL (nodes at its pixel centres, north-up rows turned south-first, nodata as NaN, its
    scale and offset applied). With ``box``, only the nodes around it (two beyond each side):
    a 2.5' global grid is 150 MB whole. InputError for a file that is no geographic grid."""
    path = Path(path)
    if path.suffix.lower() == ".gtx" and box is None:
        return read_gtx(path)
    with open_raster(path, "geoid grid", GRID_HINT) as src:
        crs, tr = src.crs, src.transform
        if crs is not None and not crs.is_geographic:
            raise InputError(f"geoid grid {path} is in {crs}, not in longitude/latitude; "
                             f"{GRID_HINT}")
        if tr.b != 0 or tr.d != 0 or tr.a <= 0 or tr.e >= 0:
            raise InputError(f"geoid grid {path} is not a north-up lon/lat grid; {GRID_HINT}")
        win = _grid_window(src.width, src.height, tr, box)
        values = src.read(1, window=win, masked=True).astype(np.float64).filled(np.nan)
        values = values * src.scales[0] + src.offsets[0]
        wt = src.window_transform(win)
    if path.suffix.lower() == ".gtx":
        values[np.abs(values + 88.8888) < 1e-3] = np.nan  # GTX no-data value
    ncols = values.shape[1]
    if ncols > 2 and abs((ncols - 1) * wt.a - 360.0) < 1e-6:
        values = values[:, :-1]  # a global grid whose last column repeats the first
    lon0 = wt.c + 0.5 * wt.a
    if lon0 >= 180.0 - 1e-9:
        lon0 -= 360.0
    lat_south = wt.f + (values.shape[0] - 0.5) * wt.e
    return GeoidGrid(values[::-1].copy(), lat_south, lon0, -wt.e, wt.a, name=path.name)


def check_geoid(path: str | Path) -> None:
    """InputError in one line unless ``path`` is a geoid grid :func:`read_geoid` reads (its
    header and georeferencing checked, its values not read)."""
    path = Path(path)
    if path.suffix.lower() == ".gtx":
        read_gtx(path)  # a few MB: the bundled 15' grid reads in milliseconds
        return
    with open_raster(path, "geoid grid", GRID_HINT) as src:
        tr = src.transform
        if (src.crs is not None and not src.crs.is_geographic) or tr.b != 0 or tr.a <= 0 \
                or tr.e >= 0:
            raise InputError(f"geoid grid {path} is not a north-up lon/lat grid; {GRID_HINT}")


def _grid_window(width: int, height: int, tr, box: BBox | None) -> Window:
    """The grid's nodes around ``box`` (two beyond each side), whole rows of a global grid
    when the box crosses its longitude seam; all of it without a box."""
    if box is None:
        return Window(0, 0, width, height)
    r0 = max(0, math.floor((box.lat_max - tr.f) / tr.e - 0.5) - 2)
    r1 = min(height, math.ceil((box.lat_min - tr.f) / tr.e - 0.5) + 3)
    lon0 = tr.c + 0.5 * tr.a
    span = width * tr.a
    west = box.lon_min
    if abs(span - 360.0) < 1e-6 or abs(span - 360.0 - tr.a) < 1e-6:
        west = lon0 + (box.lon_min - lon0) % 360.0  # the box's west edge inside the grid
    c0 = math.floor((west - lon0) / tr.a) - 2
    c1 = math.ceil((west + box.lon_max - box.lon_min - lon0) / tr.a) + 3
    if c0 < 0 or c1 > width:
        c0, c1 = max(c0, 0), min(c1, width)
        if span >= 360.0 - 1e-6:
            c0, c1 = 0, width
    if r1 - r0 < 2 or c1 - c0 < 2:
        raise InputError(f"the geoid grid does not cover lon {box.lon_min:.3f}..{box.lon_max:.3f}, "
                         f"lat {box.lat_min:.3f}..{box.lat_max:.3f}; use a grid that covers the area")
    return Window(c0, r0, c1 - c0, r1 - r0)


def proj_grid(datum: str) -> Path | None:
    """PROJ's own grid of the geoid ``datum`` (``egm2008``...) when this installation has it
    (pyproj's data folders, then the user's, where ``projsync`` puts grids), else None."""
    import pyproj.datadir

    folders = [*pyproj.datadir.get_data_dir().split(os.pathsep),
               pyproj.datadir.get_user_data_dir()]
    for name in PROJ_GRID_NAMES.get(datum, ()):
        for folder in folders:
            if (Path(folder) / name).is_file():
                return Path(folder) / name
    return None


@functools.lru_cache(maxsize=4)
def load_geoid(path: str | None = None) -> GeoidGrid:
    """The geoid grid at ``path`` (any grid :func:`read_geoid` reads), or the bundled EGM96 15'
    grid; cached per process."""
    return read_gtx(EGM96_GTX) if path is None else read_geoid(path)
