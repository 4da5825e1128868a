"""Evaluate a DEM against lidar (step 6): the DEM interpolated at every lidar point, per class.

The lidar (LAS/LAZ) streams a chunk at a time (:mod:`tasks.io.lidar`: a LAZ is decoded in a
child process, so a decoder crash on a damaged file is one error; points outside the header's
box or of a reserved class are refused, counted and left out, and the file refused when they
are more than 1 in 10,000). For each chunk the points are transformed (pyproj) from their CRS
to the DEM's, the DEM windows they fall in are read (rasterio windows, bounded in size) and
interpolated bilinearly at the points (:mod:`tasks.io.rasters_at_points`; the lidar is never
interpolated), heights are brought to metres and to the DEM's vertical datum
(:mod:`core.heights`), and the differences ``dz = DEM - lidar`` are accumulated per class by
:mod:`core.evaluation.evaluation`. Memory stays flat whatever the file size.

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
- DEM: the one rule every command follows (:func:`tasks.io.dem.dem_datum`: ``--dem-vertical``,
  else the tag ``vertical_datum`` as gcpfree writes it, else the CRS's vertical part, else an
  SRTM file name for EGM96, else refused); heights in the unit of the vertical CRS, the band
  unit or the ``units`` tag, metres by default.

Differences are taken in the DEM's datum; the geoid is read only when the two datums differ.
"""

from __future__ import annotations

import contextlib
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pyproj
import rasterio
from prefect import task

from core.choices import check_vertical_choices
from core.errors import CoverageError, InputError, InsufficientDataError
from core.evaluation.evaluation import ClassedDz, StatsConfig
from core.evaluation.evaluation_report import (
    DemInfo,
    EvaluationReport,
    GcpCheck,
    LandcoverInfo,
    PointCounts,
    PointTally,
    class_tables,
    gcp_check,
    select_points,
)
from core.heights import Z_UNITS, HeightFrame, height_difference_m
from core.jsonio import parse_json, to_json
from core.points import GeoPoint
from tasks.io.geoid import load_geoid
from tasks.io.lidar import LidarSource, inspect_lidar, lidar_chunks
from tasks.io.products import EVALUATION
from tasks.io.rasters import atomic_write_text
from tasks.io.rasters_at_points import (
    RasterSource,
    inspect_dem,
    inspect_landcover,
    open_raster,
    sample_classes,
    sample_dem,
    summarize_mask,
)
from tasks.io.vertical_crs import existing_file

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
        check_vertical_choices(self, "lidar_vertical", "dem_vertical", flag="")
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


# ---------------------------------------------------------------------------- plan


def read_gcps(path: Path) -> tuple[GeoPoint, ...]:
    """Ground points with ellipsoidal heights: a JSON list of ``[lon, lat, h]`` or of
    ``{"lon_deg", "lat_deg", "h_m"}`` objects, or ``{"points": [...]}`` (checkpoints.json)."""
    path = existing_file(path, "GCP file", "give a JSON list of [lon_deg, lat_deg, h_m]")
    doc = parse_json(path.read_text(encoding="utf-8", errors="replace"), str(path))
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
        try:
            g = GeoPoint.from_list(p)
        except InputError as exc:
            raise InputError(f"GCP file {path}: {exc}") from None
        if not (np.isfinite([g.lon_deg, g.lat_deg, g.h_m]).all() and abs(g.lat_deg) <= 90.0):
            raise InputError(f"GCP file {path}: {g.to_list()} is not a point on Earth; give "
                             "[lon_deg, lat_deg, h_m] with finite numbers")
        out.append(g)
    return tuple(out)


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
        with open_raster(existing_file(options.mask, "mask", "give the DSM's mask GeoTIFF"),
                         "mask"):
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
    tally = PointTally()
    with contextlib.ExitStack() as stack:
        dem_src = stack.enter_context(rasterio.open(plan.dem.path))
        lc_src = (stack.enter_context(rasterio.open(plan.landcover.path))
                  if plan.landcover is not None else None)
        for pts in lidar_chunks(lidar.info.path, opts.chunk_points, lidar.info.point_count,
                                opts.classes or ()):
            tally.refuse(pts.refused_bounds, pts.refused_class)
            keep = select_points(pts.classification, pts.withheld, opts.classes)
            x, y, z, cls = pts.x[keep], pts.y[keep], pts.z[keep], pts.classification[keep]
            xd, yd = to_dem.transform(x, y)
            dem_z, inside = sample_dem(dem_src, plan.dem, xd, yd)
            ok = np.isfinite(dem_z)
            tally.add(pts.withheld, keep, inside, ok)
            if not ok.any():
                continue
            if lc_src is not None and to_lc is not None:
                xl, yl = (xd[ok], yd[ok]) if to_lc is to_dem else to_lc.transform(x[ok], y[ok])
                codes = sample_classes(lc_src, plan.landcover, plan.landcover_info.nodata,
                                       xl, yl)
            else:
                codes = cls[ok]
            lon = lat = None
            if to_lonlat is not None:
                lon, lat = to_lonlat.transform(x[ok], y[ok])
            acc.add(height_difference_m(dem_z[ok], plan.dem_frame, z[ok], lidar.frame, lon,
                                        lat, geoid), codes)
    return acc, tally.counts(lidar.info.point_count)


def check_gcps(plan: EvaluationPlan, path: Path, points: tuple[GeoPoint, ...]) -> GcpCheck:
    """The DEM at the ground points (ellipsoidal heights): ``dz = DEM - h`` statistics."""
    lon = np.array([p.lon_deg for p in points])
    lat = np.array([p.lat_deg for p in points])
    x, y = _transformer(pyproj.CRS("EPSG:4326"), plan.dem.horizontal).transform(lon, lat)
    with rasterio.open(plan.dem.path) as src:
        dem_z, _ = sample_dem(src, plan.dem, np.asarray(x), np.asarray(y))
    geoid = load_geoid() if plan.dem_frame.datum != "ellipsoidal" else None
    return gcp_check(str(path), points, dem_z, plan.dem_frame, geoid, plan.options.stats)


def evaluate_plan(plan: EvaluationPlan) -> EvaluationReport:
    """Stream the lidar and build the report (no Prefect: :func:`evaluate_lidar` wraps it)."""
    acc, counts = stream_dz(plan)
    opts = plan.options
    if counts.refused_bounds:  # under MAX_REFUSED_SHARE: lidar_chunks refuses the file beyond
        print(f"lidar file {opts.lidar}: {counts.refused_bounds} of {counts.read} points "
              f"({100 * counts.refused_bounds / max(counts.read, 1):.3f} %) left out, outside "
              "the header's box: the file is damaged", file=sys.stderr, flush=True)
    if counts.refused_class:
        print(f"lidar file {opts.lidar}: {counts.refused_class} points of reserved classes "
              "23..63 left out (name them with --classes to evaluate them)", file=sys.stderr,
              flush=True)
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
    classes, labels = class_tables(acc.class_stats(), plan.landcover_info.names
                                   if plan.landcover_info is not None else None)
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
        return atomic_write_text(out, to_json(EVALUATION.dump(report), indent=1) + "\n")
    except OSError as exc:
        raise InputError(f"cannot write {out}: {exc.strerror}; choose another --out") from exc
