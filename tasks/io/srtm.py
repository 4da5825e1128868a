"""SRTM tiles: find the ones covering a box, check them, mosaic them lazily through a VRT.

Tiles are 1x1 degree, named after their south-west corner (``N44E005.hgt``,
``n44_e005_1arc_v3.tif``, ``N44E005.SRTMGL1.hgt``...), either raw .hgt
(1201x1201 for 3", 3601x3601 for 1", big-endian int16) or GeoTIFF. Heights are
orthometric (EGM96) metres; -32768 marks voids. Grid nodes sit on whole
multiples of the spacing (pixel-is-point), which GDAL reports as a corner
origin half a pixel to the north-west of the tile corner.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path
from xml.sax.saxutils import escape

import numpy as np
import rasterio

from core.errors import CoverageError, InputError
from core.geodesy import BBox
from tasks.io.rasters import open_raster

SRTM_VOID = -32768
HGT_SIZES = {1201 * 1201 * 2: 1201, 3601 * 3601 * 2: 3601}
_TILE_RE = re.compile(r"^([ns])(\d{1,2})_?([ew])(\d{1,3})", re.IGNORECASE)
_SUFFIXES = (".hgt", ".tif", ".tiff")


@dataclass(frozen=True)
class SrtmTile:
    """One SRTM tile on disk: its south-west corner and grid size."""

    path: Path
    lon0: int
    lat0: int
    size: int  # nodes per side: 1201 (3") or 3601 (1")

    @property
    def res_deg(self) -> float:
        return 1.0 / (self.size - 1)


def tile_name(lon0: int, lat0: int) -> str:
    return f"{'N' if lat0 >= 0 else 'S'}{abs(lat0):02d}{'E' if lon0 >= 0 else 'W'}{abs(lon0):03d}"


def parse_tile_name(name: str) -> tuple[int, int] | None:
    """(lon0, lat0) of the south-west corner from a tile file name, or None."""
    m = _TILE_RE.match(name)
    if not m:
        return None
    lat = int(m.group(2)) * (1 if m.group(1).lower() == "n" else -1)
    lon = int(m.group(4)) * (1 if m.group(3).lower() == "e" else -1)
    return lon, lat


def required_tiles(bbox: BBox) -> list[tuple[int, int]]:
    """South-west corners of the 1x1 degree tiles whose grids cover the box."""
    lons = range(math.floor(bbox.lon_min), max(math.ceil(bbox.lon_max), math.floor(bbox.lon_min) + 1))
    lats = range(math.floor(bbox.lat_min), max(math.ceil(bbox.lat_max), math.floor(bbox.lat_min) + 1))
    return [(lo, la) for la in lats for lo in lons]


def check_tile(path: Path, lon0: int, lat0: int) -> SrtmTile:
    """Validate one tile file and return its description; InputError says what is wrong."""
    if path.suffix.lower() == ".hgt":
        nbytes = path.stat().st_size
        if nbytes not in HGT_SIZES:
            raise InputError(
                f"malformed SRTM tile {path}: {nbytes} bytes, but a .hgt must hold 1201x1201 "
                f"(2884802 bytes, 3\") or 3601x3601 (25934402 bytes, 1\") int16 heights; "
                "the file is truncated or not SRTM: download it again"
            )
        return SrtmTile(path, lon0, lat0, HGT_SIZES[nbytes])
    with open_raster(path, "SRTM tile", "replace the file") as src:
        w, h, t = src.width, src.height, src.transform
    if w != h or w not in (1201, 3601) or abs(abs(t.a) * (w - 1) - 1.0) > 1e-6:
        raise InputError(
            f"SRTM tile {path} is {w}x{h} px at {t.a:.8f} deg: expected a 1x1 degree tile "
            "of 1201 or 3601 nodes"
        )
    return SrtmTile(path, lon0, lat0, w)


def find_tiles(srtm_dir: str | Path, bbox: BBox, *, allow_missing: bool = False) -> list[SrtmTile]:
    """The checked tiles of ``srtm_dir`` covering ``bbox``.

    Raises InputError for a missing directory and CoverageError naming the
    missing tiles (unless ``allow_missing``, e.g. for coasts where SRTM has no
    ocean tiles; at least one tile must exist).
    """
    d = Path(srtm_dir)
    if not d.is_dir():
        raise InputError(f"SRTM directory {d} does not exist; give --srtm-dir a folder of tiles")
    found: dict[tuple[int, int], Path] = {}
    for p in sorted(d.iterdir()):
        if p.suffix.lower() in _SUFFIXES and (key := parse_tile_name(p.name)) is not None:
            found.setdefault(key, p)
    need = required_tiles(bbox)
    missing = [k for k in need if k not in found]
    if missing and (not allow_missing or len(missing) == len(need)):
        names = ", ".join(tile_name(*k) for k in missing)
        raise CoverageError(
            f"SRTM in {d} does not cover the box {bbox.lon_min} {bbox.lat_min} {bbox.lon_max} "
            f"{bbox.lat_max}: missing tile(s) {names}; add them (.hgt or GeoTIFF) to the folder"
        )
    return [check_tile(found[k], *k) for k in need if k in found]


@dataclass(frozen=True)
class MosaicGrid:
    """The output lattice: nodes at ``lon0 + j*res``, ``lat0 - i*res`` (north-up)."""

    lon0: float  # centre of the top-left pixel
    lat0: float
    res_deg: float
    width: int
    height: int

    @property
    def transform(self) -> tuple[float, float, float, float, float, float]:
        """Affine coefficients (a, b, c, d, e, f): pixel corner origin, north-up."""
        r = self.res_deg
        return (r, 0.0, self.lon0 - r / 2, 0.0, -r, self.lat0 + r / 2)


def mosaic_grid(tiles: list[SrtmTile], bbox: BBox) -> MosaicGrid:
    """The finest tile lattice restricted to the nodes inside ``bbox``."""
    size = max(t.size for t in tiles)
    n = size - 1  # nodes per degree
    k0 = math.ceil(bbox.lon_min * n - 1e-6)
    k1 = math.floor(bbox.lon_max * n + 1e-6)
    i0 = math.floor(bbox.lat_max * n + 1e-6)  # northernmost node index
    i1 = math.ceil(bbox.lat_min * n - 1e-6)
    if k1 < k0 or i0 < i1:
        raise InputError("the box is smaller than one SRTM cell; enlarge it or add a margin")
    return MosaicGrid(k0 / n, i0 / n, 1.0 / n, k1 - k0 + 1, i0 - i1 + 1)


def build_vrt(tiles: list[SrtmTile], grid: MosaicGrid) -> str:
    """GDAL VRT XML mosaicking ``tiles`` onto ``grid`` (bilinear where a tile is coarser)."""
    a, _, c, _, e, f = grid.transform
    sources = []
    for t in tiles:
        with rasterio.open(t.path) as src:
            st = src.transform
            w, h = src.width, src.height
        x_off = (st.c - c) / a
        y_off = (st.f - f) / e
        x_size = w * st.a / a
        y_size = h * st.e / e
        resamp = "" if t.size == round(1 / grid.res_deg) + 1 else ' resampling="bilinear"'
        sources.append(
            f"""    <ComplexSource{resamp}>
      <SourceFilename relativeToVRT="0">{escape(str(t.path.resolve()))}</SourceFilename>
      <SourceBand>1</SourceBand>
      <SrcRect xOff="0" yOff="0" xSize="{w}" ySize="{h}"/>
      <DstRect xOff="{x_off!r}" yOff="{y_off!r}" xSize="{x_size!r}" ySize="{y_size!r}"/>
      <NODATA>{SRTM_VOID}</NODATA>
    </ComplexSource>"""
        )
    gt = ", ".join(repr(v) for v in (c, a, 0.0, f, 0.0, e))
    return f"""<VRTDataset rasterXSize="{grid.width}" rasterYSize="{grid.height}">
  <SRS dataAxisToSRSAxisMapping="2,1">EPSG:4326</SRS>
  <GeoTransform>{gt}</GeoTransform>
  <Metadata><MDI key="AREA_OR_POINT">Area</MDI></Metadata>
  <VRTRasterBand dataType="Float32" band="1">
    <NoDataValue>{SRTM_VOID}</NoDataValue>
{chr(10).join(sources)}
  </VRTRasterBand>
</VRTDataset>
"""


def covered(lon: np.ndarray, lat: np.ndarray, tiles: list[SrtmTile]) -> np.ndarray:
    """True where (lon, lat) (broadcast) falls inside one of ``tiles``."""
    lon, lat = np.broadcast_arrays(lon, lat)
    m = np.zeros(lon.shape, dtype=bool)
    eps = 1e-9
    for t in tiles:
        m |= (
            (lon >= t.lon0 - eps) & (lon <= t.lon0 + 1 + eps)
            & (lat >= t.lat0 - eps) & (lat <= t.lat0 + 1 + eps)
        )
    return m
