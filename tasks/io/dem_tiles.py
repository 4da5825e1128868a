"""DEM tiles in a folder: the tiles of one product covering a box (named tiles, or tagged DEMs
of their own extent), the nodes their mosaic spans, and that mosaic, lazily, as a GDAL VRT on
the finest tile's own lattice (with the product's quality masks on the same grid). What each
product's files are is :mod:`tasks.io.dem_products`.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from xml.sax.saxutils import escape

import numpy as np

from core.errors import CoverageError, InputError
from core.geodesy import BBox
from core.heights import DatumDecision
from tasks.io.dem_products import (
    EDGE_DEG,
    MASKS,
    TAGGED,
    DemTile,
    Product,
    check_named,
    product_of,
    tile_of,
    zip_member,
)
from tasks.io.rasters import open_raster
from tasks.io.srtm import SRTM_VOID, tile_name

#: cells whose stated height error (HEM, 1 sigma) exceeds this are voided: twice SRTM's noise
MAX_HEIGHT_ERROR_M = 10.0


@dataclass(frozen=True)
class DemSource:
    """What a reference is prepared from: a folder of DEM tiles, or one DEM file, with what the
    user said of its heights: ``vertical`` (a file's ``--reference-vertical``; a folder's
    tiles say their own), ``geoid`` (the grid its orthometric heights refer to, ``--geoid``),
    ``max_height_error_m`` (Copernicus cells whose height-error mask says more are voided)."""

    path: Path
    vertical: str = "auto"
    geoid: Path | None = None
    max_height_error_m: float = MAX_HEIGHT_ERROR_M

    def __post_init__(self) -> None:
        object.__setattr__(self, "path", Path(self.path))
        if self.geoid is not None:
            object.__setattr__(self, "geoid", Path(self.geoid))
        if not self.max_height_error_m > 0:
            raise InputError(f"the height-error limit must be positive, got "
                             f"{self.max_height_error_m} m")


@dataclass(frozen=True)
class TileSet:
    """The tiles of one product covering a box, the node extent the mosaic may span (its
    degrees', or the tiles' own), the lattice's origin (``phase``: a node; 0 for products on
    whole multiples of their spacing), and the vertical datum of their heights once decided
    (:func:`tasks.io.dem.tile_datum`)."""

    source: DemSource
    product: Product
    tiles: tuple[DemTile, ...]
    extent: tuple[float, float, float, float]
    phase: tuple[float, float] = (0.0, 0.0)
    datum: DatumDecision | None = field(default=None, compare=False)

    def __iter__(self) -> Iterator[DemTile]:
        return iter(self.tiles)

    def __len__(self) -> int:
        return len(self.tiles)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(t.path.name for t in self.tiles)

    def describe(self) -> str:
        """One line: how many tiles of which product, and what their heights are."""
        what = f"{len(self.tiles)} {self.product.name} tile(s)"
        return what if self.datum is None else f"{what}: {self.datum.describe()}"


# ---- finding and checking tiles ----------------------------------------------------------------


def required_tiles(bbox: BBox) -> list[tuple[int, int]]:
    """South-west corners of the 1x1 degree tiles whose area the box overlaps."""
    lons = range(math.floor(bbox.lon_min), max(math.ceil(bbox.lon_max), math.floor(bbox.lon_min) + 1))
    lats = range(math.floor(bbox.lat_min), max(math.ceil(bbox.lat_max), math.floor(bbox.lat_min) + 1))
    return [(lo, la) for la in lats for lo in lons]


def find_tiles(source: DemSource | str | Path, bbox: BBox, *,
               allow_missing: bool = False) -> TileSet:
    """The checked tiles of ``source`` (a folder, or one DEM file) covering ``bbox``: the
    named tiles of one product, else the folder's lon/lat GeoTIFFs that overlap the box.

    Raises InputError for a missing folder, tiles of two products over the box or a malformed
    tile, and CoverageError naming the missing tiles (unless ``allow_missing``, e.g. for coasts
    where SRTM has no ocean tiles; at least one tile must exist)."""
    src = source if isinstance(source, DemSource) else DemSource(Path(source))
    if src.path.is_file():
        return _one_file(src, bbox)
    d = src.path
    if not d.is_dir():
        raise InputError(f"DEM tile folder {d} does not exist; give --dem-dir (or --srtm-dir) "
                         "a folder of tiles")
    by_product = _named_files(d)
    need = required_tiles(bbox)
    present = {p: found for p, found in by_product.items() if any(k in found for k in need)}
    if len(present) > 1:
        names = ", ".join(f"{p.name} ({next(found[k] for k in need if k in found).name})"
                          for p, found in present.items())
        raise InputError(f"{d} holds tiles of more than one product over the box: {names}; "
                         "their heights need not refer to one geoid: give a folder of one")
    if not by_product:
        return _tagged_set(src, bbox)
    product, found = next(iter(present.items())) if present else next(iter(by_product.items()))
    missing = [k for k in need if k not in found]
    if missing and (not allow_missing or len(missing) == len(need)):
        names = ", ".join(tile_name(*k) for k in missing)
        raise CoverageError(
            f"{product.name} in {d} does not cover the box {bbox.lon_min} {bbox.lat_min} "
            f"{bbox.lon_max} {bbox.lat_max}: missing tile(s) {names}; add them to the folder")
    tiles = tuple(check_named(found[k], product, k) for k in need if k in found)
    if not allow_missing:
        _check_covers(tiles, bbox)
    return TileSet(src, product, tiles, _degrees_extent(need, product))


def _named_files(d: Path) -> dict[Product, dict[tuple[int, int], Path]]:
    """The folder's tiles by product and degree (the first name in sorted order of each):
    SRTM and NASADEM in the folder itself, Copernicus anywhere below it."""
    out: dict[Product, dict[tuple[int, int], Path]] = {}
    files = [p for p in sorted(d.iterdir()) if p.is_file()]
    files += sorted(p for p in d.rglob("Copernicus_DSM_*") if p.is_file() and p.parent != d)
    for p in files:
        if (found := product_of(p.name)) is not None:
            out.setdefault(found[0], {}).setdefault(found[1], p)
    return out


def _degrees_extent(need: list[tuple[int, int]], product: Product
                    ) -> tuple[float, float, float, float]:
    """The nodes the degrees ``need`` hold: both edges (SRTM), or not the south and east ones
    (Copernicus: those are the neighbours' first nodes)."""
    lons = [k[0] for k in need]
    lats = [k[1] for k in need]
    edge = 0.0 if product.shared_edges else EDGE_DEG
    return (min(lons), min(lats) + edge, max(lons) + 1 - edge, max(lats) + 1)


def _check_covers(tiles: tuple[DemTile, ...], bbox: BBox) -> None:
    """CoverageError when a tile (a crop of its degree) leaves part of the box's share of its
    degree without nodes."""
    for t in tiles:
        lon0, lat0 = t.corner  # type: ignore[misc]
        need = (max(bbox.lon_min, lon0), max(bbox.lat_min, lat0),
                min(bbox.lon_max, lon0 + 1), min(bbox.lat_max, lat0 + 1))
        w, s, e, n = t.extent
        tol_x, tol_y = t.res_lon_deg, t.res_lat_deg  # an open edge ends one cell short
        if w > need[0] + 1e-9 or s > need[1] + tol_y or e < need[2] - tol_x or n < need[3] - 1e-9:
            raise CoverageError(
                f"{t.product.name} tile {t.path} covers lon {w:.5f}..{e:.5f}, lat {s:.5f}.."
                f"{n:.5f} only, not the box's part of its degree (lon {need[0]:.5f}.."
                f"{need[2]:.5f}, lat {need[1]:.5f}..{need[3]:.5f}); give the whole tile, or a "
                "smaller box")


def _one_file(src: DemSource, bbox: BBox) -> TileSet:
    """One DEM file as a tile set of its own extent and lattice."""
    found = product_of(src.path.name)
    product, corner = found if found else (TAGGED, None)
    if found:
        tile = check_named(src.path, product, corner)  # type: ignore[arg-type]
    else:
        with open_raster(src.path, "DEM", "give a GeoTIFF in EPSG:4326") as r:
            tile = tile_of(r, src.path, TAGGED, None, "DEM")
    _must_overlap(tile, bbox)
    phase = (0.0, 0.0) if found else (tile.extent[0], tile.extent[3])  # named: whole multiples
    return TileSet(src, product, (tile,), tile.extent, phase)


def _tagged_set(src: DemSource, bbox: BBox) -> TileSet:
    """The folder's lon/lat GeoTIFFs overlapping the box (a folder of no named product)."""
    tiles = []
    for p in sorted(src.path.iterdir()):
        if p.suffix.lower() in (".tif", ".tiff") and p.is_file():
            with open_raster(p, "DEM", "give GeoTIFFs in EPSG:4326") as r:
                tile = tile_of(r, p, TAGGED, None, "DEM")
            if _overlaps(tile, bbox):
                tiles.append(tile)
    if not tiles:
        raise CoverageError(f"no DEM in {src.path} covers the box {bbox.lon_min} {bbox.lat_min} "
                            f"{bbox.lon_max} {bbox.lat_max} (SRTM, NASADEM or Copernicus tiles, "
                            "or lon/lat GeoTIFFs); add tiles covering it")
    finest = min(tiles, key=lambda t: (t.res_lon_deg * t.res_lat_deg, t.path.name))
    ext = tuple(f(t.extent[i] for t in tiles) for i, f in enumerate((min, min, max, max)))
    return TileSet(src, TAGGED, tuple(tiles), ext,  # type: ignore[arg-type]
                   (finest.extent[0], finest.extent[3]))


def _overlaps(tile: DemTile, bbox: BBox) -> bool:
    w, s, e, n = tile.extent
    return w <= bbox.lon_max and e >= bbox.lon_min and s <= bbox.lat_max and n >= bbox.lat_min


def _must_overlap(tile: DemTile, bbox: BBox) -> None:
    if not _overlaps(tile, bbox):
        w, s, e, n = tile.extent
        raise CoverageError(
            f"DEM {tile.path} (lon {w:.3f}..{e:.3f}, lat {s:.3f}..{n:.3f}) does not cover the "
            f"box (lon {bbox.lon_min:.3f}..{bbox.lon_max:.3f}, lat {bbox.lat_min:.3f}.."
            f"{bbox.lat_max:.3f}); give a DEM covering the scene")


# ---- the mosaic ------------------------------------------------------------------------------


@dataclass(frozen=True)
class MosaicGrid:
    """The output lattice: nodes at ``lon0 + j*res_lon_deg``, ``lat0 - i*res_lat_deg``."""

    lon0: float  # centre of the top-left cell
    lat0: float
    res_lon_deg: float
    res_lat_deg: float
    width: int
    height: int

    @property
    def transform(self) -> tuple[float, float, float, float, float, float]:
        """Affine coefficients (a, b, c, d, e, f): pixel corner origin, north-up."""
        a, r = self.res_lon_deg, self.res_lat_deg
        return (a, 0.0, self.lon0 - a / 2, 0.0, -r, self.lat0 + r / 2)


def _node_range(lo: float, hi: float, res: float, phase: float) -> tuple[float, int]:
    """The first node at or after ``lo`` on the lattice ``phase + k res`` and how many lie in
    ``[lo, hi]``; whole fractions of a degree stay exact (``k / n``)."""
    k0 = math.ceil((lo - phase) / res - 1e-6)
    k1 = math.floor((hi - phase) / res + 1e-6)
    n = round(1.0 / res)
    exact = phase == 0.0 and abs(1.0 / res - n) < 1e-6
    return (k0 / n if exact else phase + k0 * res), k1 - k0 + 1


def mosaic_grid(tiles: TileSet, bbox: BBox) -> MosaicGrid:
    """The finest tile lattice restricted to the nodes inside ``bbox`` and the set's extent."""
    res_lon = min(t.res_lon_deg for t in tiles)
    res_lat = min(t.res_lat_deg for t in tiles)
    w, s, e, n = tiles.extent
    lon0, width = _node_range(max(bbox.lon_min, w), min(bbox.lon_max, e), res_lon, tiles.phase[0])
    lat_s, height = _node_range(max(bbox.lat_min, s), min(bbox.lat_max, n), res_lat,
                                tiles.phase[1])
    if width < 1 or height < 1:
        raise InputError(f"the box is smaller than one {tiles.product.name} cell; enlarge it "
                         "or add a margin")
    return MosaicGrid(lon0, lat_s + (height - 1) * res_lat, res_lon, res_lat, width, height)


def _offset(v: float) -> float:
    """A source's place on the grid in cells: whole when it is within rounding of whole."""
    return float(round(v)) if abs(v - round(v)) < 1e-6 else v


def _vrt(grid: MosaicGrid, sources: list[str], data_type: str, nodata: float | str) -> str:
    gt = ", ".join(repr(v) for v in (grid.transform[2], grid.transform[0], 0.0,
                                     grid.transform[5], 0.0, grid.transform[4]))
    return f"""<VRTDataset rasterXSize="{grid.width}" rasterYSize="{grid.height}">
  <SRS dataAxisToSRSAxisMapping="2,1">EPSG:4326</SRS>
  <GeoTransform>{gt}</GeoTransform>
  <Metadata><MDI key="AREA_OR_POINT">Area</MDI></Metadata>
  <VRTRasterBand dataType="{data_type}" band="1">
    <NoDataValue>{nodata}</NoDataValue>
{chr(10).join(sources)}
  </VRTRasterBand>
</VRTDataset>
"""


def _source(path: str, grid: MosaicGrid, resampling: str | None, nodata: float | str | None
            ) -> str:
    """A ComplexSource placing the raster GDAL opens at ``path`` on ``grid`` by its own
    transform."""
    import rasterio

    with rasterio.open(path) as src:
        st, w, h = src.transform, src.width, src.height
    a, _, c, _, e, f = grid.transform
    same = abs(st.a - a) < 1e-12 and abs(st.e - e) < 1e-12
    resamp = "" if same and resampling is None else f' resampling="{resampling or "bilinear"}"'
    nd = "" if nodata is None else f"\n      <NODATA>{nodata}</NODATA>"
    return f"""    <ComplexSource{resamp}>
      <SourceFilename relativeToVRT="0">{escape(path)}</SourceFilename>
      <SourceBand>1</SourceBand>
      <SrcRect xOff="0" yOff="0" xSize="{w}" ySize="{h}"/>
      <DstRect xOff="{_offset((st.c - c) / a)!r}" yOff="{_offset((st.f - f) / e)!r}" xSize="{_offset(w * st.a / a)!r}" ySize="{_offset(h * st.e / e)!r}"/>{nd}
    </ComplexSource>"""


def build_vrt(tiles: TileSet, grid: MosaicGrid) -> str:
    """GDAL VRT XML mosaicking the tiles' heights onto ``grid`` (bilinear where a tile is
    coarser), each tile's void value as its nodata."""
    sources = [_source(t.gdal_path if zip_member(t.path) else str(t.path.resolve()), grid,
                       None, t.void) for t in tiles]
    return _vrt(grid, sources, "Float32", SRTM_VOID)


def build_mask_vrt(tiles: TileSet, grid: MosaicGrid, kind: str) -> str | None:
    """GDAL VRT XML of the tiles' ``kind`` masks (``WBM``, ``HEM``, ``EDM``) on ``grid``,
    nearest cell; None when no tile has that mask."""
    data_type, nodata = MASKS[kind]
    sources = [_source(str(p.resolve()), grid, "nearest", None) for t in tiles
               for k, p in t.masks if k == kind]
    return _vrt(grid, sources, data_type, nodata) if sources else None


def covered(lon: np.ndarray, lat: np.ndarray, tiles: TileSet | list[DemTile]) -> np.ndarray:
    """True where (lon, lat) (broadcast) falls inside the nodes of one of ``tiles``."""
    lon, lat = np.broadcast_arrays(lon, lat)
    m = np.zeros(lon.shape, dtype=bool)
    eps = 1e-9
    for t in tiles:
        w, s, e, n = t.extent
        m |= (lon >= w - eps) & (lon <= e + eps) & (lat >= s - eps) & (lat <= n + eps)
    return m
