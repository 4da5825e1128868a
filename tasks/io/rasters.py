"""Rasters for every task: the one opener (:func:`open_raster`), the one window reader
(:func:`read_window`), streamed tiled writes, then an atomic COG copy; strict JSON written
atomically and read back (:func:`read_json`)."""

from __future__ import annotations

import contextlib
import math
import os
import tempfile
import threading
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import rasterio
import rasterio.io
import rasterio.shutil
from affine import Affine
from rasterio.errors import NotGeoreferencedWarning, RasterioIOError
from rasterio.windows import Window

from core.dem import SurfaceGrid
from core.errors import InputError
from core.jsonio import parse_json, to_json

if TYPE_CHECKING:  # Dask and xarray are imported where arrays are written, not to read one
    import dask.array as darr
    import xarray as xr

# GDAL block cache while building a COG: bounded so memory stays flat on large rasters
COG_CACHE_MB = 256
# the Dask chunks of every raster a task maps over, cells a side (DESIGN: about 1024 x 1024)
CHUNK = 1024


class _WindowWriter:
    """A ``dask.array.store`` target writing 2-D blocks into an open rasterio dataset."""

    def __init__(self, dst: rasterio.io.DatasetWriter, lock: threading.Lock) -> None:
        self.dst = dst
        self.lock = lock

    def __setitem__(self, key: tuple[slice, slice], value: np.ndarray) -> None:
        rows, cols = key
        window = Window.from_slices(rows, cols, height=self.dst.height, width=self.dst.width)
        with self.lock:
            self.dst.write(value, 1, window=window)


@dataclass(frozen=True)
class CogOptions:
    """How one raster is written.

    ``transform`` (affine coefficients ``(a, b, c, d, e, f)`` or an ``Affine``) and ``crs``
    georeference it; raw sensor images carry ``rpcs`` instead. ``tags`` go to the default
    metadata domain; ``resampling`` makes the overviews (``"average"`` for heights,
    ``"nearest"`` for classes and masks); ``predictor`` None picks 3 for floats and 2 for
    integers.
    """

    transform: Any = None
    crs: Any = None
    nodata: float | int | None = None
    rpcs: Any = None
    tags: Mapping[str, str] = field(default_factory=dict)
    resampling: str = "average"
    predictor: int | None = None
    blocksize: int = 512


@dataclass(frozen=True, eq=False)
class CogItem:
    """A 2-D (Dask) array to write to ``path`` with ``options``."""

    data: darr.Array | np.ndarray
    path: Path
    options: CogOptions = field(default_factory=CogOptions)


def write_arrays_cog(items: list[CogItem], extra: list[Any] | None = None) -> tuple[Any, ...]:
    """Write 2-D (Dask) arrays as Cloud-Optimized GeoTIFFs, atomically, in one Dask pass.

    Arrays that share blocks (slices of one computation) are computed once; ``extra`` Dask
    values (statistics) are computed in the same pass and returned.

    Blocks are computed by Dask threads and streamed into tiled GeoTIFFs under one write
    lock each (memory stays bounded; uncompressed: they are read back once, so compressing
    them was a second compression), then GDAL's COG driver copies them with overviews,
    compressing in as many threads as the blocks were computed in.
    Everything happens in temporary folders beside the outputs; each finished file
    replaces its output by a rename, so a failure never leaves a half-written product and
    an earlier product survives a failed rerun.
    """
    import dask
    import dask.array as darr

    with contextlib.ExitStack() as stack:
        sources, targets, jobs = [], [], []
        for item in items:
            out, opts = Path(item.path), item.options
            out.parent.mkdir(parents=True, exist_ok=True)
            data = item.data
            arr = data if isinstance(data, darr.Array) else darr.from_array(np.asarray(data),
                                                                            chunks=1024)
            if arr.ndim != 2:
                raise InputError(f"{out.name}: a COG is written from a single band (2-D array), "
                                 f"got shape {arr.shape}; write each band separately")
            tmp = Path(stack.enter_context(
                tempfile.TemporaryDirectory(dir=out.parent, prefix=f".{out.name}.tmp")))
            dtype = np.dtype(arr.dtype)
            profile: dict[str, Any] = {
                "driver": "GTiff", "width": arr.shape[1], "height": arr.shape[0], "count": 1,
                "dtype": dtype.name, "tiled": True, "blockxsize": opts.blocksize,
                "blockysize": opts.blocksize, "compress": "NONE", "BIGTIFF": "IF_SAFER",
                "nodata": opts.nodata,
            }
            if opts.transform is not None:
                profile.update(transform=Affine(*tuple(opts.transform)[:6]), crs=opts.crs)
            if opts.rpcs is not None:
                profile["rpcs"] = opts.rpcs
            dst = stack.enter_context(rasterio.open(tmp / "tiled.tif", "w", **profile))
            if opts.tags:
                dst.update_tags(**opts.tags)
            sources.append(arr)
            targets.append(_WindowWriter(dst, threading.Lock()))
            predictor = opts.predictor
            if predictor is None:
                predictor = 3 if dtype.kind == "f" else 2
            jobs.append((dst, tmp, out, predictor, opts.blocksize, opts.resampling))
        stored = darr.store(sources, targets, lock=False, compute=False)
        from tasks.scheduling import threads

        with threads() as sched:  # the window writers share this process's open datasets
            results = dask.compute(stored, *(extra or []))[1:]
        for dst, tmp, out, predictor, blocksize, resampling in jobs:
            dst.close()
            cog = tmp / "cog.tif"
            with rasterio.Env(GDAL_CACHEMAX=COG_CACHE_MB):
                rasterio.shutil.copy(
                    tmp / "tiled.tif", cog, driver="COG", COMPRESS="DEFLATE",
                    PREDICTOR=str(predictor) if predictor else "NO", BLOCKSIZE=str(blocksize),
                    OVERVIEWS="AUTO", RESAMPLING=str(resampling).upper(), BIGTIFF="IF_SAFER",
                    NUM_THREADS=str(sched.workers),  # compression in as many threads
                )
            _chmod_default(cog)
        for _, tmp, out, *_ in jobs:
            os.replace(tmp / "cog.tif", out)
    return tuple(results)


def cog_item(da: xr.DataArray, out: str | Path, *, resampling: str = "average") -> CogItem:
    """A :func:`write_arrays_cog` item from a georeferenced 2-D DataArray: its rioxarray
    transform, CRS and nodata, its scalar attrs as tags."""
    tags = {k: str(v) for k, v in da.attrs.items() if isinstance(v, (str, int, float))}
    nodata = da.rio.nodata if da.rio.encoded_nodata is None else da.rio.encoded_nodata
    return CogItem(da.data, Path(out), CogOptions(
        transform=da.rio.transform(recalc=True), crs=da.rio.crs, nodata=nodata, tags=tags,
        resampling=resampling))


def _chmod_default(path: Path | str) -> None:
    """Give a temporary file the permissions a plain ``open(..., "w")`` would have."""
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(path, 0o666 & ~umask)


def atomic_write_bytes(path: str | Path, data: bytes) -> Path:
    """Write bytes to ``path`` through a temporary file and a rename."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        _chmod_default(tmp)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def atomic_write_text(path: str | Path, text: str) -> Path:
    return atomic_write_bytes(path, text.encode("utf-8"))


def atomic_write_json(path: str | Path, doc: Any, indent: int | None = 1) -> Path:
    """``doc`` written by the one strict JSON writer (:func:`core.jsonio.to_json`) through a
    temporary file."""
    return atomic_write_text(path, to_json(doc, indent))


def read_json(path: str | Path, what: str = "JSON file", hint: str = "check the path") -> Any:
    """The one JSON reader of files: the document at ``path`` through
    :func:`core.jsonio.parse_json`; a one-line InputError naming ``what`` when the file is
    missing, unreadable or not JSON."""
    try:
        text = Path(path).read_text(encoding="utf-8-sig", errors="replace")
    except OSError as exc:
        raise InputError(f"cannot read {what} {path}: {exc.strerror or exc}; {hint}") from None
    return parse_json(text, f"{what} {path}")


def open_raster(path: str | Path, what: str = "image", hint: str = "check the path"
                ) -> rasterio.io.DatasetReader:
    """The one raster opener: the file at ``path`` open for reading (a context manager).

    ``what`` says what the file is for (``"image"``, ``"reference DEM"``, ``"left ortho"``...)
    and ``hint`` what to do: a missing or unreadable file is a one-line InputError saying both.
    A raster without georeferencing opens without a warning (sensor images have none); a step
    that needs a CRS refuses it itself, in its own words.
    """
    path = Path(path)
    if not path.exists():
        raise InputError(f"{what} {path} does not exist; {hint}")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", NotGeoreferencedWarning)
            return rasterio.open(path)
    except RasterioIOError as exc:
        raise InputError(f"cannot read {what} {path}: {exc}; {hint}") from exc


def read_window(src: rasterio.io.DatasetReader, box: tuple[int, int, int, int], *,
                fill: float | None = None, nan_masked: bool = False,
                what: str = "raster") -> np.ndarray:
    """The one window reader: band 1 over ``box`` (col0, row0, col1, row1; half-open, any part
    of it may lie beyond the raster) of an open raster.

    Beyond the raster the window holds ``fill`` (default: the raster's nodata value when it
    is a finite number, else 0), in the raster's own type. With ``nan_masked`` the window is
    float64 with the raster's nodata and masked cells, and everything beyond it, NaN. A
    damaged file is a one-line InputError naming ``what``.
    """
    c0, r0, c1, r1 = (int(v) for v in box)
    nodata = src.nodata
    if nan_masked:
        out = np.full((r1 - r0, c1 - c0), np.nan)
    else:
        if fill is None:
            fill = nodata if nodata is not None and math.isfinite(nodata) else 0
        out = np.full((r1 - r0, c1 - c0), fill, dtype=src.dtypes[0])
    a0, a1, b0, b1 = max(r0, 0), min(r1, src.height), max(c0, 0), min(c1, src.width)
    if a1 <= a0 or b1 <= b0:
        return out
    win = Window(b0, a0, b1 - b0, a1 - a0)
    try:
        if nan_masked:
            part = src.read(1, window=win, masked=True)
            out[a0 - r0:a1 - r0, b0 - c0:b1 - c0] = part.astype(np.float64).filled(np.nan)
        else:
            out[a0 - r0:a1 - r0, b0 - c0:b1 - c0] = src.read(1, window=win)
    except RasterioIOError as exc:
        raise InputError(f"cannot read the pixels of {what} {src.name}: {exc}; the file is "
                         "damaged, give a whole file") from None
    return out


def read_surface_window(path: str | Path, bounds_m: tuple[float, float, float, float],
                        margin_cells: int = 2, what: str = "DEM") -> SurfaceGrid:
    """The cells of a north-up projected raster covering ``bounds_m`` (x_min, y_min, x_max,
    y_max) plus ``margin_cells``, as float64 heights: NaN for nodata and beyond the raster
    (:func:`read_window`), in the grid convention of :class:`core.dem.RegularGrid`."""
    xmin, ymin, xmax, ymax = bounds_m
    with open_raster(path, what) as src:
        t = src.transform
        c0 = math.floor((xmin - t.c) / t.a) - margin_cells
        c1 = math.ceil((xmax - t.c) / t.a) + margin_cells
        r0 = math.floor((t.f - ymax) / -t.e) - margin_cells
        r1 = math.ceil((t.f - ymin) / -t.e) + margin_cells
        z = read_window(src, (c0, r0, c1, r1), nan_masked=True, what=what)
    return SurfaceGrid(z, t.c + (c0 + 0.5) * t.a, t.f + (r0 + 0.5) * t.e, t.a, t.e)
