"""Tasks of step 5: an image orthorectified on a DEM, tile by tile with Dask (a COG).

1. :func:`plan_ortho`: the output grid. The image footprint over the DEM's heights (read once,
   over the footprint at the model's plausible heights), in the local UTM zone or the CRS
   asked, cells of the image's GSD unless told, aligned on multiples of the cell size (two
   orthos at one resolution share a lattice, so :mod:`tasks.ortho.compare` can compare them)
   and cut to the DEM's extent. A DEM that misses the footprint stops here, in one line.
2. :func:`orthorectify`: every output tile of ``CHUNK`` cells reads the DEM under it and the
   image window it needs, and runs :func:`core.ortho.tile_geometry` and
   :func:`core.ortho.resample` (:func:`ortho_block`); the tiles stream into ``OUT`` (the
   image's type, its nodata or 0, overviews) and, when asked, ``OUT_occlusion.tif``
   (0 seen, 1 hidden by relief, 255 no data), with ``OUT.json``.

Memory per tile is bounded: one DEM window, one image window (read decimated when the cells
are twice the pixels or more) and a few arrays of the tile's cells.
"""

from __future__ import annotations

import contextlib
import math
import tempfile
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import dask.array as darr
import numpy as np
import pyproj
from prefect import task
from prefect.cache_policies import NO_CACHE

from core.choices import Resampling, VerticalChoice
from core.errors import CoverageError, InputError
from core.geodesy import utm_epsg
from core.heights import DatumDecision
from core.matching.grid import GridSpec
from core.ortho.ortho import OrthoConfig, resample, source_window, tile_geometry, to_dtype
from core.sensors.base import ray_ground_move_per_m
from core.sensors.footprint import footprint_box, footprint_lonlat, scene_height_range_m
from core.sensors.viewing import point_geometry
from tasks.io.crs import Projection
from tasks.io.rasters import (
    CHUNK,
    CogItem,
    CogOptions,
    atomic_write_json,
    open_raster,
    write_arrays_cog,
)
from tasks.io.sensors import LoadedModel, load_model
from tasks.ortho.inputs import (
    DemSource,
    bounds_in,
    dem_height_range,
    describe_dem,
    read_image_window,
    read_tile_dem,
)
from tasks.scheduling import Schedule, compute, schedule, threads

DEFAULT_CONFIG = OrthoConfig()
MAX_CELLS = 4_000_000_000
OCCLUSION_SEEN, OCCLUSION_HIDDEN, OCCLUSION_NODATA = 0, 1, 255


@dataclass(frozen=True, eq=False)
class OrthoPlan:
    """The output grid of an ortho and what its tiles read.

    ``grid`` in EPSG ``epsg``; ``image_size`` (cols, rows), ``dtype`` and ``src_nodata`` of
    the image (band 1 of ``n_bands``); ``nodata`` of the output; ``h_range_m`` the DEM's
    ellipsoidal heights over the footprint; ``coverage_pct`` the part of the footprint's box
    inside the DEM's extent; ``dem_margin_m`` the widening of each tile's DEM window (the
    reach of an occluding line of sight).
    """

    image: str
    model: LoadedModel
    dem: DemSource
    grid: GridSpec
    epsg: int
    image_size: tuple[int, int]
    n_bands: int
    dtype: str
    src_nodata: float | None
    nodata: float | None
    gsd_m: float
    h_range_m: tuple[float, float]
    coverage_pct: float
    dem_margin_m: float


@dataclass(frozen=True)
class OrthoSummary:
    """What :func:`orthorectify` wrote and measured."""

    path: str
    occlusion_path: str | None
    json_path: str
    image: str
    model: str
    dem: str
    dem_vertical: str
    dem_vertical_source: str
    epsg: int
    resolution_m: float
    width: int
    height: int
    resampling: str
    dtype: str
    nodata: float | None
    valid_pct: float
    occluded_pct: float | None
    coverage_pct: float
    max_error_px: float
    min_step_px: int
    h_range_m: tuple[float, float]

    def to_dict(self) -> dict[str, Any]:
        return {"format": "gcpfree.ortho", "version": 1, **asdict(self)}

    def lines(self) -> list[str]:
        out = [
            (f"ortho          {self.path} ({self.width} x {self.height} cells of "
             f"{self.resolution_m:g} m, EPSG:{self.epsg}, {self.resampling}, {self.dtype}, "
             f"nodata {self.nodata})"),
            (f"coverage       {self.valid_pct:.1f} % of the grid has a value; the DEM covers "
             f"{self.coverage_pct:.1f} % of the image footprint"),
            (f"DEM            {self.dem}: "
             + DatumDecision(self.dem_vertical, self.dem_vertical_source).describe()),
            (f"geometry       ellipsoidal heights {self.h_range_m[0]:.0f} .. "
             f"{self.h_range_m[1]:.0f} m; model interpolated within {self.max_error_px:.4f} px "
             f"(lattice down to {self.min_step_px} cells)"),
        ]
        if self.occlusion_path is not None:
            out.append(f"occlusion      {self.occlusion_path} ({self.occluded_pct:.2f} % of the "
                       "valid cells hidden by relief)")
        return out


@dataclass(frozen=True)
class OrthoOptions:
    """Inputs of ``gcpfree ortho``: the ``image`` (its ``model`` file, default found beside
    it; ``band`` for SPOT multispectral look angles), the ``dem`` and its ``dem_vertical``
    (``auto``, ``ellipsoidal``, ``egm96``), the output ``out`` (COG; ``.json`` beside it),
    ``resolution_m`` (default the image's GSD), ``epsg`` (default the local UTM zone),
    ``resampling``, ``occlusion_mask`` (written when given) and the parallel tiles
    ``workers``."""

    image: Path
    dem: Path
    out: Path
    model: Path | None = None
    band: int | None = None
    dem_vertical: VerticalChoice = "auto"
    resolution_m: float | None = None
    epsg: int | None = None
    resampling: Resampling = "bilinear"
    occlusion_mask: Path | None = None
    workers: int | None = None

    @property
    def config(self) -> OrthoConfig:
        """The kernel's settings (checked: a bad value raises InputError)."""
        return OrthoConfig(resampling=self.resampling, occlusion=self.occlusion_mask is not None)


def check_ortho_options(options: OrthoOptions) -> OrthoPlan:
    """Every input read and checked, no Prefect run: the model of the image, the DEM, the
    output grid (:func:`plan_ortho`), the output folders. Bad input is one InputError line."""
    options.config  # noqa: B018 (checks the settings)
    if not Path(options.image).exists():
        raise InputError(f"image {options.image} does not exist; give the image to "
                         "orthorectify")
    for path, what in ((options.out, "--out"), (options.occlusion_mask, "--occlusion-mask")):
        if path is not None and not Path(path).resolve().parent.is_dir():
            raise InputError(f"the folder of {what} ({Path(path).resolve().parent}) does not "
                             "exist; create it first")
    loaded = load_model(options.image, model=options.model, band=options.band)
    dem = describe_dem(options.dem, options.dem_vertical)
    return plan_ortho.fn(loaded, dem, options.resolution_m, options.epsg,
                         options.occlusion_mask is not None)


# ---------------------------------------------------------------------------- 1. plan


def output_epsg(epsg: int | None, lon_deg: float, lat_deg: float) -> int:
    """The CRS asked (checked: projected, in metres) or the UTM zone of (lon, lat)."""
    if epsg is None:
        return utm_epsg(lon_deg, lat_deg)
    try:
        crs = pyproj.CRS.from_epsg(int(epsg))
    except pyproj.exceptions.CRSError as exc:
        raise InputError(f"--crs {epsg} is not an EPSG code PROJ knows; give e.g. 32631") \
            from exc
    if not crs.is_projected or crs.axis_info[0].unit_name not in ("metre", "meter"):
        raise InputError(f"--crs EPSG:{epsg} ({crs.name}) is not a projected CRS in metres; "
                         "give one (e.g. a UTM zone) or leave it out for the local UTM zone")
    return int(epsg)


@task(name="plan-ortho", cache_policy=NO_CACHE)
def plan_ortho(loaded: LoadedModel, dem: DemSource, resolution_m: float | None = None,
               epsg: int | None = None, occlusion: bool = False) -> OrthoPlan:
    """The output grid (see the module docstring).

    Raises:
        InputError: a bad resolution or CRS, an unreadable image.
        CoverageError: the DEM has no height over the image footprint.
    """
    if resolution_m is not None and not resolution_m > 0:
        raise InputError(f"--resolution must be > 0 m, got {resolution_m}")
    image = loaded.image or loaded.source
    with open_raster(image, "image") as src:
        n_bands, dtype, src_nodata = src.count, src.dtypes[0], src.nodata
        size = (src.width, src.height)
    if size != tuple(loaded.size):
        raise InputError(f"{image} is {size[0]}x{size[1]} px but its model describes "
                         f"{loaded.size[0]}x{loaded.size[1]}; give the model of this image")
    box = footprint_box([(loaded.model, (0, 0, *loaded.size))],
                        scene_height_range_m([loaded.model]))
    h_range = dem_height_range(dem, box)
    if h_range is None:
        raise CoverageError(
            f"DEM {dem.path} has no height over the image footprint (lon {box.lon_min:.3f}.."
            f"{box.lon_max:.3f}, lat {box.lat_min:.3f}..{box.lat_max:.3f}); give a DEM "
            "covering the scene")
    lo, hi = h_range
    centre = point_geometry(loaded.model, 0.5 * (size[0] - 1), 0.5 * (size[1] - 1),
                            0.5 * (lo + hi))
    epsg = output_epsg(epsg, float(centre.lon_deg), float(centre.lat_deg))
    gsd = float(0.5 * (centre.gsd_across_m + centre.gsd_along_m))
    res = float(resolution_m) if resolution_m is not None else float(f"{gsd:.2g}")
    lon, lat = footprint_lonlat(loaded.model, *size, (lo, hi))
    x, y = Projection(epsg).to_xy(lon, lat)
    foot = (float(x.min()), float(y.min()), float(x.max()), float(y.max()))
    ext = bounds_in(dem, epsg)
    inter = (max(foot[0], ext[0]), max(foot[1], ext[1]), min(foot[2], ext[2]),
             min(foot[3], ext[3]))
    if inter[2] - inter[0] < res or inter[3] - inter[1] < res:
        raise CoverageError(f"DEM {dem.path} does not cover the image footprint; give a DEM "
                            "covering the scene")
    grid = GridSpec.covering(inter, res)
    if grid.n_rows * grid.n_cols > MAX_CELLS:
        raise InputError(f"{grid.n_cols} x {grid.n_rows} cells of {res:g} m is too many; give "
                         "a coarser --resolution")
    coverage = 100.0 * ((inter[2] - inter[0]) * (inter[3] - inter[1])
                        / max((foot[2] - foot[0]) * (foot[3] - foot[1]), 1e-9))
    margin = 0.0
    if occlusion:
        border_c, border_r = np.meshgrid(np.linspace(0, size[0] - 1, 5),
                                         np.linspace(0, size[1] - 1, 5))
        move = ray_ground_move_per_m(loaded.model, border_c.ravel(), border_r.ravel(), lo, hi)
        margin = (hi - lo) * move
    nodata = src_nodata
    if nodata is None:
        nodata = 0.0 if np.dtype(dtype).kind in "iu" else math.nan
    return OrthoPlan(str(image), loaded, dem, grid, epsg, size, n_bands, dtype, src_nodata,
                     nodata, gsd, (lo, hi), min(coverage, 100.0), margin)


# ---------------------------------------------------------------------------- 2. tiles


def ortho_block(block: np.ndarray, plan: OrthoPlan, config: OrthoConfig,
                block_info: dict | None = None) -> np.ndarray:
    """(4, h, w) float64 of one output tile: image values (NaN no data), occlusion (0/1, NaN
    where no value), the interpolation error found (px) and the lattice step (cells)."""
    (r0, r1), (c0, c1) = block_info[0]["array-location"][-2:]
    return ortho_tile(plan, config, r0, r1, c0, c1)


def ortho_tile(plan: OrthoPlan, config: OrthoConfig, r0: int, r1: int, c0: int, c1: int
               ) -> np.ndarray:
    """:func:`ortho_block` of the output cells ``[r0:r1, c0:c1]``."""
    g = plan.grid
    cells = GridSpec(g.x0_m + c0 * g.res_m, g.y0_m - r0 * g.res_m, g.res_m, c1 - c0, r1 - r0)
    out = np.full((4, r1 - r0, c1 - c0), np.nan)
    dem = read_tile_dem(plan.dem, cells.bounds_of(0, r1 - r0, 0, c1 - c0), plan.epsg,
                        plan.dem_margin_m)
    if dem is None:
        return out
    geo = tile_geometry(plan.model.model, cells, dem, Projection(plan.epsg).to_lonlat, config)
    out[2], out[3] = geo.max_error_px, geo.step_px
    win = source_window(geo.col, geo.row, plan.image_size, config.resampling)
    if win is None:
        return out
    pixels = read_image_window(plan.image, win)
    out[0] = resample(pixels, win, geo.col, geo.row, plan.image_size, config.resampling,
                      plan.src_nodata)
    if geo.occluded is not None:
        out[1] = np.where(np.isnan(out[0]), np.nan, geo.occluded)
    return out


def _as_type(values: np.ndarray, out_dtype: np.dtype, nodata: float | None) -> np.ndarray:
    return to_dtype(values, out_dtype, nodata)


def _tile_extreme(block: np.ndarray, ufunc: np.ufunc, initial: float) -> np.ndarray:
    return np.full((1, 1), ufunc.reduce(block.ravel(), initial=initial))


def _per_tile(plane: darr.Array, ufunc: np.ufunc, initial: float) -> darr.Array:
    """One value per tile: ``ufunc`` (np.fmax or np.fmin: NaN skipped) over the tile's cells,
    ``initial`` when all are NaN; one pass, no temporary array of the tile's size."""
    return plane.map_blocks(_tile_extreme, ufunc, initial, dtype=plane.dtype,
                            chunks=tuple((1,) * len(c) for c in plane.chunks))


def _occlusion_codes(occluded: np.ndarray) -> np.ndarray:
    return np.where(np.isnan(occluded), OCCLUSION_NODATA, occluded).astype(np.uint8)


def _tiles_in_threads(plan: OrthoPlan, config: OrthoConfig, dtype: np.dtype,
                      base: darr.Array) -> tuple[darr.Array, darr.Array, list[Any]]:
    """The typed ortho, its occlusion codes and the counts (valid cells, hidden cells, largest
    interpolation error, smallest lattice step) as one graph of :func:`ortho_block`."""
    stack = darr.map_blocks(ortho_block, base, plan=plan, config=config, new_axis=0,
                            chunks=((4,),) + base.chunks, dtype=np.float64)
    values = stack[0]
    ortho = values.map_blocks(_as_type, out_dtype=dtype, nodata=plan.nodata, dtype=dtype)
    codes = stack[1].map_blocks(_occlusion_codes, dtype=np.uint8)
    counts = [darr.isfinite(values).sum(), (stack[1] == 1).sum(),
              _per_tile(stack[2], np.fmax, -1.0).max(), _per_tile(stack[3], np.fmin, np.inf).min()]
    return ortho, codes, counts


def _tile_to_files(plan: OrthoPlan, config: OrthoConfig, dtype: np.dtype, r0: int, r1: int,
                   c0: int, c1: int, tmp: Path) -> tuple[int, int, float, float]:
    """One tile (:func:`ortho_tile`) in a worker process: its typed values (and occlusion
    codes) saved in ``tmp``; its counts returned."""
    out = ortho_tile(plan, config, r0, r1, c0, c1)
    np.save(tmp / f"values_{r0}_{c0}.npy", to_dtype(out[0], dtype, plan.nodata))
    if config.occlusion:
        np.save(tmp / f"occlusion_{r0}_{c0}.npy", _occlusion_codes(out[1]))
    return (int(np.isfinite(out[0]).sum()), int((out[1] == 1).sum()),
            float(np.fmax.reduce(out[2].ravel(), initial=-1.0)),
            float(np.fmin.reduce(out[3].ravel(), initial=np.inf)))


def _saved_tile(block: np.ndarray, tmp: Path, kind: str,
                block_info: dict | None = None) -> np.ndarray:
    (r0, _), (c0, _) = block_info[0]["array-location"][-2:]
    return np.load(tmp / f"{kind}_{r0}_{c0}.npy")


def _tiles_in_processes(plan: OrthoPlan, config: OrthoConfig, dtype: np.dtype,
                        base: darr.Array, tmp: Path, run: Schedule
                        ) -> tuple[darr.Array, darr.Array, list[Any]]:
    """:func:`_tiles_in_threads`'s values, the tiles computed in ``run.workers`` processes
    first (:func:`_tile_to_files`), then read back tile by tile by the writer."""
    import dask

    edges = [np.concatenate([[0], np.cumsum(c)]) for c in base.chunks]
    parts = [dask.delayed(_tile_to_files)(plan, config, dtype, int(r0), int(r1), int(c0),
                                          int(c1), tmp)
             for r0, r1 in zip(edges[0][:-1], edges[0][1:], strict=True)
             for c0, c1 in zip(edges[1][:-1], edges[1][1:], strict=True)]
    stats = np.array(compute(parts, workers=run.workers, processes=True), dtype=np.float64)
    ortho = base.map_blocks(_saved_tile, tmp, "values", dtype=dtype)
    codes = base.map_blocks(_saved_tile, tmp, "occlusion", dtype=np.uint8)
    counts = [int(stats[:, 0].sum()), int(stats[:, 1].sum()), float(stats[:, 2].max()),
              float(stats[:, 3].min())]
    return ortho, codes, counts


@task(name="orthorectify", cache_policy=NO_CACHE)
def orthorectify(plan: OrthoPlan, out: Path, config: OrthoConfig = DEFAULT_CONFIG,
                 num_workers: int | None = None,
                 occlusion_path: Path | None = None) -> OrthoSummary:
    """Write the ortho of ``plan`` to ``out`` (COG), the occlusion mask when
    ``config.occlusion`` (to ``occlusion_path``, default ``OUT_occlusion.tif``), and
    ``out.json``; return the summary.

    The tiles run as :func:`tasks.scheduling.schedule` decides: in worker processes from 8
    tiles on with more than one worker (the model's projection holds Python's lock much of
    the time, so threads shared one core: 1.13x with 2 on the spot pair), each writing its
    typed values (and occlusion codes) to a temporary file that the COG writer then streams;
    else in threads, straight into the writer."""
    out = Path(out)
    g = plan.grid
    dtype = np.dtype(plan.dtype) if np.dtype(plan.dtype).kind in "iu" else np.dtype(np.float32)
    base = darr.zeros(g.shape, chunks=CHUNK, dtype=np.float64)
    run = schedule(base.npartitions, num_workers, processes=None)
    tags = {"software": "gcpfree ortho", "image": Path(plan.image).name,
            "model": Path(plan.model.source).name, "dem": Path(plan.dem.path).name,
            "dem_vertical": plan.dem.vertical, "resampling": config.resampling}
    georef = {"transform": g.geotransform(), "crs": f"EPSG:{plan.epsg}"}
    if not config.occlusion:
        occlusion_path = None
    elif occlusion_path is None:
        occlusion_path = out.with_name(out.stem + "_occlusion.tif")
    with contextlib.ExitStack() as stack:
        if run.scheduler == "processes":
            tmp = Path(stack.enter_context(tempfile.TemporaryDirectory(
                dir=out.parent, prefix=f".{out.name}.tmp-tiles")))
            ortho, codes, counts = _tiles_in_processes(plan, config, dtype, base, tmp, run)
        else:
            ortho, codes, counts = _tiles_in_threads(plan, config, dtype, base)
        items = [CogItem(ortho, out, CogOptions(nodata=plan.nodata, tags=tags, **georef))]
        if config.occlusion:
            items.append(CogItem(codes, occlusion_path, CogOptions(
                nodata=OCCLUSION_NODATA, resampling="nearest",
                tags={"values": "0 seen, 1 hidden from the sensor by relief, 255 no data"},
                **georef)))
        with threads(num_workers):
            n_valid, n_hidden, err, step = write_arrays_cog(items, extra=counts)
    n_valid = int(n_valid)
    summary = OrthoSummary(
        path=str(out), occlusion_path=str(occlusion_path) if occlusion_path else None,
        json_path=str(out.with_suffix(".json")), image=plan.image,
        model=str(plan.model.source), dem=plan.dem.path, dem_vertical=plan.dem.vertical,
        dem_vertical_source=plan.dem.vertical_source, epsg=plan.epsg, resolution_m=g.res_m, width=g.n_cols, height=g.n_rows,
        resampling=config.resampling, dtype=dtype.name,
        nodata=None if plan.nodata is None or math.isnan(plan.nodata) else plan.nodata,
        valid_pct=100.0 * n_valid / (g.n_rows * g.n_cols),
        occluded_pct=(100.0 * int(n_hidden) / max(n_valid, 1)) if config.occlusion else None,
        coverage_pct=plan.coverage_pct,
        max_error_px=max(float(err), 0.0),
        min_step_px=int(step) if np.isfinite(step) else config.step_px,
        h_range_m=plan.h_range_m)
    atomic_write_json(out.with_suffix(".json"), summary.to_dict())
    return summary
