"""Evaluate a DEM against lidar (step 6): the DEM interpolated at every lidar point, per class.

The lidar (LAS/LAZ) streams through laspy's chunk iterator; for each chunk the points are
transformed (pyproj) from their CRS to the DEM's, the DEM windows they fall in are read
(rasterio windows, bounded in size) and interpolated bilinearly at the points (the lidar is
never interpolated), heights are brought to metres and to the DEM's vertical datum, and the
differences ``dz = DEM - lidar`` are accumulated per class by :mod:`core.evaluation`. Memory
stays flat whatever the file size.

Units and datums, read from the files (``auto``) unless given:

- lidar x, y: the units of the file's CRS (international or US survey feet, metres,
  degrees), handled by pyproj;
- lidar z: the unit of the vertical part of a compound CRS, else of a 3-D CRS's height axis,
  else the GeoTIFF VerticalUnitsGeoKey, else the horizontal unit of a projected CRS (LAS
  practice: Autzen is feet for x, y and z), else metres;
- lidar vertical datum: EGM96 when the compound CRS (or VerticalCSTypeGeoKey) is EGM96
  height, ellipsoidal for a 3-D CRS; with no vertical CRS, WGS84 ellipsoidal is *assumed*
  and said so in the report. Any other vertical datum (NAVD88, EGM2008...) is refused:
  gcpfree converts only EGM96 (``h = H + N``);
- DEM: the tag ``vertical_datum`` (``"WGS84 ellipsoid..."`` as simulate and prepare-reference
  write it; ``"EGM96..."``), else a compound CRS, else :func:`tasks.dem_io.resolve_vertical`
  (``.hgt`` and SRTM-named files EGM96, anything else ellipsoidal); heights in the unit of
  the vertical CRS, the band unit or the ``units`` tag, metres by default.

Differences are taken in the DEM's datum; the geoid is read only when the two datums differ.
"""

from __future__ import annotations

import contextlib
import logging
import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import laspy
import numpy as np
import pyproj
import rasterio
from prefect import task
from pyproj.exceptions import CRSError
from rasterio.enums import MaskFlags
from rasterio.errors import RasterioIOError
from rasterio.windows import Window

from core.dem import sample_bilinear
from core.errors import CoverageError, InputError, InsufficientDataError
from core.evaluation import (
    ClassedDz,
    CrsInfo,
    DemInfo,
    DzAccumulator,
    EvaluationReport,
    GcpCheck,
    HeightFrame,
    LandcoverInfo,
    LidarInfo,
    MaskSummary,
    PointCounts,
    StatsConfig,
    affine_nodes,
    code_counts,
    height_difference_m,
    inside_grid,
    sample_nearest,
    select_points,
    window_groups,
)
from core.jsonio import parse_json
from core.points import GeoPoint
from tasks.dem_io import resolve_vertical
from tasks.geoid import load_geoid
from tasks.raster_io import atomic_write_text

VERTICALS = ("auto", "ellipsoidal", "egm96")
Z_UNITS: dict[str, float] = {"m": 1.0, "ft": 0.3048, "us-ft": 1200.0 / 3937.0}
UNIT_NAMES = {  # unit strings met in rasters and CRSs -> Z_UNITS key
    "m": "m", "metre": "m", "meter": "m", "metres": "m", "meters": "m",
    "ft": "ft", "foot": "ft", "feet": "ft", "international foot": "ft",
    "us-ft": "us-ft", "ftus": "us-ft", "us survey foot": "us-ft", "us_survey_foot": "us-ft",
    "foot_us": "us-ft", "us foot": "us-ft", "survey foot": "us-ft",
}
EPSG_UNITS = {9001: "m", 9002: "ft", 9003: "us-ft"}  # GeoTIFF VerticalUnitsGeoKey values
ASPRS_LABELS = {
    0: "never classified", 1: "unclassified", 2: "ground", 3: "low vegetation",
    4: "medium vegetation", 5: "high vegetation", 6: "building", 7: "low point (noise)",
    8: "model key-point", 9: "water", 10: "rail", 11: "road surface", 12: "overlap",
    13: "wire guard", 14: "wire conductor", 15: "transmission tower", 16: "wire connector",
    17: "bridge deck", 18: "high noise",
}
#: DEM windows are read at most this many cells on a side (8 MB of float64)
WINDOW_CELLS = 1024
NO_LANDCOVER = "no_landcover"  # points off the land-cover raster or on its nodata
_NO_CODE = -1


# ---------------------------------------------------------------------------- options


@dataclass(frozen=True)
class EvaluationOptions:
    """What ``gcpfree evaluate`` is asked (see its ``--help``).

    ``landcover_names``: JSON (``{"1": "bare_soil"}``) or ``CODE=NAME`` pairs separated by
    commas; ``classes``: LAS codes to evaluate (default: all but the noise classes 7, 18);
    ``lidar_crs``: overrides the file's CRS (any pyproj input, e.g. ``EPSG:2992``);
    ``lidar_z_unit``: ``auto`` or one of ``m``, ``ft``, ``us-ft``.
    """

    dem: Path
    lidar: Path
    out: Path | None = None
    landcover: Path | None = None
    landcover_names: str | None = None
    lidar_vertical: str = "auto"
    dem_vertical: str = "auto"
    lidar_crs: str | None = None
    lidar_z_unit: str = "auto"
    classes: tuple[int, ...] | None = None
    mask: Path | None = None
    gcps: Path | None = None
    chunk_points: int = 1_000_000
    stats: StatsConfig = field(default_factory=StatsConfig)

    def __post_init__(self) -> None:
        for name in ("lidar_vertical", "dem_vertical"):
            if getattr(self, name) not in VERTICALS:
                raise InputError(f"{name.replace('_', '-')} {getattr(self, name)!r} unknown; "
                                 f"use one of {VERTICALS}")
        if self.lidar_z_unit not in ("auto", *Z_UNITS):
            raise InputError(f"lidar z unit {self.lidar_z_unit!r} unknown; use auto, "
                             f"{', '.join(Z_UNITS)}")
        if self.classes is not None and (not self.classes or
                                         not all(0 <= c <= 255 for c in self.classes)):
            raise InputError(f"classes {self.classes} must be LAS codes 0..255, e.g. 2,5,6")
        if self.chunk_points < 1000:
            raise InputError(f"chunk of {self.chunk_points} points is too small; use >= 1000")
        if self.landcover_names is not None and self.landcover is None:
            raise InputError("--landcover-names needs --landcover (a land-cover raster)")


# ---------------------------------------------------------------------------- CRS and units


def _unit_key(name: str | None, what: str) -> str | None:
    """Z_UNITS key of a unit string; None when empty; InputError when unknown."""
    if name is None or not str(name).strip():
        return None
    key = UNIT_NAMES.get(str(name).strip().lower().replace("_", " ").replace("  ", " "))
    key = key or UNIT_NAMES.get(str(name).strip().lower())
    if key is None:
        raise InputError(f"{what}: unit {name!r} not understood; convert the heights to metres "
                         "or feet, or give the unit explicitly")
    return key


def _vertical_datum(vcrs: pyproj.CRS) -> str | None:
    """``egm96`` for EGM96 gravity-related heights, ``ellipsoidal`` for ellipsoidal heights,
    None for any other vertical datum."""
    if vcrs.is_geographic or vcrs.is_projected:  # a 3-D CRS: its height is ellipsoidal
        return "ellipsoidal"
    datum = vcrs.datum.name if vcrs.datum else ""
    if "egm96" in datum.lower().replace(" ", "") or vcrs.to_epsg() == 5773:
        return "egm96"
    return None


@dataclass(frozen=True, eq=False)
class _Vertical:
    """The vertical part of a CRS: datum (None: not convertible), unit, where it came from."""

    datum: str | None
    datum_name: str
    z_factor_m: float
    z_unit: str


def _split_crs(crs: pyproj.CRS) -> tuple[pyproj.CRS, _Vertical | None]:
    """The 2-D horizontal CRS and the vertical part (None when the CRS has none)."""
    if crs.is_compound:
        horiz, vert = crs.sub_crs_list[0], crs.sub_crs_list[-1]
        ax = vert.axis_info[0]
        return horiz, _Vertical(_vertical_datum(vert), vert.name, ax.unit_conversion_factor,
                                ax.unit_name)
    if crs.is_vertical or crs.is_geocentric:
        raise InputError(f"CRS {crs.name!r} has no horizontal part; give a projected or "
                         "geographic CRS")
    if len(crs.axis_info) == 3:
        ax = crs.axis_info[2]
        return crs.to_2d(), _Vertical("ellipsoidal", "ellipsoidal height",
                                      ax.unit_conversion_factor, ax.unit_name)
    return crs, None


def _geokeys(header: laspy.LasHeader) -> dict[int, int]:
    """Short GeoTIFF keys of the file (the ones stored inline)."""
    out: dict[int, int] = {}
    for vlr in header.vlrs:
        if isinstance(vlr, laspy.vlrs.known.GeoKeyDirectoryVlr):
            out.update({k.id: k.value_offset for k in vlr.geo_keys if k.tiff_tag_location == 0})
    return out


def crs_info(crs: pyproj.CRS) -> CrsInfo:
    """How the report names a CRS: its name, authority code (``EPSG:32631+5773`` for a
    compound of two EPSG CRSs) and WKT."""
    auth = crs.to_authority(min_confidence=90)
    if auth is None and crs.is_compound:
        parts = [s.to_authority(min_confidence=90) for s in crs.sub_crs_list]
        if all(parts):
            auth = (parts[0][0], "+".join(p[1] for p in parts))  # type: ignore[index]
    return CrsInfo(crs.name, ":".join(auth) if auth else None, crs.to_wkt())


def _unsupported_datum(what: str, name: str, option: str) -> InputError:
    return InputError(f"{what} heights are {name!r}, a vertical datum gcpfree cannot convert "
                      f"(EGM96 and WGS84 ellipsoidal only); convert them first, or declare "
                      f"them with {option} egm96|ellipsoidal")


# ---------------------------------------------------------------------------- sources


@dataclass(frozen=True, eq=False)
class LidarSource:
    """A lidar file ready to stream: its horizontal CRS and height frame."""

    info: LidarInfo
    horizontal: pyproj.CRS
    frame: HeightFrame


@dataclass(frozen=True, eq=False)
class RasterSource:
    """A north-up or rotated raster (DEM or land cover) and its horizontal CRS."""

    path: Path
    horizontal: pyproj.CRS
    transform: tuple[float, ...]
    shape: tuple[int, int]


def _exists(path: Path, what: str, hint: str) -> Path:
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{what} {path} does not exist; {hint}")
    return path


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
    """Read a LAS/LAZ header: CRS, units, vertical datum (module docstring), point count."""
    path = _exists(path, "lidar file", "give a LAS or LAZ file")
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
    horizontal, vert = _split_crs(full)
    keys = _geokeys(header) if crs_source == "file" else {}
    if vert is None and keys.get(4096, 0) not in (0, 32767):  # VerticalCSTypeGeoKey
        with contextlib.suppress(CRSError):
            vcrs = pyproj.CRS.from_epsg(keys[4096])
            ax = vcrs.axis_info[0]
            factor, unit = ax.unit_conversion_factor, ax.unit_name
            if keys.get(4099) in EPSG_UNITS:  # VerticalUnitsGeoKey says the unit
                unit = EPSG_UNITS[keys[4099]]
                factor = Z_UNITS[unit]
            vert = _Vertical(_vertical_datum(vcrs), vcrs.name, factor, unit)
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
            raise _unsupported_datum(f"lidar file {path}", vert.datum_name, "--lidar-vertical")
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


def _open_raster(path: Path, what: str) -> rasterio.io.DatasetReader:
    try:
        return rasterio.open(path)
    except RasterioIOError as exc:
        raise InputError(f"cannot read {what} {path}: {exc}; give a GeoTIFF") from exc


def _raster_source(src: rasterio.io.DatasetReader, path: Path,
                   what: str) -> tuple[RasterSource, pyproj.CRS]:
    if src.crs is None:
        raise InputError(f"{what} {path} has no CRS; georeference it (e.g. gdal_edit.py "
                         "-a_srs EPSG:...)")
    full = pyproj.CRS.from_wkt(src.crs.to_wkt())
    horizontal, _ = _split_crs(full)
    return RasterSource(path, horizontal, tuple(src.transform)[:6], (src.height, src.width)), full


def inspect_dem(path: Path, vertical: str = "auto") -> tuple[RasterSource, DemInfo, HeightFrame]:
    """Read a DEM's georeferencing, vertical datum and height unit (module docstring)."""
    path = _exists(path, "DEM", "give the DSM as a GeoTIFF")
    with _open_raster(path, "DEM") as src:
        raster, full = _raster_source(src, path, "DEM")
        tags = {k.lower(): v for k, v in src.tags().items()}
        band_unit = src.units[0] if src.units else None
        bounds = tuple(src.bounds)
        width, height = src.width, src.height
    _, vert = _split_crs(full)
    if vertical != "auto":
        datum, v_src = vertical, "given"
    elif "vertical_datum" in tags:
        text = tags["vertical_datum"]
        v_src = f"tag vertical_datum={text!r}"
        if "ellipsoid" in text.lower():
            datum = "ellipsoidal"
        elif "egm96" in text.lower().replace(" ", ""):
            datum = "egm96"
        else:
            raise _unsupported_datum(f"DEM {path}", text, "--dem-vertical")
    elif vert is not None:
        if vert.datum is None:
            raise _unsupported_datum(f"DEM {path}", vert.datum_name, "--dem-vertical")
        datum, v_src = vert.datum, f"CRS: {vert.datum_name}"
    else:
        datum = resolve_vertical(path, "auto")
        v_src = ("SRTM file name" if datum == "egm96" else
                 "assumed: no vertical_datum tag or vertical CRS")
    if vert is not None:
        z_factor, z_name, z_src = vert.z_factor_m, vert.z_unit, "vertical CRS"
    else:
        key = _unit_key(band_unit, f"DEM {path} band") or _unit_key(tags.get("units"),
                                                                   f"DEM {path} tag units")
        z_src = "band unit or units tag" if key else "assumed"
        key = key or "m"
        z_factor, z_name = Z_UNITS[key], key
    info = DemInfo(path=str(path), crs=crs_info(full), vertical=datum, vertical_source=v_src,
                   z_unit=z_name, z_factor_m=z_factor, z_unit_source=z_src, width=width,
                   height=height, transform=raster.transform,
                   bounds=bounds)  # type: ignore[arg-type]
    return raster, info, HeightFrame(datum, z_factor)


def parse_landcover_names(spec: str) -> dict[int, str]:
    """``{"1": "bare_soil"}`` (JSON, either way round) or ``1=bare_soil,2=forest`` -> codes."""
    text = spec.strip()
    if text.startswith("{"):
        pairs = [(str(k), str(v)) for k, v in parse_json(text, "--landcover-names").items()]
    else:
        pairs = []
        for item in filter(None, (s.strip() for s in text.split(","))):
            if "=" not in item:
                raise InputError(f"--landcover-names item {item!r} is not CODE=NAME; write e.g. "
                                 "1=bare_soil,2=forest")
            k, v = item.split("=", 1)
            pairs.append((k.strip(), v.strip()))
    names: dict[int, str] = {}
    for k, v in pairs:
        code, name = (k, v) if k.lstrip("-").isdigit() else (v, k)
        if not code.lstrip("-").isdigit() or not name:
            raise InputError(f"--landcover-names pair {k!r}: {v!r} needs an integer code and a "
                             "name")
        names[int(code)] = name
    if len(set(names.values())) != len(names) or NO_LANDCOVER in names.values():
        raise InputError(f"--landcover-names must give distinct names (and not "
                         f"{NO_LANDCOVER!r}), got {names}")
    return names


def inspect_landcover(path: Path, names: str | None) -> tuple[RasterSource, LandcoverInfo]:
    """The land-cover raster; names from ``names`` or from its tags (``NAME=code``)."""
    path = _exists(path, "land-cover raster", "give a GeoTIFF of class codes")
    with _open_raster(path, "land-cover raster") as src:
        raster, full = _raster_source(src, path, "land-cover raster")
        tags = src.tags()
        nodata = None if src.nodata is None or not math.isfinite(src.nodata) else int(src.nodata)
        if np.dtype(src.dtypes[0]).kind not in "iu":
            raise InputError(f"land-cover raster {path} holds {src.dtypes[0]} values; give "
                             "integer class codes")
    if names is not None:
        codes, source = parse_landcover_names(names), "--landcover-names"
    else:
        codes = {int(v): k.lower() for k, v in tags.items() if v.strip().isdigit()
                 and k.lower() not in {"seed", "version"}}
        source = "raster tags NAME=code" if codes else "codes (no names in the raster tags)"
    info = LandcoverInfo(str(path), crs_info(full), tuple(sorted(codes.items())), source,
                         nodata)
    return raster, info


def read_gcps(path: Path) -> tuple[GeoPoint, ...]:
    """Ground points with ellipsoidal heights: a JSON list of ``[lon, lat, h]`` or of
    ``{"lon_deg", "lat_deg", "h_m"}`` objects, or ``{"points": [...]}`` (checkpoints.json)."""
    path = _exists(path, "GCP file", "give a JSON list of [lon_deg, lat_deg, h_m]")
    doc = parse_json(path.read_text(), str(path))
    items = doc.get("points") if isinstance(doc, dict) else doc
    if not isinstance(items, list) or not items:
        raise InputError(f"GCP file {path} holds no list of points; give [[lon, lat, h], ...]")
    out = []
    for p in items:
        if isinstance(p, dict):
            try:
                p = [p["lon_deg"], p["lat_deg"], p["h_m"]]
            except KeyError as exc:
                raise InputError(f"GCP record {p!r:.80} in {path} lacks {exc}") from exc
        out.append(GeoPoint.from_list(p))
    return tuple(out)


# ---------------------------------------------------------------------------- plan


@dataclass(frozen=True, eq=False)
class EvaluationPlan:
    """Everything checked before the points stream."""

    options: EvaluationOptions
    lidar: LidarSource
    dem: RasterSource
    dem_info: DemInfo
    dem_frame: HeightFrame
    landcover: RasterSource | None
    landcover_info: LandcoverInfo | None
    gcps: tuple[GeoPoint, ...] | None
    transformation: str = ""


def _transformer(src: pyproj.CRS, dst: pyproj.CRS) -> pyproj.Transformer:
    return pyproj.Transformer.from_crs(src, dst, always_xy=True)


def _operation(tr: pyproj.Transformer, x: float, y: float) -> str:
    """The coordinate operation PROJ uses at (x, y) (its choice may depend on the area)."""
    tr.transform(x, y)
    try:
        return tr.get_last_used_operation().description
    except pyproj.exceptions.ProjError:  # no operation: the CRSs are the same
        return "none (same horizontal CRS)"


def plan_evaluation(options: EvaluationOptions) -> EvaluationPlan:
    """Read every header, resolve CRSs, units and datums, and check that the DEM covers the
    lidar. Plain function: the CLI calls it before Prefect starts.

    Raises:
        InputError: a missing or unreadable input, an unknown CRS or vertical datum.
        CoverageError: the DEM and the lidar's extent do not overlap.
    """
    lidar = inspect_lidar(options.lidar, options.lidar_crs, options.lidar_vertical,
                          options.lidar_z_unit)
    dem, dem_info, frame = inspect_dem(options.dem, options.dem_vertical)
    lc = lc_info = None
    if options.landcover is not None:
        lc, lc_info = inspect_landcover(options.landcover, options.landcover_names)
    gcps = read_gcps(options.gcps) if options.gcps is not None else None
    if options.mask is not None:
        with _open_raster(_exists(options.mask, "mask", "give the DSM's mask GeoTIFF"), "mask"):
            pass
    xmin, ymin, xmax, ymax = lidar.info.bounds
    try:
        to_dem = _transformer(lidar.horizontal, dem.horizontal)
        bx = to_dem.transform_bounds(xmin, ymin, xmax, ymax, densify_pts=21)
        operation = _operation(to_dem, 0.5 * (xmin + xmax), 0.5 * (ymin + ymax))
    except pyproj.exceptions.ProjError as exc:
        raise CoverageError(f"the lidar extent cannot be transformed to the DEM's CRS ({exc}); "
                            "check --lidar-crs") from exc
    db = dem_info.bounds
    if not all(map(math.isfinite, bx)) or bx[0] > db[2] or bx[2] < db[0] or bx[1] > db[3] \
            or bx[3] < db[1]:
        raise CoverageError(
            f"DEM {options.dem} (x {db[0]:.1f}..{db[2]:.1f}, y {db[1]:.1f}..{db[3]:.1f} in "
            f"{dem_info.crs.authority or dem_info.crs.name}) does not cover the lidar (x "
            f"{bx[0]:.1f}..{bx[2]:.1f}, y {bx[1]:.1f}..{bx[3]:.1f} there; x {xmin:.1f}..{xmax:.1f}"
            f", y {ymin:.1f}..{ymax:.1f} in the file's {lidar.info.xy_unit}); give a DEM over "
            "the lidar, or check --lidar-crs")
    return EvaluationPlan(options, lidar, dem, dem_info, frame, lc, lc_info, gcps, operation)


# ---------------------------------------------------------------------------- streaming


def _chunks(path: Path, n: int, expected: int) -> Iterator[laspy.ScaleAwarePointRecord]:
    """The file's points, ``n`` at a time; a truncated or corrupt file raises InputError."""
    read = 0
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


def _read_window(src: rasterio.io.DatasetReader, r0: int, r1: int, c0: int, c1: int,
                 float_nan: bool) -> np.ndarray:
    """One window of band 1; ``float_nan``: as float64 with nodata and masked cells NaN."""
    win = Window(c0, r0, c1 - c0, r1 - r0)
    if not float_nan:
        return src.read(1, window=win)
    a = src.read(1, window=win, out_dtype="float64")
    flags = src.mask_flag_enums[0]
    if MaskFlags.nodata in flags:
        a[a == src.nodata] = np.nan
    elif MaskFlags.all_valid not in flags:
        a[src.read_masks(1, window=win) == 0] = np.nan
    return a


def sample_dem(src: rasterio.io.DatasetReader, raster: RasterSource, x: np.ndarray,
               y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Bilinear DEM values at points in the DEM's CRS, reading only the windows they need;
    (values with NaN off the grid or next to voids, inside-the-grid flags)."""
    fi, fj = affine_nodes(raster.transform, x, y)
    z = np.full(fi.shape, np.nan)
    for g in window_groups(fi, fj, raster.shape, WINDOW_CELLS):
        win = _read_window(src, g.row0, g.row1, g.col0, g.col1, float_nan=True)
        z[g.index] = sample_bilinear(win, fi[g.index] - g.row0, fj[g.index] - g.col0)
    return z, inside_grid(fi, fj, raster.shape)


def _sample_classes(src: rasterio.io.DatasetReader, raster: RasterSource, nodata: int | None,
                    x: np.ndarray, y: np.ndarray) -> np.ndarray:
    fi, fj = affine_nodes(raster.transform, x, y)
    codes = np.full(fi.shape, _NO_CODE, dtype=np.int64)
    for g in window_groups(fi, fj, raster.shape, WINDOW_CELLS, nearest=True):
        win = _read_window(src, g.row0, g.row1, g.col0, g.col1, float_nan=False)
        codes[g.index] = sample_nearest(win.astype(np.int64), fi[g.index] - g.row0,
                                        fj[g.index] - g.col0, _NO_CODE)
    if nodata is not None:
        codes[codes == nodata] = _NO_CODE
    return codes


def stream_dz(plan: EvaluationPlan) -> tuple[ClassedDz, PointCounts]:
    """Stream the lidar and accumulate ``dz`` per class (LAS codes, or land-cover codes with
    -1 for points without land cover)."""
    opts, lidar = plan.options, plan.lidar
    acc = ClassedDz(opts.stats)
    to_dem = _transformer(lidar.horizontal, plan.dem.horizontal)
    to_lc = None
    if plan.landcover is not None:
        to_lc = (to_dem if plan.landcover.horizontal == plan.dem.horizontal else
                 _transformer(lidar.horizontal, plan.landcover.horizontal))
    convert = plan.dem_frame.datum != lidar.frame.datum
    to_lonlat = _transformer(lidar.horizontal, pyproj.CRS("EPSG:4326")) if convert else None
    geoid = load_geoid() if convert else None
    n = dict.fromkeys(("read", "withheld", "excluded_class", "outside_dem", "on_void",
                       "evaluated"), 0)
    with contextlib.ExitStack() as stack:
        dem_src = stack.enter_context(rasterio.open(plan.dem.path))
        lc_src = (stack.enter_context(rasterio.open(plan.landcover.path))
                  if plan.landcover is not None else None)
        for pts in _chunks(lidar.info.path, opts.chunk_points, lidar.info.point_count):
            cls = np.asarray(pts.classification)
            withheld = np.asarray(pts.withheld).astype(bool)
            keep = select_points(cls, withheld, opts.classes)
            n["read"] += cls.size
            n["withheld"] += int(withheld.sum())
            n["excluded_class"] += int((~keep & ~withheld).sum())
            x, y = np.asarray(pts.x)[keep], np.asarray(pts.y)[keep]
            z, cls = np.asarray(pts.z)[keep], cls[keep]
            xd, yd = to_dem.transform(x, y)
            dem_z, inside = sample_dem(dem_src, plan.dem, xd, yd)
            ok = np.isfinite(dem_z)
            n["outside_dem"] += int((~inside).sum())
            n["on_void"] += int((inside & ~ok).sum())
            n["evaluated"] += int(ok.sum())
            if not ok.any():
                continue
            if lc_src is not None and to_lc is not None:
                xl, yl = (xd[ok], yd[ok]) if to_lc is to_dem else to_lc.transform(x[ok], y[ok])
                codes = _sample_classes(lc_src, plan.landcover, plan.landcover_info.nodata,
                                        xl, yl)
            else:
                codes = cls[ok]
            lon = lat = None
            if to_lonlat is not None:
                lon, lat = to_lonlat.transform(x[ok], y[ok])
            acc.add(height_difference_m(dem_z[ok], plan.dem_frame, z[ok], lidar.frame, lon,
                                        lat, geoid), codes)
    return acc, PointCounts(in_file=lidar.info.point_count, **n)


def summarize_mask(path: Path) -> MaskSummary:
    """Count the mask's codes block by block (0 valid, 1 mismatch, 2 occluded/outside)."""
    totals = {0: 0, 1: 0, 2: 0}
    cells = 0
    with _open_raster(Path(path), "mask") as src:
        for _, win in src.block_windows(1):
            block = src.read(1, window=win)
            cells += block.size
            for c, k in code_counts(block, (0, 1, 2)).items():
                totals[c] += k
    pct = 100.0 / max(cells, 1)
    return MaskSummary(str(path), totals[0], totals[1], totals[2], cells - sum(totals.values()),
                       totals[1] * pct, totals[2] * pct)


def check_gcps(plan: EvaluationPlan, path: Path, points: tuple[GeoPoint, ...]) -> GcpCheck:
    """The DEM at the ground points (ellipsoidal heights): ``dz = DEM - h`` statistics."""
    lon = np.array([p.lon_deg for p in points])
    lat = np.array([p.lat_deg for p in points])
    h = np.array([p.h_m for p in points])
    x, y = _transformer(pyproj.CRS("EPSG:4326"), plan.dem.horizontal).transform(lon, lat)
    with rasterio.open(plan.dem.path) as src:
        dem_z, _ = sample_dem(src, plan.dem, np.asarray(x), np.asarray(y))
    ok = np.isfinite(dem_z)
    convert = plan.dem_frame.datum != "ellipsoidal"
    acc = DzAccumulator(plan.options.stats)
    acc.add(height_difference_m(dem_z[ok], plan.dem_frame, h[ok], HeightFrame("ellipsoidal"),
                                lon[ok], lat[ok], load_geoid() if convert else None))
    return GcpCheck(str(path), len(points), int((~ok).sum()), acc.stats())


def evaluate_plan(plan: EvaluationPlan) -> EvaluationReport:
    """Stream the lidar and build the report (no Prefect: :func:`evaluate_lidar` wraps it)."""
    acc, counts = stream_dz(plan)
    opts = plan.options
    if counts.evaluated == 0:
        kept = counts.read - counts.withheld - counts.excluded_class
        if counts.on_void == 0:
            d = plan.dem_info
            raise CoverageError(
                f"none of the {kept} lidar points selected lies on DEM {opts.dem} (x "
                f"{d.bounds[0]:.1f}..{d.bounds[2]:.1f}, y {d.bounds[1]:.1f}..{d.bounds[3]:.1f}"
                f"); give a DEM over the lidar, or check --lidar-crs and --classes")
        raise InsufficientDataError(f"all {counts.on_void} lidar points on DEM {opts.dem} fall "
                                    "on voids; give a DEM with heights over the lidar")
    stats = acc.class_stats()
    if plan.landcover_info is not None:
        names = dict(plan.landcover_info.names)
        classes = {(NO_LANDCOVER if c == _NO_CODE else names.get(c, str(c))): s
                   for c, s in stats.items()}
        labels = {k: "" for k in classes}
    else:
        classes = {str(c): s for c, s in stats.items()}
        labels = {str(c): ASPRS_LABELS.get(c, "") for c in stats}
    return EvaluationReport(
        dem=plan.dem_info, lidar=plan.lidar.info, landcover=plan.landcover_info,
        classes_from="landcover" if plan.landcover_info else "las",
        class_filter=opts.classes, heights_compared=plan.dem_frame.datum,
        transformation=plan.transformation, points=counts,
        classes=classes, class_labels=labels, all=acc.overall(), stats_config=opts.stats,
        mask=summarize_mask(opts.mask) if opts.mask is not None else None,
        gcps=check_gcps(plan, opts.gcps, plan.gcps) if opts.gcps and plan.gcps else None,
    )


@task(name="evaluate-dem-against-lidar")
def evaluate_lidar(options: EvaluationOptions) -> EvaluationReport:
    """Check the inputs, stream the lidar, return the report."""
    return evaluate_plan(plan_evaluation(options))


@task(name="write-evaluation", retries=1)
def write_evaluation(report: EvaluationReport, out: Path) -> Path:
    """Write eval.json atomically."""
    try:
        return atomic_write_text(out, report.to_json() + "\n")
    except OSError as exc:
        raise InputError(f"cannot write {out}: {exc.strerror}; choose another --out") from exc
