"""Tasks of ``gcpfree fill-voids``: an SRTM tile's voids filled from an oriented DSM, written back
in the tile's own format and grid. The maths is :func:`core.evaluation.void_fill.delta_surface_fill`.

1. The tile: an SRTM ``.hgt`` (1201x1201 or 3601x3601 big-endian int16, placed by its name,
   ``N44E005.hgt``) or a lon/lat GeoTIFF of any size (int16 SRTM tiles, or float heights).
   Voids are ``-32768`` (or the GeoTIFF's nodata, NaN). Its vertical datum by the one rule
   (:func:`tasks.io.dem.dem_datum`: ``--srtm-vertical``, a ``vertical_datum`` tag such as
   ``prepare-reference`` writes, a vertical CRS, an SRTM name for EGM96, else refused).
2. The DSM (any projected or geographic CRS, NaN nodata): its vertical datum and height unit
   as ``gcpfree evaluate`` reads them (:func:`tasks.io.rasters_at_points.inspect_dem`: the
   ``vertical_datum`` tag of ``gcpfree dsm``, a compound CRS...). Only the window under the
   tile is read, averaged by GDAL to cells of about the tile's node spacing when the DSM is
   finer (so memory stays small whatever its resolution), then interpolated bilinearly at the
   tile's nodes (:func:`core.dem.sample_bilinear`) and brought to the tile's datum with the
   geoid (``H = h - N``).
3. Output: the tile's bytes with only the filled cells changed (rounded to whole metres in an
   integer tile), written atomically; ``OUT.json`` beside it holds the summary.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import rasterio
from prefect import task
from prefect.cache_policies import NO_CACHE
from rasterio.enums import Resampling
from rasterio.io import MemoryFile
from rasterio.windows import Window

from core.choices import check_vertical_choices
from core.dem import sample_bilinear
from core.errors import CoverageError, InputError
from core.evaluation.evaluation_report import DemInfo
from core.evaluation.void_fill import FillConfig, FillResult, delta_surface_fill, dsm_to_datum
from core.geodesy import ARCSEC, metres_per_degree
from core.geoid import GeoidGrid
from core.grid_points import affine_nodes
from core.heights import HeightFrame
from core.jsonio import to_json
from tasks.io.crs import Projection
from tasks.io.dem import dem_datum
from tasks.io.documents import plain
from tasks.io.geoid import load_geoid
from tasks.io.products import EVALUATION  # noqa: F401  (registers eval.json's layouts)
from tasks.io.rasters import atomic_write_bytes, atomic_write_json, open_raster
from tasks.io.rasters_at_points import inspect_dem
from tasks.io.srtm import SRTM_VOID, check_tile, parse_tile_name

TIFF_SUFFIXES = (".tif", ".tiff")
REPORT_FORMAT = "gcpfree.fill_voids"
BLOCK_ROWS = 256  # tile node rows resampled at a time


@dataclass(frozen=True)
class FillOptions:
    """Inputs of ``gcpfree fill-voids``: the ``srtm`` tile, the ``dem`` (DSM) and the output
    tile ``out`` (same format as ``srtm``; the summary goes to ``out`` with ``.json``).
    ``srtm_vertical``/``dem_vertical``: ``auto`` (read from the files) or ``egm96`` /
    ``ellipsoidal``; ``geoid``: a GTX grid (default the bundled EGM96)."""

    srtm: Path
    dem: Path
    out: Path
    srtm_vertical: str = "auto"
    dem_vertical: str = "auto"
    geoid: Path | None = None
    config: FillConfig = field(default_factory=FillConfig)

    def __post_init__(self) -> None:
        check_vertical_choices(self, "srtm_vertical", "dem_vertical")

    @property
    def json_path(self) -> Path:
        return Path(self.out).with_suffix(".json")


@dataclass(frozen=True, eq=False)
class TileGrid:
    """An SRTM tile read whole: its stored ``values`` (int16 or float), where it is
    (``transform``: affine coefficients, pixel-corner origin, EPSG:4326), its ``void`` value,
    vertical datum, and for a GeoTIFF the profile and tags to write it back with."""

    path: Path
    kind: str  # "hgt" or "geotiff"
    values: np.ndarray
    transform: tuple[float, float, float, float, float, float]
    void_value: float
    vertical: str
    vertical_source: str
    profile: dict[str, Any] | None = None
    tags: dict[str, str] | None = None

    @property
    def shape(self) -> tuple[int, int]:
        return self.values.shape  # type: ignore[return-value]

    def void_mask(self) -> np.ndarray:
        v = self.values
        mask = v == self.void_value
        if v.dtype.kind == "f":
            mask |= np.isnan(v) | (v <= SRTM_VOID + 0.5)
        return mask

    def heights_m(self) -> np.ndarray:
        """Heights as float64 metres, NaN on voids."""
        return np.where(self.void_mask(), np.nan, self.values.astype(np.float64))

    def lonlat(self, rows: slice, cols: slice) -> tuple[np.ndarray, np.ndarray]:
        """Longitudes and latitudes (degrees) of the nodes ``[rows, cols]``."""
        a, _, c, _, e, f = self.transform
        r, k = np.mgrid[rows, cols]
        return c + (k + 0.5) * a, f + (r + 0.5) * e


@dataclass(frozen=True)
class FillPlan:
    """The inputs checked: the tile (described, not held), the DSM as read, which tile nodes
    the DSM reaches (``rows``/``cols``: half-open ranges) and how the DSM is resampled."""

    tile_kind: str
    tile_shape: tuple[int, int]
    tile_res_arcsec: float
    tile_vertical: str
    tile_vertical_source: str
    dem: DemInfo
    dem_epsg: int
    rows: tuple[int, int]
    cols: tuple[int, int]
    node_spacing_m: float
    dem_cell_m: float
    decimation: int


@dataclass(frozen=True)
class FillSummary:
    """What ``fill-voids`` did, as printed and written to ``OUT.json``. Counts are cells;
    ``ring`` holds the statistics of ``DSM - SRTM`` (metres) on the valid border ring, with the
    keys of ``eval.json`` (``count``, ``mean`` = bias, ``nmad``...)."""

    srtm: str
    dem: str
    out: str
    json_path: str
    tile_format: str
    width: int
    height: int
    res_arcsec: float
    srtm_vertical: str
    srtm_vertical_source: str
    dem_crs: str
    dem_vertical: str
    dem_vertical_source: str
    dem_cell_m: float
    dem_read_cell_m: float
    nodes_under_dem: tuple[int, int, int, int]  # row0, row1, col0, col1 (half-open)
    border_cells: int
    outlier_nmad: float
    smooth_cells: int
    n_void: int
    n_filled: int
    n_still_void: int
    n_voids_under_dem: int
    n_voids_unanchored: int
    n_cells_unanchored: int
    fallback_delta_m: float
    ring: dict[str, Any]
    n_ring_rejected: int
    delta_min_m: float | None
    delta_max_m: float | None
    delta_mean_m: float | None
    filled_min_m: float | None
    filled_max_m: float | None

    def to_dict(self) -> dict[str, Any]:
        return {"format": REPORT_FORMAT, "version": 1, **asdict(self)}

    def to_json(self) -> str:
        return to_json(self.to_dict())

    def lines(self) -> list[str]:
        ring = self.ring
        dz = "" if self.delta_min_m is None else (
            f"SRTM - DSM added {self.delta_min_m:+.1f} .. {self.delta_max_m:+.1f} m "
            f"(mean {self.delta_mean_m:+.1f} m)")
        out = [
            (f"{'srtm':<14} {self.srtm}: {self.width} x {self.height} nodes at "
             f"{self.res_arcsec:g}\", {self.srtm_vertical} heights ({self.srtm_vertical_source})"),
            (f"{'dsm':<14} {self.dem}: {self.dem_crs}, {self.dem_cell_m:g} m cells read at "
             f"{self.dem_read_cell_m:g} m, {self.dem_vertical} heights "
             f"({self.dem_vertical_source})"),
            (f"{'voids':<14} {self.n_void} void cells, {self.n_filled} filled, "
             f"{self.n_still_void} still void ({self.n_voids_under_dem} voids under the DSM)"),
        ]
        if ring["count"]:
            out.append(
                f"{'border ring':<14} DSM - SRTM on {ring['count']} cells "
                f"({self.border_cells} around the voids): bias {ring['mean']:+.2f} m, "
                f"median {ring['median']:+.2f} m, NMAD {ring['nmad']:.2f} m, "
                f"LE68 {ring['le68']:.2f} m; {self.n_ring_rejected} outliers not used")
        else:
            out.append(f"{'border ring':<14} no valid cell with a DSM height around the voids")
        if dz:
            out.append(f"{'delta':<14} {dz}")
        if self.n_cells_unanchored:
            out.append(f"{'no border':<14} {self.n_cells_unanchored} cells in "
                       f"{self.n_voids_unanchored} void parts without a DSM border took the "
                       f"median difference {self.fallback_delta_m:+.2f} m")
        out.append(f"{'out':<14} {self.out}")
        out.append(f"{'json':<14} {self.json_path}")
        return out


# ---- reading ------------------------------------------------------------------------------------


def _tile_vertical(vertical: str, path: Path) -> tuple[str, str]:
    """The tile's datum by the one rule (:func:`tasks.io.dem.dem_datum`)."""
    d = dem_datum(path, vertical, what="SRTM tile", option="--srtm-vertical")
    return d.datum, d.source


def read_tile(path: str | Path, vertical: str = "auto") -> TileGrid:
    """Read an SRTM ``.hgt`` (placed by its name) or a lon/lat GeoTIFF tile whole."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"SRTM tile {path} does not exist; give a .hgt or GeoTIFF tile")
    suffix = path.suffix.lower()
    if suffix == ".hgt":
        corner = parse_tile_name(path.name)
        if corner is None:
            raise InputError(f"SRTM tile {path}: a .hgt is placed by its name; name it after "
                             "its south-west corner, e.g. N44E005.hgt")
        tile = check_tile(path, *corner)
        n = tile.size
        values = np.fromfile(path, dtype=">i2").reshape(n, n).astype(np.int16)
        r = tile.res_deg
        datum, source = _tile_vertical(vertical, path)
        return TileGrid(path, "hgt", values, (r, 0.0, tile.lon0 - r / 2, 0.0, -r,
                                              tile.lat0 + 1 + r / 2), SRTM_VOID, datum, source)
    if suffix not in TIFF_SUFFIXES:
        raise InputError(f"SRTM tile {path}: give a .hgt or a GeoTIFF (.tif), not {suffix!r}")
    with open_raster(path, "SRTM tile", "give a .hgt or GeoTIFF") as src:
        if src.crs is None or not src.crs.is_geographic:
            raise InputError(f"SRTM tile {path} is not in geographic coordinates (CRS "
                             f"{src.crs}); give a lon/lat tile (EPSG:4326)")
        t = src.transform
        if t.b != 0 or t.d != 0:
            raise InputError(f"SRTM tile {path} is rotated; warp it north-up first")
        if src.count != 1:
            raise InputError(f"SRTM tile {path} has {src.count} bands; give a one-band tile")
        values = src.read(1)
        profile = dict(src.profile)
        tags = src.tags()
    kind = np.dtype(values.dtype).kind
    if kind not in "iuf":
        raise InputError(f"SRTM tile {path} holds {values.dtype} values; give heights")
    nodata = profile.get("nodata")
    if nodata is None:
        nodata = np.nan if kind == "f" else SRTM_VOID
    datum, source = _tile_vertical(vertical, path)
    return TileGrid(path, "geotiff", values, tuple(t)[:6], float(nodata), datum, source,
                    profile, tags)


def _check_out(tile: TileGrid, out: Path) -> None:
    suffix = Path(out).suffix.lower()
    want = (".hgt",) if tile.kind == "hgt" else TIFF_SUFFIXES
    if suffix not in want:
        raise InputError(f"--out {out}: the filled tile is written in the input's format; give "
                         f"a {' or '.join(want)} path")
    if Path(out).resolve() == tile.path.resolve():
        raise InputError(f"--out {out} is the input tile; write the filled tile elsewhere")
    if tile.kind == "hgt" and parse_tile_name(Path(out).name) != parse_tile_name(tile.path.name):
        raise InputError(f"--out {out}: a .hgt is placed by its name alone; name it "
                         f"{tile.path.name} (in another folder) to keep the tile's grid")
    folder = Path(out).resolve().parent
    if not folder.is_dir():
        raise InputError(f"the folder of --out ({folder}) does not exist; create it first")


def _dem_bounds_lonlat(proj: Projection, bounds: tuple[float, ...]) -> tuple[float, ...]:
    """(lon_min, lat_min, lon_max, lat_max) of a DSM's bounds, its edges densified."""
    left, bottom, right, top = bounds
    s = np.linspace(0.0, 1.0, 33)
    x = np.concatenate([left + s * (right - left), np.full(33, right),
                        right - s * (right - left), np.full(33, left)])
    y = np.concatenate([np.full(33, bottom), bottom + s * (top - bottom), np.full(33, top),
                        top - s * (top - bottom)])
    lon, lat = proj.to_lonlat(x, y)
    return float(lon.min()), float(lat.min()), float(lon.max()), float(lat.max())


def plan_fill(options: FillOptions, tile: TileGrid | None = None) -> FillPlan:
    """Check the inputs (tile, DSM, output path) and find which tile nodes the DSM reaches;
    plain function, so the command fails in one line before any flow starts.

    Raises:
        InputError: unreadable or unsuitable inputs, an output of another format.
        CoverageError: the DSM and the tile do not overlap.
    """
    tile = tile or read_tile(options.srtm, options.srtm_vertical)
    _check_out(tile, Path(options.out))
    raster, info, _ = inspect_dem(Path(options.dem), options.dem_vertical)
    epsg = raster.horizontal.to_epsg()
    if epsg is None:
        raise InputError(f"DSM {options.dem} is in a CRS without an EPSG code "
                         f"({raster.horizontal.name}); reproject it to its UTM zone")
    a, b, _, d, e, _ = raster.transform
    if b != 0 or d != 0:
        raise InputError(f"DSM {options.dem} is rotated; warp it north-up first")
    proj = Projection(int(epsg))
    lon0, lat0, lon1, lat1 = _dem_bounds_lonlat(proj, info.bounds)
    fi, fj = affine_nodes(tile.transform, [lon0, lon1], [lat1, lat0])
    nr, nc = tile.shape
    r0, r1 = max(0, math.floor(fi[0])), min(nr, math.ceil(fi[1]) + 1)
    c0, c1 = max(0, math.floor(fj[0])), min(nc, math.ceil(fj[1]) + 1)
    if r1 - r0 < 2 or c1 - c0 < 2:
        raise CoverageError(
            f"DSM {options.dem} (lon {lon0:.3f}..{lon1:.3f}, lat {lat0:.3f}..{lat1:.3f}) does "
            f"not overlap SRTM tile {options.srtm}; give the DSM of the tile's area")
    ta, te = tile.transform[0], tile.transform[4]
    lat_c = tile.transform[5] + 0.5 * (r0 + r1) * te
    m_lon, m_lat = metres_per_degree(lat_c)
    spacing_m = float(min(abs(ta) * m_lon, abs(te) * m_lat))
    cell_m = float(min(abs(a), abs(e)))
    if raster.horizontal.is_geographic:
        cell_m = float(min(abs(a) * m_lon, abs(e) * m_lat))
    return FillPlan(
        tile_kind=tile.kind, tile_shape=tile.shape,
        tile_res_arcsec=round(abs(ta) / ARCSEC, 6), tile_vertical=tile.vertical,
        tile_vertical_source=tile.vertical_source, dem=info, dem_epsg=int(epsg),
        rows=(r0, r1), cols=(c0, c1), node_spacing_m=spacing_m, dem_cell_m=cell_m,
        decimation=max(1, math.floor(spacing_m / cell_m)))


def dsm_block(src: rasterio.io.DatasetReader, decimation: int, lon: np.ndarray,
              lat: np.ndarray, x: np.ndarray, y: np.ndarray, frame: HeightFrame, datum: str,
              geoid: GeoidGrid) -> np.ndarray:
    """The DSM at the points ``(x, y)`` of its CRS (``lon``, ``lat`` in degrees), in metres of
    ``datum``; NaN off the DSM. Reads the one window the points need, averaged by GDAL over
    ``decimation`` cells (the finite ones: NaN is the nodata), then samples it bilinearly."""
    f = decimation
    fi, fj = affine_nodes(tuple(src.transform)[:6], x, y)
    ok = np.isfinite(fi) & np.isfinite(fj)
    if not ok.any():
        return np.full(lon.shape, np.nan)
    # whole read cells of f x f DSM cells counted from the DSM's corner, so that every block
    # sees the same averages (a partial cell at the DSM's far edges is left out)
    r0 = max(0, (math.floor(fi[ok].min()) - f - 1) // f * f)
    c0 = max(0, (math.floor(fj[ok].min()) - f - 1) // f * f)
    n_rows = (min(src.height, math.ceil(fi[ok].max()) + 2 * f + 2) - r0) // f
    n_cols = (min(src.width, math.ceil(fj[ok].max()) + 2 * f + 2) - c0) // f
    if n_rows < 2 or n_cols < 2:
        return np.full(lon.shape, np.nan)
    z = src.read(1, window=Window(c0, r0, n_cols * f, n_rows * f), out_shape=(n_rows, n_cols),
                 resampling=Resampling.average, masked=True, out_dtype="float64").filled(np.nan)
    h = sample_bilinear(z, (fi - r0 + 0.5) / f - 0.5, (fj - c0 + 0.5) / f - 0.5)
    return dsm_to_datum(h, frame, datum, lon, lat, geoid)


def dsm_on_nodes(options: FillOptions, plan: FillPlan, tile: TileGrid) -> np.ndarray:
    """The DSM's heights (metres, the tile's datum) at the tile nodes ``plan.rows`` x
    ``plan.cols``; NaN where the DSM has none. Read :data:`BLOCK_ROWS` node rows at a time,
    so memory stays small whatever the sizes of the tile and the DSM."""
    (r0, r1), (c0, c1) = plan.rows, plan.cols
    out = np.full((r1 - r0, c1 - c0), np.nan)
    proj = Projection(plan.dem_epsg)
    frame = HeightFrame(plan.dem.vertical, plan.dem.z_factor_m)
    geoid = load_geoid(str(options.geoid) if options.geoid else None)
    with rasterio.open(options.dem) as src:
        for b0 in range(r0, r1, BLOCK_ROWS):
            b1 = min(r1, b0 + BLOCK_ROWS)
            lon, lat = tile.lonlat(slice(b0, b1), slice(c0, c1))
            x, y = proj.to_xy(lon.ravel(), lat.ravel())
            out[b0 - r0:b1 - r0] = dsm_block(src, plan.decimation, lon.ravel(), lat.ravel(),
                                             x, y, frame, tile.vertical,
                                             geoid).reshape(lon.shape)
    return out


# ---- writing ------------------------------------------------------------------------------------


def tile_values(tile: TileGrid, result: FillResult, rows: slice, cols: slice) -> np.ndarray:
    """The tile's stored values with the filled cells replaced (rounded and clipped to the
    range of an integer type, whose lowest value stays the void)."""
    out = tile.values.copy()
    sub = out[rows, cols]
    h = result.heights_m[result.filled]
    if out.dtype.kind in "iu":
        info = np.iinfo(out.dtype)
        h = np.clip(np.rint(h), info.min + 1, info.max)
    sub[result.filled] = h.astype(out.dtype)
    return out


def write_tile(tile: TileGrid, values: np.ndarray, out: Path) -> Path:
    """``values`` in the tile's format and grid, atomically: raw big-endian int16 for a
    ``.hgt``; for a GeoTIFF its profile and tags."""
    if tile.kind == "hgt":
        return atomic_write_bytes(out, values.astype(">i2").tobytes())
    profile = {k: v for k, v in (tile.profile or {}).items() if k != "driver"}
    with MemoryFile() as mem:
        with mem.open(driver="GTiff", **profile) as dst:
            dst.write(values, 1)
            if tile.tags:
                dst.update_tags(**tile.tags)
        data = mem.read()
    return atomic_write_bytes(out, data)


# ---- tasks --------------------------------------------------------------------------------------


def _summary(options: FillOptions, plan: FillPlan, tile: TileGrid,
             result: FillResult) -> FillSummary:
    d = result.delta_m[result.filled]
    hf = result.heights_m[result.filled]
    n_void = int(tile.void_mask().sum())
    c = plan.dem.crs
    return FillSummary(
        srtm=str(options.srtm), dem=str(options.dem), out=str(options.out),
        json_path=str(options.json_path), tile_format=tile.kind, width=tile.shape[1],
        height=tile.shape[0], res_arcsec=plan.tile_res_arcsec, srtm_vertical=tile.vertical,
        srtm_vertical_source=tile.vertical_source, dem_crs=c.authority or c.name,
        dem_vertical=plan.dem.vertical, dem_vertical_source=plan.dem.vertical_source,
        dem_cell_m=round(plan.dem_cell_m, 3),
        dem_read_cell_m=round(plan.dem_cell_m * plan.decimation, 3),
        nodes_under_dem=(*plan.rows, *plan.cols), border_cells=options.config.border_cells,
        outlier_nmad=options.config.outlier_nmad, smooth_cells=options.config.smooth_cells,
        n_void=n_void, n_filled=result.n_filled, n_still_void=n_void - result.n_filled,
        n_voids_under_dem=result.n_voids,
        n_voids_unanchored=result.n_voids_unanchored,
        n_cells_unanchored=result.n_cells_unanchored,
        fallback_delta_m=result.fallback_delta_m, ring=plain(result.ring),
        n_ring_rejected=result.n_ring_rejected,
        delta_min_m=float(d.min()) if d.size else None,
        delta_max_m=float(d.max()) if d.size else None,
        delta_mean_m=float(d.mean()) if d.size else None,
        filled_min_m=float(hf.min()) if hf.size else None,
        filled_max_m=float(hf.max()) if hf.size else None)


@task(name="fill-srtm-voids", cache_policy=NO_CACHE)
def fill_tile_voids(options: FillOptions) -> FillSummary:
    """Read the tile and the DSM under it, fill the voids (delta surface), write the tile in
    its own format and grid. Cell counts cover the whole tile."""
    tile = read_tile(options.srtm, options.srtm_vertical)
    plan = plan_fill(options, tile)
    rows, cols = slice(*plan.rows), slice(*plan.cols)
    dsm = dsm_on_nodes(options, plan, tile)
    result = delta_surface_fill(tile.heights_m()[rows, cols], dsm, options.config)
    write_tile(tile, tile_values(tile, result, rows, cols), Path(options.out))
    return _summary(options, plan, tile, result)


@task(name="write-fill-report", retries=1)
def write_fill_report(summary: FillSummary) -> Path:
    """``OUT.json``: the summary, atomically."""
    return atomic_write_json(summary.json_path, summary.to_dict())
