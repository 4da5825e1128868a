"""The archive as a map, refreshed as pairs end: ``ROOT/map.html`` (a page with the map, the
counts, the throughput and the slowest steps) and ``ROOT/map.svg`` beside ``summary.csv``, and
the Prefect artifact ``archive-map`` (the same map and tables as markdown) on the run's page.

What the map is drawn from, as the archive leaves it:

- **footprints**: a ``gcpfree scenes`` catalog's scene footprints (computed there at the
  terrain's mean height); for another catalog, each image's corners localised by its own
  model at the model's own mean height (:func:`tasks.archive.scenes.own_height_m`). A pair is
  drawn as the overlap of its two images' footprints (where its DSM can be); a pair whose
  models cannot be read is listed without one;
- **status**, per pair: ``done``, ``skipped`` (complete from an earlier run: drawn as done),
  ``refused`` and ``failed`` with their reasons (:class:`tasks.archive.runs.PairResult`),
  ``running`` (on a worker now, as the Dask scheduler says) and ``queued`` (submitted, not
  started);
- **stated accuracy**: the check-point RMS the orientation predicts for itself
  (``report.json``'s ``absolute.predicted``, worst image and axis, pixels), beside the measured
  one when check points were given;
- **time**: the seconds each pair took on its worker, and each step's from the products' write
  times (:data:`STEPS`: a step ends when its last product is renamed into place; the products
  an earlier run made are not counted);
- **relief**: an SRTM hillshade under the footprints (:func:`core.simulation.render.hillshade`
  on the archive's reference or DEM tiles read at the map's scale), when they cover them.

The page and the SVG are self-contained (no script, no font, nothing fetched: the hillshade is a
PNG inside the SVG); drawing is :mod:`tasks.archive.map_render`. A map that cannot be drawn never
stops the archive: it says why on the page.
"""

from __future__ import annotations

import functools
import statistics
import warnings
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from core.errors import GcpFreeError
from core.geodesy import BBox, metres_per_degree
from core.sensors.viewing import clip_convex, scene_geometry, signed_area
from tasks.archive.catalog import Catalog, PairEntry, one_line
from tasks.archive.runs import PairResult

Polygon = tuple[tuple[float, float], ...]

#: the pair flow's steps in the order it runs them, each with the product written last
STEPS = (("relative orientation", "relative/rel.json"), ("relative DEM", "relative_dem.tif"),
         ("surface matching", "windows.json"), ("absolute orientation", "right.json"),
         ("final DSM", "dsm_egm96.tif"), ("orthos", "ortho_right.tif"),
         ("ortho check", "ortho_compare.json"), ("lidar evaluation", "eval.json"),
         ("report", "report.html"), ("STAC and manifest", "pair.json"))
#: the map's statuses, in the legend's order (``skipped`` is drawn as ``done``)
MAP_STATUSES = ("done", "refused", "failed", "running", "queued")
SHADE_PX = 600  # the hillshade's longer side, pixels
MARGIN = 0.08  # of the footprints' extent, around them


@dataclass(frozen=True)
class PairState:
    """One pair as the map shows it (see the module docstring); figures None when unknown."""

    id: str
    status: str
    reason: str = ""
    stated_px: float | None = None
    measured_px: float | None = None
    gcps: int | None = None
    seconds: float | None = None
    steps: tuple[tuple[str, float], ...] = ()

    @property
    def shown(self) -> str:
        """The status drawn: ``skipped`` (complete from an earlier run) is ``done``."""
        return "done" if self.status == "skipped" else self.status


@dataclass(frozen=True)
class Footprints:
    """Where the pairs and scenes lie, (lon, lat) polygons counter-clockwise; ``missing``: the
    pairs without one and why; ``source``: how they were found."""

    pairs: Mapping[str, Polygon]
    scenes: Mapping[str, Polygon]
    missing: Mapping[str, str]
    source: str

    def box(self) -> BBox | None:
        """The box of every footprint with a margin, None without any."""
        pts = [p for poly in (*self.pairs.values(), *self.scenes.values()) for p in poly]
        if not pts:
            return None
        lon, lat = np.array(pts).T
        pad = MARGIN * max(float(np.ptp(lon)), float(np.ptp(lat)), 0.01)
        return BBox(float(lon.min()), float(lat.min()), float(lon.max()),
                    float(lat.max())).expanded(pad)


@dataclass(frozen=True)
class Shade:
    """The hillshade under the map: a greyscale PNG over ``bounds`` (lon_min, lat_min, lon_max,
    lat_max, the outer edges of its pixels) and what it was made from."""

    png: bytes
    bounds: tuple[float, float, float, float]
    source: str


@dataclass(frozen=True)
class ArchiveMap:
    """Everything the map page shows at one moment of a run."""

    root: Path
    pairs: tuple[PairState, ...]
    footprints: Footprints
    shade: Shade | None
    shade_note: str
    elapsed_s: float
    updated_utc: str = field(default_factory=lambda: datetime.now(UTC).strftime(
        "%Y-%m-%d %H:%M:%S UTC"))

    def count(self, status: str) -> int:
        return sum(p.shown == status for p in self.pairs)

    def throughput(self) -> Throughput:
        """:func:`throughput` of this map."""
        return throughput(self)

    def slowest_steps(self) -> list[StepTimes]:
        """:func:`slowest_steps` of its pairs."""
        return slowest_steps(self.pairs)


# ----------------------------------------------------------------------------- footprints


def _ccw(poly: Iterable[tuple[float, float]]) -> np.ndarray:
    p = np.asarray(list(poly), dtype=np.float64).reshape(-1, 2)
    return p if signed_area(p) >= 0 else p[::-1]


def overlap(a: Polygon, b: Polygon) -> Polygon:
    """The part of footprint ``a`` inside footprint ``b`` (both convex, lon/lat), or ``a``
    when they do not meet."""
    inside = clip_convex(_ccw(a), _ccw(b))
    poly = inside if inside.shape[0] >= 3 else _ccw(a)
    return tuple((float(x), float(y)) for x, y in poly)


def _model_corners(loaded) -> Polygon:  # LoadedModel
    from tasks.archive.scenes import own_height_m

    g = scene_geometry(loaded.model, *loaded.size, own_height_m(loaded)[0])
    return tuple((c.lon_deg, c.lat_deg) for c in g.corners)


def _from_models(entry: PairEntry) -> tuple[Polygon, Polygon]:
    from rasterio.errors import NotGeoreferencedWarning

    with warnings.catch_warnings():  # raw sensor images have no CRS, by nature
        warnings.simplefilter("ignore", NotGeoreferencedWarning)
        left, right = entry.pair_inputs().load()
    return _model_corners(left), _model_corners(right)


@functools.lru_cache(maxsize=4)
def catalog_footprints(catalog: Catalog) -> Footprints:
    """Each pair's and scene's footprint (see the module docstring); computed once per catalog
    in a process."""
    by_image = {Path(s.image).resolve(): s for s in catalog.scenes if s.footprint}
    pairs: dict[str, Polygon] = {}
    scenes: dict[str, Polygon] = {s.id: tuple(s.footprint) for s in by_image.values()}
    missing: dict[str, str] = {}
    from_models = 0
    for e in catalog.pairs:
        a, b = by_image.get(Path(e.left).resolve()), by_image.get(Path(e.right).resolve())
        try:
            if a is not None and b is not None:
                left, right = a.footprint, b.footprint
            else:
                left, right = _from_models(e)
                from_models += 1
                scenes[f"{e.id}/left"], scenes[f"{e.id}/right"] = left, right
            pairs[e.id] = overlap(left, right)
        except Exception as exc:  # noqa: BLE001 - a pair without a footprint is listed
            missing[e.id] = one_line(str(exc)) or type(exc).__name__
    source = ("the scenes catalog's footprints (gcpfree scenes, at the terrain's mean height)"
              if not from_models else
              "each image's corners by its own model at the model's own mean height"
              if from_models == len(catalog.pairs) else
              f"the scenes catalog's footprints; {from_models} pairs from their models")
    return Footprints(pairs, scenes, missing, source)


# ----------------------------------------------------------------------------- relief


def _dem_raster(box: BBox, reference: Path | None, dem_dir: Path | None
                ) -> tuple[str, str, Path | None]:
    """(what rasterio opens, what it is, a temporary VRT to remove) for the map's box."""
    if reference is not None:
        return str(reference), f"the reference {Path(reference).name}", None
    import tempfile

    from tasks.io.dem_tiles import DemSource, build_vrt, find_tiles, mosaic_grid

    tiles = find_tiles(DemSource(Path(dem_dir)), box, allow_missing=True)  # type: ignore[arg-type]
    fd, name = tempfile.mkstemp(prefix="gcpfree-map-", suffix=".vrt")
    vrt = Path(name)
    with open(fd, "w") as f:
        f.write(build_vrt(tiles, mosaic_grid(tiles, box)))
    return str(vrt), f"{tiles.product.name} tiles {', '.join(tiles.names)}", vrt


def _read_heights(path: str, box: BBox) -> tuple[np.ndarray, tuple[float, float, float, float]]:
    """The DEM's heights over ``box`` at about :data:`SHADE_PX` pixels on the longer side
    (averaged; voids NaN), and the outer bounds of what was read."""
    from rasterio.enums import Resampling
    from rasterio.windows import from_bounds

    from tasks.io.dem import VOID_BELOW_M
    from tasks.io.rasters import open_raster

    with open_raster(path, "DEM") as src:
        b = src.bounds
        clip = (max(box.lon_min, b.left), max(box.lat_min, b.bottom),
                min(box.lon_max, b.right), min(box.lat_max, b.top))
        if clip[0] >= clip[2] or clip[1] >= clip[3]:
            raise GcpFreeError("the DEM does not reach the footprints")
        win = from_bounds(*clip, transform=src.transform).round_offsets().round_lengths()
        f = max(float(win.width), float(win.height)) / SHADE_PX
        shape = (max(2, round(float(win.height) / max(f, 1.0))),
                 max(2, round(float(win.width) / max(f, 1.0))))
        z = src.read(1, window=win, out_shape=shape, resampling=Resampling.average,
                     masked=True).astype(np.float64).filled(np.nan)
        left, bottom, right, top = src.window_bounds(win)
    z[z <= VOID_BELOW_M] = np.nan
    return z, (left, bottom, right, top)


def grey_png(grey: np.ndarray) -> bytes:
    """An 8-bit greyscale PNG of ``grey`` (uint8, rows top down): each row filtered by its
    difference to the row above (PNG filter 2, "Up"), then deflated."""
    import struct
    import zlib

    g = np.ascontiguousarray(grey, dtype=np.uint8)
    if g.ndim != 2 or 0 in g.shape:
        raise GcpFreeError(f"a greyscale image is 2-D and not empty, got shape {g.shape}")
    up = np.diff(g, axis=0, prepend=np.zeros((1, g.shape[1]), np.uint8))  # wraps mod 256
    raw = np.hstack([np.full((g.shape[0], 1), 2, np.uint8), up]).tobytes()

    def chunk(kind: bytes, data: bytes) -> bytes:
        return (struct.pack(">I", len(data)) + kind + data
                + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF))

    header = struct.pack(">IIBBBBB", g.shape[1], g.shape[0], 8, 0, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header)
            + chunk(b"IDAT", zlib.compress(raw, 9)) + chunk(b"IEND", b""))


@functools.lru_cache(maxsize=4)
def read_shade(box: BBox, reference: Path | None, dem_dir: Path | None
               ) -> tuple[Shade | None, str]:
    """The hillshade of the archive's reference or DEM tiles over ``box`` (sun from the
    north-west, 45 degrees up; the heights' datum does not change a shade), or None and why."""
    from core.simulation.render import hillshade

    if reference is None and dem_dir is None:
        return None, "no hillshade: the archive has no reference DEM"
    vrt = None
    try:
        path, what, vrt = _dem_raster(box, reference, dem_dir)
        z, bounds = _read_heights(path, box)
    except (GcpFreeError, OSError) as exc:
        return None, f"no hillshade: {one_line(str(exc))}"
    finally:
        if vrt is not None:
            vrt.unlink(missing_ok=True)
    if not np.isfinite(z).any():
        return None, f"no hillshade: {what} has only voids under the footprints"
    m_lon, m_lat = metres_per_degree(0.5 * (bounds[1] + bounds[3]))
    dx_m = (bounds[2] - bounds[0]) / z.shape[1] * m_lon
    dy_m = -(bounds[3] - bounds[1]) / z.shape[0] * m_lat
    shade = hillshade(z, dx_m, dy_m, 315.0, 45.0)
    grey = np.where(np.isfinite(shade), 40.0 + 215.0 * np.nan_to_num(shade), 250.0)
    cell = max(abs(dx_m), abs(dy_m))
    return Shade(grey_png(np.round(grey).astype(np.uint8)), bounds,
                 f"hillshade of {what}, {cell:.0f} m cells"), ""


# ----------------------------------------------------------------------------- pair states


def stated_and_measured_px(out: Path) -> tuple[float | None, float | None, int | None]:
    """From ``out/report.json``: the worst predicted check-point RMS over the images and axes
    (px), the worst measured one (check points given), the GCPs used; Nones when unread."""
    from tasks.absolute.report import read_report

    try:
        report = read_report(Path(out) / "report.json")
    except GcpFreeError:
        return None, None, None
    images = (report.absolute.predicted or {}).get("images", {})
    stated = [float(v[k]) for v in images.values()
              for k in ("predicted_rms_col_px", "predicted_rms_row_px")]
    measured = [float(getattr(c, k)) for c in (report.check_points or {}).values()
                for k in ("rms_col_px", "rms_row_px")]
    return (max(stated) if stated else None, max(measured) if measured else None,
            report.gcps.used)


def step_times(out: Path, since_s: float) -> tuple[tuple[str, float], ...]:
    """Each step of :data:`STEPS` this run made in ``out`` (its product written at or after
    ``since_s``, seconds since the epoch) and its seconds: from the previous step's product,
    the first from ``since_s``."""
    made: list[tuple[str, float]] = []
    for step, product in STEPS:
        path = Path(out) / product
        if path.is_file() and path.stat().st_mtime >= since_s:
            made.append((step, path.stat().st_mtime))
    out_steps, before = [], since_s
    for step, t in sorted(made, key=lambda m: m[1]):
        out_steps.append((step, max(0.0, t - before)))
        before = t
    return tuple(out_steps)


def pair_state(pair_id: str, status: str, out: Path, result: PairResult | None = None
               ) -> PairState:
    """A pair's state on the map: its figures read from its products when it is done or kept,
    its reason and times from this run's ``result``."""
    stated = measured = gcps = None
    if status in ("done", "skipped"):
        stated, measured, gcps = stated_and_measured_px(out)
    if result is None:
        return PairState(pair_id, status, stated_px=stated, measured_px=measured, gcps=gcps)
    steps = step_times(out, result.started_s) if result.started_s is not None else ()
    return PairState(pair_id, status, result.reason, stated, measured, gcps, result.seconds,
                     steps)


# ----------------------------------------------------------------------------- the run


@dataclass(frozen=True)
class Throughput:
    """This run so far: pairs ended and left, pairs per hour, the median and slowest seconds a
    pair took on its worker, the seconds the rest would take at this rate (None: unknown)."""

    ended: int
    left: int
    per_hour: float | None
    median_s: float | None
    max_s: float | None
    eta_s: float | None


def throughput(m: ArchiveMap) -> Throughput:
    secs = [p.seconds for p in m.pairs if p.seconds is not None]
    left = sum(p.shown in ("running", "queued") for p in m.pairs)
    per_h = 3600.0 * len(secs) / m.elapsed_s if secs and m.elapsed_s > 0 else None
    return Throughput(len(secs), left, per_h, statistics.median(secs) if secs else None,
                      max(secs) if secs else None, left * 3600.0 / per_h if per_h else None)


@dataclass(frozen=True)
class StepTimes:
    """One step over this run's pairs: how many made it, the total, median and slowest
    seconds, and the pair that was slowest."""

    step: str
    pairs: int
    total_s: float
    median_s: float
    max_s: float
    slowest: str


def slowest_steps(pairs: Iterable[PairState]) -> list[StepTimes]:
    """Each step of this run, the longest in total first."""
    by_step: dict[str, list[tuple[float, str]]] = {}
    for p in pairs:
        for step, s in p.steps:
            by_step.setdefault(step, []).append((s, p.id))
    rows = [StepTimes(step, len(v), sum(s for s, _ in v), statistics.median(s for s, _ in v),
                      *max(v)) for step, v in by_step.items()]
    return sorted(rows, key=lambda r: -r.total_s)
