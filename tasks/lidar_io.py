"""Lidar files (LAS/LAZ, laspy): the header read and checked, then the points in chunks.

:func:`inspect_lidar` resolves the file's CRS, its horizontal and height units and its vertical
datum (the rules are in :mod:`tasks.evaluate`) and checks that the file is whole;
:func:`lidar_chunks` streams the points a chunk at a time, so memory stays flat whatever the
file size.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import laspy
import pyproj
from pyproj.exceptions import CRSError

from core.errors import InputError
from core.evaluation import LidarInfo
from core.heights import EPSG_UNITS, Z_UNITS, HeightFrame
from tasks.evaluation_crs import (
    VerticalPart,
    crs_info,
    existing_file,
    split_crs,
    unsupported_datum,
    vertical_datum,
)


@dataclass(frozen=True, eq=False)
class LidarSource:
    """A lidar file ready to stream: its horizontal CRS and height frame."""

    info: LidarInfo
    horizontal: pyproj.CRS
    frame: HeightFrame


def _geokeys(header: laspy.LasHeader) -> dict[int, int]:
    """Short GeoTIFF keys of the file (the ones stored inline)."""
    out: dict[int, int] = {}
    for vlr in header.vlrs:
        if isinstance(vlr, laspy.vlrs.known.GeoKeyDirectoryVlr):
            out.update({k.id: k.value_offset for k in vlr.geo_keys if k.tiff_tag_location == 0})
    return out


@contextlib.contextmanager
def _laspy_quiet() -> Iterator[None]:
    """laspy logs a failed decompression before raising it; we raise it as one InputError, so
    its log line would only repeat the message."""
    log = logging.getLogger("laspy")
    level = log.level
    log.setLevel(logging.CRITICAL)
    try:
        yield
    finally:
        log.setLevel(level)


def _check_header(path: str | Path) -> None:
    """The record counts of the LAS public header against the file's size, before laspy reads
    the header: a damaged count makes laspy loop over billions of empty records (minutes, then
    a MemoryError) instead of failing."""
    path = Path(path)
    size = path.stat().st_size
    with path.open("rb") as f:
        head = f.read(247)
    if len(head) < 227 or head[:4] != b"LASF":
        raise InputError(f"cannot read lidar file {path}: not a LAS/LAZ file (no LASF header "
                         "of 227 bytes); give an intact LAS or LAZ file")
    minor = head[25]
    header_size = int.from_bytes(head[94:96], "little")
    to_points = int.from_bytes(head[96:100], "little")
    n_vlrs = int.from_bytes(head[100:104], "little")
    if not header_size + 54 * n_vlrs <= to_points <= size:
        raise InputError(f"cannot read lidar file {path}: a corrupt header, {n_vlrs} records "
                         f"and point data at byte {to_points} do not fit a header of {header_size} bytes "
                         f"and a file of {size}; give an intact LAS/LAZ file")
    if minor >= 4 and len(head) >= 247:
        first_evlr = int.from_bytes(head[235:243], "little")
        n_evlrs = int.from_bytes(head[243:247], "little")
        if n_evlrs and first_evlr + 60 * n_evlrs > size:
            raise InputError(f"cannot read lidar file {path}: a corrupt header, {n_evlrs} "
                             f"extended records from byte {first_evlr} do not fit a file of {size} "
                             "bytes; give an intact LAS/LAZ file")


def _check_complete(f: laspy.LasReader, path: Path) -> None:
    """A cheap check for a truncated file: the size of a LAS, the chunk table of a LAZ (lazrs
    reads it when decompression starts)."""
    h = f.header
    if not h.are_points_compressed:
        need = h.offset_to_point_data + h.point_count * h.point_format.size
        if path.stat().st_size < need:
            raise InputError(f"lidar file {path} is truncated: {path.stat().st_size} bytes for "
                             f"{h.point_count} points ({need} needed); give an intact file")
    elif h.point_count:
        try:
            f.read_points(1)
        except RuntimeError as exc:  # lazrs.LazrsError
            raise InputError(f"lidar file {path} is truncated or corrupt ({exc}); give an "
                             "intact LAZ file") from exc


def inspect_lidar(path: Path, crs: str | None = None, vertical: str = "auto",
                  z_unit: str = "auto") -> LidarSource:
    """Read a LAS/LAZ header: CRS, units, vertical datum (rules in :mod:`tasks.evaluate`),
    point count."""
    path = existing_file(path, "lidar file", "give a LAS or LAZ file")
    _check_header(path)
    try:
        with _laspy_quiet(), laspy.open(path) as f:
            header = f.header
            _check_complete(f, path)
    except (laspy.errors.LaspyException, OSError, ValueError) as exc:
        raise InputError(f"cannot read lidar file {path}: {exc}; give an intact LAS/LAZ "
                         "file") from exc
    if crs is not None:
        try:
            full = pyproj.CRS.from_user_input(crs)
        except CRSError as exc:
            raise InputError(f"--lidar-crs {crs!r} is not a CRS pyproj knows; give e.g. "
                             "EPSG:32631 or EPSG:32631+5773") from exc
        crs_source = "--lidar-crs"
    else:
        try:
            full = header.parse_crs()
        except (CRSError, laspy.errors.LaspyException, ValueError) as exc:
            raise InputError(f"lidar file {path} has a CRS record pyproj cannot read ({exc}); "
                             "give the CRS with --lidar-crs") from exc
        if full is None:
            raise InputError(f"lidar file {path} has no CRS (no WKT or GeoTIFF keys); give it "
                             "with --lidar-crs (e.g. EPSG:32631+5773 for UTM 31N with EGM96 "
                             "heights)")
        crs_source = "file"
    horizontal, vert = split_crs(full)
    keys = _geokeys(header) if crs_source == "file" else {}
    if vert is None and keys.get(4096, 0) not in (0, 32767):  # VerticalCSTypeGeoKey
        with contextlib.suppress(CRSError):
            vcrs = pyproj.CRS.from_epsg(keys[4096])
            ax = vcrs.axis_info[0]
            factor, unit = ax.unit_conversion_factor, ax.unit_name
            if keys.get(4099) in EPSG_UNITS:  # VerticalUnitsGeoKey says the unit
                unit = EPSG_UNITS[keys[4099]]
                factor = Z_UNITS[unit]
            vert = VerticalPart(vertical_datum(vcrs), vcrs.name, factor, unit)
    hax = horizontal.axis_info[0]
    xy_factor = None if horizontal.is_geographic else hax.unit_conversion_factor
    # z unit
    if z_unit != "auto":
        z_factor, z_name, z_src = Z_UNITS[z_unit], z_unit, "given"
    elif vert is not None:
        z_factor, z_name, z_src = vert.z_factor_m, vert.z_unit, "vertical CRS"
    elif keys.get(4099) in EPSG_UNITS:
        key = EPSG_UNITS[keys[4099]]
        z_factor, z_name, z_src = Z_UNITS[key], key, "VerticalUnitsGeoKey"
    elif xy_factor is not None:
        z_factor, z_name = xy_factor, hax.unit_name
        z_src = "no vertical CRS: the horizontal unit"
    else:
        z_factor, z_name, z_src = 1.0, "metre", "no vertical CRS: metres assumed"
    # vertical datum
    if vertical != "auto":
        datum, v_src = vertical, "given"
    elif vert is not None:
        if vert.datum is None:
            raise unsupported_datum(f"lidar file {path}", vert.datum_name, "--lidar-vertical")
        datum, v_src = vert.datum, f"CRS: {vert.datum_name}"
    else:
        datum, v_src = "ellipsoidal", "assumed: the CRS has no vertical part"
    b = (*header.mins[:2], *header.maxs[:2])
    info = LidarInfo(
        path=str(path), crs=crs_info(full), crs_source=crs_source, xy_unit=hax.unit_name,
        xy_factor_m=xy_factor, z_unit=z_name, z_factor_m=z_factor, z_unit_source=z_src,
        vertical=datum, vertical_source=v_src, point_count=int(header.point_count),
        las_version=str(header.version), point_format=int(header.point_format.id),
        bounds=tuple(float(v) for v in b),  # type: ignore[arg-type]
    )
    return LidarSource(info, horizontal, HeightFrame(datum, z_factor))


def lidar_chunks(path: Path, n: int, expected: int) -> Iterator[laspy.ScaleAwarePointRecord]:
    """The file's points, ``n`` at a time; a truncated or corrupt file raises InputError."""
    read = 0
    _check_header(path)
    try:
        with _laspy_quiet(), laspy.open(path) as f:
            for pts in f.chunk_iterator(n):
                read += len(pts)
                yield pts
    except (laspy.errors.LaspyException, RuntimeError, OSError, ValueError) as exc:
        raise InputError(f"lidar file {path} is truncated or corrupt after {read} of {expected} "
                         f"points ({exc}); give an intact LAS/LAZ file") from exc
    if read != expected:
        raise InputError(f"lidar file {path} holds {read} points where its header says "
                         f"{expected}: it is truncated; give an intact LAS/LAZ file")
