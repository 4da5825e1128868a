"""What ``eval.json`` holds, and the bookkeeping of the points that fills it (step 6, the
evaluation against lidar; the statistics themselves are :mod:`core.evaluation.evaluation`).

- The report's schema: :class:`EvaluationReport` and its parts (the DEM, the lidar file and the
  land cover as read, :class:`PointCounts`, the optional mask and GCP checks), each a frozen
  dataclass; :data:`tasks.io.products.EVALUATION` writes and reads them as eval.json.
- The points: which are evaluated (:func:`select_points`), which a sound file cannot hold
  (:func:`refused_points`: outside the header's box, of a reserved class), where each went
  (:class:`PointTally`), the names of the classes (:func:`class_tables`), the mask raster's
  counts (:func:`mask_summary`) and the DEM at GCPs (:func:`gcp_check`).

No I/O here: ``tasks.evaluation.lidar`` reads the files and calls these functions.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.evaluation.evaluation import DzAccumulator, DzStats, StatsConfig
from core.geoid import GeoidGrid
from core.heights import HeightFrame, height_difference_m
from core.points import GeoPoint

#: ASPRS classes that are not a surface: 7 low point (noise), 18 high noise
NOISE_CLASSES = (7, 18)
#: the report's labels of the ASPRS LAS classes
ASPRS_LABELS = {
    0: "never classified", 1: "unclassified", 2: "ground", 3: "low vegetation",
    4: "medium vegetation", 5: "high vegetation", 6: "building", 7: "low point (noise)",
    8: "model key-point", 9: "water", 10: "rail", 11: "road surface", 12: "overlap",
    13: "wire guard", 14: "wire conductor", 15: "transmission tower", 16: "wire connector",
    17: "bridge deck", 18: "high noise", 19: "overhead structure", 20: "ignored ground",
    21: "snow", 22: "temporal exclusion",
}
#: ASPRS LAS 1.4 R15 defines classes 0..22 and leaves 64..255 to users; 23..63 are reserved,
#: so a point holding one was decoded from damaged data, unless the user names the class
RESERVED_CLASSES = (23, 63)
#: the share of a file's points the checks may refuse before the whole file is refused. A
#: sound file has none: writers take the header's box from the points (:func:`refused_points`
#: allows for their rounding). A damaged LAZ chunk that decodes without error is garbage from
#: the damage to the chunk's end: on 300 damages inside the chunks of 200,000 simulator points
#: (LAS 1.4 LAZ), 279 raised an error and 21 decoded, 984 to 75,693 points wrong each, of which
#: the checks refused 99.3 % (0.06 % to 38 % of the file per damage) and let 0.7 % through,
#: tens of metres wrong, at worst 6.7 times as many as they refused. Refusing beyond 1 in
#: 10,000 keeps those let through below 0.07 % of the points evaluated, which moves the
#: median, NMAD and LE68/LE90 by less than 0.07 percentile points.
MAX_REFUSED_SHARE = 0.0001
NO_LANDCOVER = "no_landcover"  # points off the land-cover raster or on its nodata
NO_CODE = -1  # their class code
REPORT_FORMAT = "gcpfree.evaluation"


# ---------------------------------------------------------------------------- the report


@dataclass(frozen=True)
class CrsInfo:
    """A CRS as the report states it: name, authority code when known, WKT."""

    name: str
    authority: str | None
    wkt: str


@dataclass(frozen=True)
class LidarInfo:
    """The lidar file and how it was read: ``xy_factor_m`` None for degrees."""

    path: str
    crs: CrsInfo
    crs_source: str
    xy_unit: str
    xy_factor_m: float | None
    z_unit: str
    z_factor_m: float
    z_unit_source: str
    vertical: str
    vertical_source: str
    point_count: int
    las_version: str
    point_format: int
    bounds: tuple[float, float, float, float]

@dataclass(frozen=True)
class DemInfo:
    """The DEM and how its heights were read; ``transform`` the GDAL affine (a..f)."""

    path: str
    crs: CrsInfo
    vertical: str
    vertical_source: str
    z_unit: str
    z_factor_m: float
    z_unit_source: str
    width: int
    height: int
    transform: tuple[float, ...]
    bounds: tuple[float, float, float, float]

@dataclass(frozen=True)
class LandcoverInfo:
    """The land-cover raster sampled (nearest) at the points and the names of its codes."""

    path: str
    crs: CrsInfo
    names: tuple[tuple[int, str], ...]
    names_source: str
    nodata: int | None

@dataclass(frozen=True)
class PointCounts:
    """What happened to the points: ``read`` = ``refused + withheld + excluded_class +
    outside_dem + on_void + evaluated``, ``refused`` = ``refused_bounds + refused_class``:
    points outside the header's box or of a reserved class (:func:`refused_points`), decoded
    from damaged data."""

    in_file: int
    read: int
    withheld: int
    excluded_class: int
    outside_dem: int
    on_void: int
    evaluated: int
    refused_bounds: int = 0
    refused_class: int = 0

    @property
    def refused(self) -> int:
        return self.refused_bounds + self.refused_class

    @property
    def refused_pct(self) -> float:
        """The refused points in per cent of those read."""
        return 100.0 * self.refused / max(self.read, 1)


@dataclass(frozen=True)
class MaskSummary:
    """Cells of the DSM's mask raster: 0 valid, 1 mismatch, 2 occluded or outside; other
    values counted apart. Percentages of all cells."""

    path: str
    valid: int
    mismatch: int
    occluded_or_outside: int
    other: int
    mismatched_pct: float
    occluded_pct: float


@dataclass(frozen=True)
class GcpCheck:
    """The DEM at known ground points (ellipsoidal heights): ``dz = DEM - h``."""

    path: str
    points: int
    outside_dem: int
    stats: DzStats

@dataclass(frozen=True)
class EvaluationReport:
    """Everything ``eval.json`` holds (written and read by :data:`tasks.io.products.EVALUATION`,
    which adds the file's format, version, ``dz`` and ``inputs``): the statistics of ``dz = DEM - lidar``
    per class (``classes``: LAS code as a string, or land-cover name) and overall (``all``),
    how the inputs were read, where the points went, and the optional mask and GCP checks."""

    dem: DemInfo
    lidar: LidarInfo
    landcover: LandcoverInfo | None
    classes_from: str
    class_filter: tuple[int, ...] | None
    heights_compared: str
    transformation: str
    points: PointCounts
    classes: Mapping[str, DzStats]
    class_labels: Mapping[str, str]
    all: DzStats
    stats_config: StatsConfig
    mask: MaskSummary | None = None
    gcps: GcpCheck | None = None


# ---------------------------------------------------------------------------- classes and points


def select_points(codes: ArrayLike, withheld: ArrayLike | None = None,
                  keep: Sequence[int] | None = None,
                  drop: Sequence[int] = NOISE_CLASSES) -> NDArray[np.bool_]:
    """Points to evaluate: not withheld, and of a class in ``keep`` when given, else of any
    class but ``drop`` (by default the ASPRS noise classes 7 and 18)."""
    codes = np.asarray(codes)
    ok = np.isin(codes, np.asarray(keep)) if keep is not None else ~np.isin(codes, np.asarray(
        drop, dtype=np.int64))
    if withheld is not None:
        ok &= ~np.asarray(withheld, dtype=bool)
    return ok


def refused_points(x: ArrayLike, y: ArrayLike, z: ArrayLike, codes: ArrayLike,
                   mins: Sequence[float], maxs: Sequence[float], scales: Sequence[float],
                   accept: Sequence[int] = ()) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
    """Points a sound lidar file cannot hold, as two masks: ``outside`` the header's box
    (``mins``/``maxs`` per axis x, y, z; with the slack of one scale step, as writers may take
    the box from unquantised values, plus the float32 rounding of the bound, as some store it;
    a box with NaN holds nothing), and, of the others, ``reserved``: a class in
    :data:`RESERVED_CLASSES` not named in ``accept``."""
    inside = np.ones(np.shape(codes), dtype=bool)
    for v, lo, hi, scale in zip((x, y, z), mins, maxs, scales, strict=True):
        v = np.asarray(v, dtype=np.float64)
        tol = abs(scale) + 2.0**-23 * max(abs(lo), abs(hi))
        inside &= (v >= lo - tol) & (v <= hi + tol)
    codes = np.asarray(codes)
    lo_c, hi_c = RESERVED_CLASSES
    reserved = inside & (codes >= lo_c) & (codes <= hi_c)
    if len(accept):
        reserved &= ~np.isin(codes, np.asarray(accept))
    return ~inside, reserved


def too_many_refused(refused: int, in_file: int) -> bool:
    """More points refused than :data:`MAX_REFUSED_SHARE` of the file's count allows."""
    return refused > MAX_REFUSED_SHARE * in_file


def code_counts(values: ArrayLike, codes: Sequence[int]) -> dict[int, int]:
    """How many of ``values`` equal each of ``codes`` (a mask raster block, say)."""
    v = np.asarray(values).ravel()
    return {int(c): int(np.count_nonzero(v == c)) for c in codes}


# ---------------------------------------------------------------------------- bookkeeping


@dataclass
class PointTally:
    """Where the points of a stream went, chunk by chunk; :meth:`counts` gives the report's
    :class:`PointCounts`."""

    read: int = 0
    withheld: int = 0
    excluded_class: int = 0
    outside_dem: int = 0
    on_void: int = 0
    evaluated: int = 0
    refused_bounds: int = 0
    refused_class: int = 0

    def refuse(self, outside: int, reserved: int) -> None:
        """Points of a chunk read but refused (:func:`refused_points`), before :meth:`add`
        counts the chunk's accepted ones."""
        self.read += outside + reserved
        self.refused_bounds += outside
        self.refused_class += reserved

    def add(self, withheld: ArrayLike, keep: ArrayLike, inside: ArrayLike,
            valid: ArrayLike) -> None:
        """One chunk: ``withheld`` and ``keep`` (:func:`select_points`) flag all its points,
        ``inside`` (on the DEM's grid) and ``valid`` (a DEM value there) the kept ones."""
        withheld = np.asarray(withheld, dtype=bool)
        keep = np.asarray(keep, dtype=bool)
        inside = np.asarray(inside, dtype=bool)
        valid = np.asarray(valid, dtype=bool)
        self.read += withheld.size
        self.withheld += int(withheld.sum())
        self.excluded_class += int((~keep & ~withheld).sum())
        self.outside_dem += int((~inside).sum())
        self.on_void += int((inside & ~valid).sum())
        self.evaluated += int(valid.sum())

    def counts(self, in_file: int) -> PointCounts:
        return PointCounts(in_file, self.read, self.withheld, self.excluded_class,
                           self.outside_dem, self.on_void, self.evaluated, self.refused_bounds,
                           self.refused_class)


def class_tables(stats: Mapping[int, DzStats], landcover_names: Sequence[tuple[int, str]] | None
                 ) -> tuple[dict[str, DzStats], dict[str, str]]:
    """The report's ``classes`` and ``class_labels`` from the statistics per code: with
    ``landcover_names`` (``(code, name)`` pairs) keyed by name (a code without one by its
    number, :data:`NO_CODE` as :data:`NO_LANDCOVER`) with empty labels; otherwise keyed by LAS
    code and labelled with the ASPRS names."""
    if landcover_names is not None:
        names = dict(landcover_names)
        classes = {(NO_LANDCOVER if c == NO_CODE else names.get(c, str(c))): s
                   for c, s in stats.items()}
        return classes, {k: "" for k in classes}
    return {str(c): s for c, s in stats.items()}, {str(c): ASPRS_LABELS.get(c, "") for c in stats}


def mask_summary(path: str, blocks: Iterable[ArrayLike]) -> MaskSummary:
    """Count the codes of a mask raster given block by block (0 valid, 1 mismatch, 2 occluded
    or outside, anything else other)."""
    totals = {0: 0, 1: 0, 2: 0}
    cells = 0
    for block in blocks:
        cells += np.size(block)
        for c, k in code_counts(block, (0, 1, 2)).items():
            totals[c] += k
    pct = 100.0 / max(cells, 1)
    return MaskSummary(path, totals[0], totals[1], totals[2], cells - sum(totals.values()),
                       totals[1] * pct, totals[2] * pct)


def gcp_check(path: str, points: Sequence[GeoPoint], dem_z: ArrayLike, dem: HeightFrame,
              geoid: GeoidGrid | None, config: StatsConfig) -> GcpCheck:
    """``dz = DEM - h`` at ground points (ellipsoidal ``h``), ``dem_z`` the DEM at them (NaN
    off the DEM or on a void); ``geoid`` needed when the DEM's heights are not ellipsoidal."""
    lon = np.array([p.lon_deg for p in points])
    lat = np.array([p.lat_deg for p in points])
    h = np.array([p.h_m for p in points])
    dem_z = np.asarray(dem_z)
    ok = np.isfinite(dem_z)
    acc = DzAccumulator(config)
    acc.add(height_difference_m(dem_z[ok], dem, h[ok], HeightFrame("ellipsoidal"), lon[ok],
                                lat[ok], geoid))
    return GcpCheck(path, len(points), int((~ok).sum()), acc.stats())
