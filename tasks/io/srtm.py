"""SRTM tiles as files: their names, sizes and void value, and the check of one tile (finding
the tiles of any product covering a box and their mosaic: :mod:`tasks.io.dem_tiles`).

Tiles are 1x1 degree, named after their south-west corner (``N44E005.hgt``,
``n44_e005_1arc_v3.tif``, ``N44E005.SRTMGL1.hgt``...), either raw .hgt
(1201x1201 for 3", 3601x3601 for 1", big-endian int16) or GeoTIFF. Heights are
orthometric (EGM96) metres; -32768 marks voids. Grid nodes sit on whole
multiples of the spacing (pixel-is-point), which GDAL reports as a corner
origin half a pixel to the north-west of the tile corner.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from core.errors import InputError
from tasks.io.rasters import open_raster

SRTM_VOID = -32768
HGT_SIZES = {1201 * 1201 * 2: 1201, 3601 * 3601 * 2: 3601}
_TILE_RE = re.compile(r"^([ns])(\d{1,2})_?([ew])(\d{1,3})", re.IGNORECASE)


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

