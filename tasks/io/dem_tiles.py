"""DEM tiles in a folder: which product each file is, the tiles covering a box, their lattice,
the product's own quality masks beside them, and their lazy mosaic (a GDAL VRT).

The products, by the names they are distributed under:

- SRTM: ``N44E005.hgt``, ``N44E005.SRTMGL1.hgt``, ``n44_e005_1arc_v3.tif``, ``N44E005.tif``;
  1201 (3") or 3601 (1") nodes a side, on whole multiples of the spacing, both edges of the
  degree included (shared with the neighbours); EGM96 heights, -32768 voids.
- NASADEM: ``NASADEM_HGT_n44e005.zip`` as distributed (its ``n44e005.hgt`` read inside it;
  unzipped, that is an SRTM name, read as SRTM) or ``NASADEM_HGT_n44e005.tif``: SRTM's 1"
  lattice, EGM96 heights.
- Copernicus DEM GLO-30 / GLO-90: ``Copernicus_DSM_COG_10_N54_00_W165_00_DEM.tif`` (AWS) or
  ``Copernicus_DSM_10_N54_00_W165_00_DEM.tif`` (ESA), in the folder or in the layouts of
  their distributions (``<tile>/DEM/<tile>_DEM.tif``, ``<tile>_DEM/<tile>_DEM.tif``); 3600
  (GLO-90: 1200) rows of 1" (3"), columns of 1" south of 50 degrees, 1.5" to 60, 2" to 70,
  3" to 80, 5" to 85, 10" beyond (GLO-90: three times those); the first node on the tile's
  north-west corner, none on its south and east edges; EGM2008 heights (said by nothing in
  the file but its name). The masks of its AUXFILES beside the tile (``_WBM`` water body: 1
  ocean, 2 lake, 3 river; ``_HEM`` height error, 1 sigma in metres; ``_EDM`` editing, 0 void)
  void water and unreliable cells.
- any other lon/lat GeoTIFF (a national DEM) whose tag or CRS says its datum, or whose
  heights the user says are above a geoid grid (``--geoid``): its own extent and lattice,
  when the folder holds no named tiles.

Every file is georeferenced by GDAL, which reads a pixel-is-point GeoTIFF (SRTM, Copernicus)
and a pixel-is-area one into the same cell centres: a tile's nodes are its pixel centres.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from xml.sax.saxutils import escape

import numpy as np

from core.errors import CoverageError, InputError
from core.geodesy import ARCSEC, BBox
from core.heights import DatumDecision
from tasks.io.rasters import open_raster
from tasks.io.srtm import SRTM_VOID, check_tile, parse_tile_name, tile_name

COPERNICUS_VOID = -32767.0
#: a Copernicus tile's AUXFILES masks read here: (file suffix, GDAL data type, "no data" value)
MASKS = {"WBM": ("Byte", 255), "HEM": ("Float32", "nan"), "EDM": ("Byte", 255)}
#: cells whose stated height error (HEM, 1 sigma) exceeds this are voided: twice SRTM's noise
MAX_HEIGHT_ERROR_M = 10.0
_COP_RE = re.compile(r"^Copernicus_DSM_(?:COG_)?(10|30)_([NS])(\d{2})_00_([EW])(\d{3})_00"
                     r"(?:_DEM)?\.tiff?$", re.IGNORECASE)
_NASADEM_RE = re.compile(r"^NASADEM_HGT_([ns])(\d{2})([ew])(\d{3})\.(?:hgt|zip|tiff?)$",
                         re.IGNORECASE)
_SRTM_SUFFIXES = (".hgt", ".tif", ".tiff")
_EDGE_DEG = 1e-7  # a node this close inside a degree's open edge belongs to the next tile


@dataclass(frozen=True)
class Product:
    """A DEM product as its tiles are named: ``datum`` its names say (None: the file says it
    itself), ``shared_edges`` whether a tile holds both edges of its degree (SRTM), ``void``
    the void value of its files when they declare no nodata."""

    name: str
    datum: str | None
    shared_edges: bool = True
    void: float | None = None


SRTM = Product("SRTM", "egm96", True, SRTM_VOID)
NASADEM = Product("NASADEM", "egm96", True, SRTM_VOID)
GLO30 = Product("Copernicus GLO-30", "egm2008", False, COPERNICUS_VOID)
GLO90 = Product("Copernicus GLO-90", "egm2008", False, COPERNICUS_VOID)
TAGGED = Product("DEM", None, False, None)


def product_of(name: str) -> tuple[Product, tuple[int, int]] | None:
    """The product a file name says and the south-west corner (lon, lat) of its degree, or
    None for a name no product uses."""
    if m := _COP_RE.match(name):
        lat = int(m.group(3)) * (1 if m.group(2).upper() == "N" else -1)
        lon = int(m.group(5)) * (1 if m.group(4).upper() == "E" else -1)
        return (GLO30 if m.group(1) == "10" else GLO90), (lon, lat)
    if m := _NASADEM_RE.match(name):
        lat = int(m.group(2)) * (1 if m.group(1).lower() == "n" else -1)
        lon = int(m.group(4)) * (1 if m.group(3).lower() == "e" else -1)
        return NASADEM, (lon, lat)
    if Path(name).suffix.lower() in _SRTM_SUFFIXES and (k := parse_tile_name(name)):
        return SRTM, k
    return None


def named_datum(path: Path) -> tuple[str, str] | None:
    """``(datum, reason)`` a product's file name says (step 4 of the datum rule), or None."""
    found = product_of(path.name)
    if found is None or found[0].datum is None:
        return None
    product = found[0]
    label = {"egm96": "EGM96", "egm2008": "EGM2008"}[product.datum]
    return product.datum, f"{product.name} file {path.name}: {label}"


def copernicus_spacing_arcsec(product: Product, lat0: int) -> tuple[float, float]:
    """(columns, rows) spacing of a Copernicus tile whose degree starts at ``lat0``: columns
    widen with latitude so cells stay about square on the ground."""
    band = lat0 if lat0 >= 0 else -lat0 - 1  # the tile's smallest |latitude|, whole degrees
    factor = next(f for top, f in ((50, 1), (60, 1.5), (70, 2), (80, 3), (85, 5), (91, 10))
                  if band < top)
    base = 1.0 if product is GLO30 else 3.0
    return base * factor, base


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
class DemTile:
    """One DEM file of a tile set: its product and degree (None for a DEM of its own extent),
    its node spacing, the extent of its nodes (west, south, east, north: the outer cells'
    centres), the void value its cells use, and its quality masks found beside it."""

    path: Path
    product: Product
    corner: tuple[int, int] | None
    res_lon_deg: float
    res_lat_deg: float
    extent: tuple[float, float, float, float]
    void: float | None = None
    masks: tuple[tuple[str, Path], ...] = ()

    @property
    def gdal_path(self) -> str:
        """What GDAL opens: the file, or the ``.hgt`` inside a NASADEM zip."""
        return zip_member(self.path) or str(self.path)

    @property
    def res_deg(self) -> float:
        """The finer of its two spacings."""
        return min(self.res_lon_deg, self.res_lat_deg)

    @property
    def lon0(self) -> int | None:
        return None if self.corner is None else self.corner[0]

    @property
    def lat0(self) -> int | None:
        return None if self.corner is None else self.corner[1]


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


def zip_member(path: Path) -> str | None:
    """GDAL's path of the ``.hgt`` inside a NASADEM zip (``NASADEM_HGT_n44e005.zip`` holds
    ``n44e005.hgt``), None for any other file."""
    if path.suffix.lower() != ".zip":
        return None
    return f"/vsizip/{path.resolve()}/{path.stem[len('NASADEM_HGT_'):].lower()}.hgt"


def check_named(path: Path, product: Product, corner: tuple[int, int]) -> DemTile:
    """Validate one named tile against its product's lattice; InputError says what is wrong."""
    what = f"{product.name} tile"
    member = zip_member(path)
    if product is NASADEM and path.suffix.lower() == ".hgt":
        raise InputError(f"{what} {path}: GDAL reads a .hgt by its SRTM name; keep the zip as "
                         f"distributed or name the file {path.stem[len('NASADEM_HGT_'):]}.hgt")
    if product in (SRTM, NASADEM) and member is None:
        check_tile(path, *corner)  # sizes of .hgt and SRTM GeoTIFFs
    if member is not None:
        import rasterio

        try:
            src = rasterio.open(member)
        except rasterio.errors.RasterioIOError as exc:
            raise InputError(f"cannot read {what} {path}: {exc}; download it again") from exc
        if (src.width, src.height) != (3601, 3601):
            src.close()
            raise InputError(f"{what} {path} holds {src.width}x{src.height} heights, not "
                             "NASADEM's 3601x3601; download it again")
    else:
        src = open_raster(path, what, "replace the file")
    with src:
        tile = _tile_of(src, path, product, corner, what)
    if product in (GLO30, GLO90):
        _check_copernicus_lattice(tile, corner)
    return tile


def _tile_of(src, path: Path, product: Product, corner: tuple[int, int] | None,
             what: str) -> DemTile:
    """A DemTile from an open raster (its nodes are its pixel centres)."""
    t = src.transform
    if src.crs is not None and not src.crs.is_geographic:
        raise InputError(f"{what} {path} is in {src.crs}, not longitude/latitude; reproject it "
                         "to EPSG:4326 (e.g. gdalwarp -t_srs EPSG:4326)")
    if t.b != 0 or t.d != 0 or t.a <= 0 or t.e >= 0:
        raise InputError(f"{what} {path} is not a north-up lon/lat grid; reproject it to "
                         "EPSG:4326")
    west, north = t.c + 0.5 * t.a, t.f + 0.5 * t.e
    extent = (west, north + (src.height - 1) * t.e, west + (src.width - 1) * t.a, north)
    void = src.nodata if src.nodata is not None else product.void
    masks = _masks_beside(path) if product in (GLO30, GLO90) else ()
    return DemTile(path, product, corner, t.a, -t.e, extent, void, masks)


def _check_copernicus_lattice(tile: DemTile, corner: tuple[int, int]) -> None:
    """A Copernicus tile (or a crop of one) on its product's lattice, inside its degree."""
    dx_as, dy_as = copernicus_spacing_arcsec(tile.product, corner[1])
    lon0, lat0 = corner
    west, south, east, north = tile.extent
    steps = ((west - lon0) / (dx_as * ARCSEC), (lat0 + 1 - north) / (dy_as * ARCSEC))
    ok = (abs(tile.res_lon_deg / ARCSEC - dx_as) < 1e-6 and
          abs(tile.res_lat_deg / ARCSEC - dy_as) < 1e-6 and
          all(abs(s - round(s)) < 1e-3 for s in steps) and
          west > lon0 - 1e-9 and east < lon0 + 1 - _EDGE_DEG and
          north < lat0 + 1 + 1e-9 and south > lat0 + _EDGE_DEG)
    if not ok:
        raise InputError(
            f"{tile.product.name} tile {tile.path} has {tile.res_lon_deg / ARCSEC:g}\" x "
            f"{tile.res_lat_deg / ARCSEC:g}\" cells from lon {west:.6f} lat {north:.6f}: its "
            f"product puts {dx_as:g}\" x {dy_as:g}\" cells from its degree's north-west corner "
            f"({lon0}, {lat0 + 1}) inside the degree; give the tile as distributed")


def _masks_beside(path: Path) -> tuple[tuple[str, Path], ...]:
    """The Copernicus AUXFILES masks of a tile found beside it (same folder, ``AUXFILES/``
    beside it or beside its ``DEM/`` folder)."""
    stem = path.stem[:-4] if path.stem.upper().endswith("_DEM") else path.stem
    folders = (path.parent, path.parent / "AUXFILES", path.parent.parent / "AUXFILES")
    found = []
    for kind in MASKS:
        for folder in folders:
            hit = next((p for p in (folder / f"{stem}_{kind}.tif", folder / f"{stem}_{kind}.TIF")
                        if p.is_file()), None)
            if hit is not None:
                found.append((kind, hit))
                break
    return tuple(found)


def _degrees_extent(need: list[tuple[int, int]], product: Product
                    ) -> tuple[float, float, float, float]:
    """The nodes the degrees ``need`` hold: both edges (SRTM), or not the south and east ones
    (Copernicus: those are the neighbours' first nodes)."""
    lons = [k[0] for k in need]
    lats = [k[1] for k in need]
    edge = 0.0 if product.shared_edges else _EDGE_DEG
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
            tile = _tile_of(r, src.path, TAGGED, None, "DEM")
    _must_overlap(tile, bbox)
    phase = (0.0, 0.0) if found else (tile.extent[0], tile.extent[3])  # named: whole multiples
    return TileSet(src, product, (tile,), tile.extent, phase)


def _tagged_set(src: DemSource, bbox: BBox) -> TileSet:
    """The folder's lon/lat GeoTIFFs overlapping the box (a folder of no named product)."""
    tiles = []
    for p in sorted(src.path.iterdir()):
        if p.suffix.lower() in (".tif", ".tiff") and p.is_file():
            with open_raster(p, "DEM", "give GeoTIFFs in EPSG:4326") as r:
                tile = _tile_of(r, p, TAGGED, None, "DEM")
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
