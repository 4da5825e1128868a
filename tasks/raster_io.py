"""Raster writing shared by every task: streamed tiled writes, then an atomic COG copy."""

from __future__ import annotations

import os
import tempfile
import threading
from pathlib import Path

import dask
import rasterio
import rasterio.shutil
import xarray as xr

# GDAL block cache while building a COG: bounded so memory stays flat on large rasters
COG_CACHE_MB = 256


def write_cog(
    da: xr.DataArray,
    out: str | Path,
    *,
    resampling: str = "average",
    predictor: int = 3,
    blocksize: int = 512,
) -> Path:
    """Write a (lazy) georeferenced DataArray to ``out`` as a Cloud-Optimized GeoTIFF.

    The array is streamed block by block into a tiled GeoTIFF (Dask threads, one
    write lock), then GDAL's COG driver copies it with overviews. Everything
    happens in a temporary folder beside ``out``; the finished file replaces
    ``out`` atomically, so a failure never leaves a half-written product and an
    earlier product at ``out`` survives a failed rerun.
    """
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=out.parent, prefix=f".{out.name}.tmp") as tmp:
        tiled = Path(tmp) / "tiled.tif"
        cog = Path(tmp) / "cog.tif"
        with dask.config.set(scheduler="threads"):
            da.rio.to_raster(
                tiled,
                driver="GTiff",
                tiled=True,
                blockxsize=blocksize,
                blockysize=blocksize,
                compress="DEFLATE",
                BIGTIFF="IF_SAFER",
                lock=threading.Lock(),
            )
        with rasterio.Env(GDAL_CACHEMAX=COG_CACHE_MB):
            rasterio.shutil.copy(
                tiled,
                cog,
                driver="COG",
                COMPRESS="DEFLATE",
                PREDICTOR=str(predictor) if predictor else "NO",
                BLOCKSIZE=str(blocksize),
                OVERVIEWS="AUTO",
                RESAMPLING=resampling.upper(),
                BIGTIFF="IF_SAFER",
            )
        _chmod_default(cog)
        os.replace(cog, out)
    return out


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
