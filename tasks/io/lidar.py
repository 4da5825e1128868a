"""Lidar files (LAS/LAZ, laspy): the header read and checked, then the points in chunks.

:func:`inspect_lidar` resolves the file's CRS, its horizontal and height units and its vertical
datum (the rules are in :mod:`tasks.evaluation.lidar`) and checks that the file is whole;
:func:`lidar_chunks` streams the points a chunk at a time, so memory stays flat whatever the
file size.

A LAZ is never decompressed in this process: lazrs, laspy's decoder, aborts the process or
panics on some damaged files instead of raising (:mod:`tasks.io.laz_child` says which), so a child
process decodes it and sends the raw point records through a pipe, and a crash of the child
becomes one :class:`~core.errors.InputError` naming the file. A plain LAS is read here (laspy,
NumPy only). Damaged bytes can also decode without any error into wrong points (always in a
plain LAS; in a LAZ when the damage keeps the decoder going): every chunk is checked
(:func:`core.evaluation.evaluation_report.refused_points`: inside the header's box, no reserved class), the
refused points are counted and left out, and a file with more of them than
:data:`core.evaluation.evaluation_report.MAX_REFUSED_SHARE` of its points is refused as corrupt.
"""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import subprocess
import sys
import tempfile
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO, cast

import laspy
import numpy as np
import pyproj
from numpy.typing import NDArray
from pyproj.exceptions import CRSError

from core.errors import GcpFreeError, InputError
from core.evaluation.evaluation_report import (
    MAX_REFUSED_SHARE,
    LidarInfo,
    refused_points,
    too_many_refused,
)
from core.heights import EPSG_UNITS, Z_UNITS, HeightFrame
from tasks.io.laz_child import END, ERROR, WORD
from tasks.io.vertical_crs import (
    VerticalPart,
    crs_info,
    existing_file,
    split_crs,
    unsupported_datum,
    vertical_datum,
)

#: the module the child runs, and the package root put on its path so that ``-m`` finds it
CHILD = "tasks.io.laz_child"
_ROOT = Path(__file__).resolve().parents[2]
_SEL = laspy.DecompressionSelection
#: the LAZ layers the evaluation reads (point formats 6-10 skip the others; 0-5 decode all)
LAYERS = _SEL.XY_RETURNS_CHANNEL | _SEL.Z | _SEL.CLASSIFICATION | _SEL.FLAGS


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
    """A cheap check for a truncated file: the size of a LAS, the chunk table and the first
    point of a LAZ (decoded in the child process); and the header's box, which the points are
    checked against."""
    h = f.header
    if not h.are_points_compressed:
        need = h.offset_to_point_data + h.point_count * h.point_format.size
        if path.stat().st_size < need:
            raise InputError(f"lidar file {path} is truncated: {path.stat().st_size} bytes for "
                             f"{h.point_count} points ({need} needed); give an intact file")
    elif h.point_count:
        for _ in _laz_records(path, h, 0, h.point_count):
            pass
    lo, hi = np.asarray(h.mins, dtype=float), np.asarray(h.maxs, dtype=float)
    if h.point_count and not (np.isfinite(lo).all() and np.isfinite(hi).all()
                              and (lo <= hi).all()):
        box = ", ".join(f"{a} {u:g}..{v:g}" for a, u, v in zip("xyz", lo, hi, strict=True))
        raise InputError(f"lidar file {path} has a corrupt header: its box ({box}) is not "
                         "finite or inverted; give an intact LAS/LAZ file")


# ---------------------------------------------------------------------------- LAZ in a child


def _read_word(stream: BinaryIO) -> int | None:
    b = stream.read(WORD.size)
    return WORD.unpack(b)[0] if len(b) == WORD.size else None


def _crash(proc: subprocess.Popen, err: BinaryIO) -> str:
    """How the child ended, with the first line it wrote on stderr (lazrs's panic or failed
    allocation), e.g. ``killed by SIGABRT: memory allocation of 61347878160 bytes failed``."""
    rc = proc.wait()
    how = f"exit status {rc}"
    if rc < 0:
        try:
            how = f"killed by {signal.Signals(-rc).name}"
        except ValueError:
            how = f"killed by signal {-rc}"
    err.seek(0)
    lines = [ln.strip() for ln in err.read(4096).decode("utf-8", "replace").splitlines()]
    first = next((ln for ln in lines if ln), "")
    return f"{how}: {first[:200]}" if first else how


def _laz_records(path: Path, header: laspy.LasHeader, n: int, expected: int
                 ) -> Iterator[laspy.ScaleAwarePointRecord]:
    """The LAZ file's points, ``n`` at a time, decoded by :mod:`tasks.io.laz_child` in a child
    process (``n = 0``: only check the chunk table and the first point). The decoder's error
    or crash raises InputError; a consumer that stops early kills the child."""
    vlrs = header.vlrs.get("LasZipVlr")
    if not vlrs:
        raise InputError(f"cannot read lidar file {path}: its points are compressed but it has "
                         "no LASzip record; give an intact LAZ file")
    cmd = [sys.executable, "-P", "-m", CHILD, str(path),
           str(header.offset_to_point_data), str(expected), vlrs[0].record_data.hex(), str(n),
           str(int(LAYERS))]
    env = {**os.environ, "RUST_BACKTRACE": "0",
           "PYTHONPATH": os.pathsep.join(filter(None, [str(_ROOT),
                                                       os.environ.get("PYTHONPATH")]))}
    size, dtype, read = header.point_format.size, header.point_format.dtype(), 0
    with tempfile.TemporaryFile() as err, subprocess.Popen(
            cmd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=err, env=env) as proc:
        out = cast(BinaryIO, proc.stdout)
        try:
            word = _read_word(out)
            if word is not None and word != size:
                raise InputError(f"lidar file {path} is corrupt: its LASzip record describes "
                                 f"{word}-byte points where its header says {size}; give an "
                                 "intact LAZ file")
            while word is not None:
                word = _read_word(out)
                if word is None or word == END:
                    break
                if word == ERROR:
                    k = _read_word(out) or 0
                    msg = out.read(min(max(k, 0), 1000)).decode("utf-8", "replace")
                    where = f" after {read} of {expected} points" if n else ""
                    raise InputError(f"lidar file {path} is truncated or corrupt{where} ({msg});"
                                     " give an intact LAZ file")
                if not 0 < word <= min(n, expected - read):
                    raise InputError(f"lidar file {path}: the LAZ decoder sent {word} points "
                                     f"after {read} of {expected}; give an intact LAZ file")
                data = out.read(word * size)
                if len(data) < word * size:
                    break
                read += word
                yield laspy.ScaleAwarePointRecord(np.frombuffer(data, dtype), header.point_format,
                                                  header.scales, header.offsets)
            if word != END:
                where = f"after {read} of {expected} points" if n else \
                    "reading its chunk table and first point"
                raise InputError(f"lidar file {path} is corrupt: the LAZ decoder crashed {where} "
                                 f"({_crash(proc, err)}); give an intact LAZ file")
        finally:
            if proc.poll() is None:
                proc.kill()


# ---------------------------------------------------------------------------- inspect


def inspect_lidar(path: Path, crs: str | None = None, vertical: str = "auto",
                  z_unit: str = "auto") -> LidarSource:
    """Read a LAS/LAZ header: CRS, units, vertical datum (rules in :mod:`tasks.evaluation.lidar`),
    point count."""
    path = existing_file(path, "lidar file", "give a LAS or LAZ file")
    _check_header(path)
    try:
        with _laspy_quiet(), laspy.open(path) as f:
            header = f.header
            _check_complete(f, path)
    except GcpFreeError:
        raise
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


@dataclass(frozen=True, eq=False)
class LidarChunk:
    """The points of one chunk that passed the checks: ``x``, ``y``, ``z`` in the file's units,
    the LAS class and the withheld flag; and how many of the chunk's points were refused,
    outside the header's box or of a reserved class."""

    x: NDArray[np.float64]
    y: NDArray[np.float64]
    z: NDArray[np.float64]
    classification: NDArray[np.uint8]
    withheld: NDArray[np.bool_]
    refused_bounds: int = 0
    refused_class: int = 0

    def __len__(self) -> int:
        return int(self.x.size)


def _checked(pts: laspy.ScaleAwarePointRecord, header: laspy.LasHeader,
             accept: Sequence[int]) -> LidarChunk:
    """The chunk's points checked against the header's box and the reserved classes (but those
    in ``accept``); the refused ones counted and left out."""
    x, y, z = (np.asarray(v, dtype=np.float64) for v in (pts.x, pts.y, pts.z))
    cls = np.asarray(pts.classification)
    withheld = np.asarray(pts.withheld).astype(bool)
    outside, reserved = refused_points(x, y, z, cls, header.mins, header.maxs, header.scales,
                                       accept)
    bad = outside | reserved
    if not bad.any():
        return LidarChunk(x, y, z, cls, withheld)
    ok = ~bad
    return LidarChunk(x[ok], y[ok], z[ok], cls[ok], withheld[ok], int(outside.sum()),
                      int(reserved.sum()))


def _too_many(path: Path, expected: int, outside: int) -> InputError:
    return InputError(
        f"lidar file {path} is corrupt: {outside} points read lie outside its header's box, "
        f"more than {100 * MAX_REFUSED_SHARE:g} % of its {expected} points; give an intact "
        "LAS/LAZ file")


def lidar_chunks(path: Path, n: int, expected: int, accept_classes: Sequence[int] = ()
                 ) -> Iterator[LidarChunk]:
    """The file's points, ``n`` at a time, checked (module docstring): a truncated or corrupt
    file raises InputError, as does one with more than
    :data:`~core.evaluation.evaluation_report.MAX_REFUSED_SHARE` of its ``expected`` points outside its header's
    box (as soon as that many are). Points of a reserved class are left out and counted but do
    not condemn the file: national products use them (AHN's class 26), so only the box, which
    a sound file never breaks, decides. ``accept_classes``: reserved classes the user named
    (``--classes``)."""
    path = Path(path)
    read = outside = reserved = 0
    _check_header(path)
    try:
        with contextlib.ExitStack() as stack:
            stack.enter_context(_laspy_quiet())
            f = stack.enter_context(laspy.open(path))
            h = f.header
            records = (stack.enter_context(contextlib.closing(_laz_records(path, h, n, expected)))
                       if h.are_points_compressed else f.chunk_iterator(n))
            for pts in records:
                read += len(pts)
                chunk = _checked(pts, h, accept_classes)
                outside += chunk.refused_bounds
                reserved += chunk.refused_class
                if too_many_refused(outside, expected):
                    raise _too_many(path, expected, outside)
                yield chunk
    except GcpFreeError:
        raise
    except (laspy.errors.LaspyException, RuntimeError, OSError, ValueError) as exc:
        raise InputError(f"lidar file {path} is truncated or corrupt after {read} of {expected} "
                         f"points ({exc}); give an intact LAS/LAZ file") from exc
    if read != expected:
        raise InputError(f"lidar file {path} holds {read} points where its header says "
                         f"{expected}: it is truncated; give an intact LAS/LAZ file")
