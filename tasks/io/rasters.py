"""Raster writing shared by every task: streamed tiled writes, then an atomic COG copy."""

from __future__ import annotations

import contextlib
import json
import math
import os
import tempfile
import threading
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import dask
import dask.array as darr
import numpy as np
import rasterio
import rasterio.io
import rasterio.shutil
import xarray as xr
from affine import Affine
from rasterio.errors import NotGeoreferencedWarning, RasterioIOError
from rasterio.windows import Window

from core.dem import SurfaceGrid
from core.errors import InputError

# GDAL block cache while building a COG: bounded so memory stays flat on large rasters
COG_CACHE_MB = 256


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
    lock each (memory stays bounded), then GDAL's COG driver copies them with overviews.
    Everything happens in temporary folders beside the outputs; each finished file
    replaces its output by a rename, so a failure never leaves a half-written product and
    an earlier product survives a failed rerun.
    """
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
                "blockysize": opts.blocksize, "compress": "DEFLATE", "BIGTIFF": "IF_SAFER",
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
        with dask.config.set(scheduler="threads"):
            results = dask.compute(stored, *(extra or []))[1:]
        for dst, tmp, out, predictor, blocksize, resampling in jobs:
            dst.close()
            cog = tmp / "cog.tif"
            with rasterio.Env(GDAL_CACHEMAX=COG_CACHE_MB):
                rasterio.shutil.copy(
                    tmp / "tiled.tif", cog, driver="COG", COMPRESS="DEFLATE",
                    PREDICTOR=str(predictor) if predictor else "NO", BLOCKSIZE=str(blocksize),
                    OVERVIEWS="AUTO", RESAMPLING=str(resampling).upper(), BIGTIFF="IF_SAFER",
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


def json_ready(obj: Any) -> Any:
    """``obj`` as strict JSON values: NaN and infinities -> None, tuples and arrays -> lists,
    NumPy scalars -> Python numbers, paths -> strings."""
    if isinstance(obj, dict):
        return {str(k): json_ready(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple, np.ndarray)):
        return [json_ready(v) for v in (obj.tolist() if isinstance(obj, np.ndarray) else obj)]
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, Path):
        return str(obj)
    return obj


def atomic_write_json(path: str | Path, doc: Any, indent: int | None = 1) -> Path:
    """``doc`` written as strict JSON (see :func:`json_ready`) through a temporary file."""
    return atomic_write_text(path, json.dumps(json_ready(doc), indent=indent, allow_nan=False))


def open_image(path: str | Path) -> rasterio.io.DatasetReader:
    """The raster at ``path`` (sensor images have no CRS: no warning for it); InputError when
    it cannot be read."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", NotGeoreferencedWarning)
            return rasterio.open(path)
    except RasterioIOError as exc:
        raise InputError(f"cannot read image {path}: {exc}; check the path") from exc


def read_surface_window(path: str | Path, bounds_m: tuple[float, float, float, float],
                        margin_cells: int = 2) -> SurfaceGrid:
    """The part of a north-up projected raster covering ``bounds_m`` (x_min, y_min, x_max,
    y_max) plus ``margin_cells``, as float64 heights (NaN outside the raster)."""
    xmin, ymin, xmax, ymax = bounds_m
    with rasterio.open(path) as src:
        t = src.transform
        res = t.a
        c0 = int(np.floor((xmin - t.c) / res)) - margin_cells
        c1 = int(np.ceil((xmax - t.c) / res)) + margin_cells
        r0 = int(np.floor((t.f - ymax) / res)) - margin_cells
        r1 = int(np.ceil((t.f - ymin) / res)) + margin_cells
        a = src.read(1, window=Window(c0, r0, c1 - c0, r1 - r0), boundless=True,
                     fill_value=np.nan, masked=False).astype(np.float64)
    return SurfaceGrid(a, t.c + (c0 + 0.5) * res, t.f - (r0 + 0.5) * res, res, res)
