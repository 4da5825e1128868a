"""DEM products as files: which product a file is by its name, the lattice and void value its
tiles have, the masks beside them, and the check of one tile.

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

import re
from dataclasses import dataclass
from pathlib import Path

from core.errors import InputError
from core.geodesy import ARCSEC
from tasks.io.rasters import open_raster
from tasks.io.srtm import SRTM_VOID, check_tile, parse_tile_name

COPERNICUS_VOID = -32767.0
#: a Copernicus tile's AUXFILES masks read here: (file suffix, GDAL data type, "no data" value)
MASKS = {"WBM": ("Byte", 255), "HEM": ("Float32", "nan"), "EDM": ("Byte", 255)}
_COP_RE = re.compile(r"^Copernicus_DSM_(?:COG_)?(10|30)_([NS])(\d{2})_00_([EW])(\d{3})_00"
                     r"(?:_DEM)?\.tiff?$", re.IGNORECASE)
_NASADEM_RE = re.compile(r"^NASADEM_HGT_([ns])(\d{2})([ew])(\d{3})\.(?:hgt|zip|tiff?)$",
                         re.IGNORECASE)
_SRTM_SUFFIXES = (".hgt", ".tif", ".tiff")
#: a node this close inside a degree's open edge belongs to the next tile
EDGE_DEG = 1e-7




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
        tile = tile_of(src, path, product, corner, what)
    if product in (GLO30, GLO90):
        _check_copernicus_lattice(tile, corner)
    return tile


def tile_of(src, path: Path, product: Product, corner: tuple[int, int] | None,
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
          west > lon0 - 1e-9 and east < lon0 + 1 - EDGE_DEG and
          north < lat0 + 1 + 1e-9 and south > lat0 + EDGE_DEG)
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


