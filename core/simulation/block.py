"""Blocks of simulated scenes (``gcpfree simulate --block RxC --dates K``): R x C scenes over K
dates of one world, laid out as an archive holds them.

- **Along track** (the block's rows): the R scenes of a column on one date are consecutive
  segments of ONE pass: one orbit, one attitude (its polynomial, jitter and, with realistic
  errors, its profile: functions of time, so the series continues from scene to scene), one
  satellite and date; scene ``r`` is the pass's lines ``r * step .. r * step + n_rows - 1``
  (:meth:`~core.sensors.pushbroom.PushbroomModel.with_image_window`), ``step`` leaving
  ``overlap`` of the lines to the next scene.
- **Across track** (the columns): adjacent passes, each its own orbit, solved so that the
  centre pixel of its middle line sees a point ``(1 - overlap)`` of the narrowest swath of the
  dates away from its neighbour's, across the track; on the date's consecutive days.
- **Dates**: each date views the block from its own across-track incidence (and the preset's
  pitch), so the same (row, col) on two dates is a stereo pair (spot's +25.5 / -20 deg: B/H
  0.84), under that date's sun, on the world as it changed by then (``--date-change``).

Errors are drawn as the pair simulator draws them (:func:`core.simulation.scene.truth_model`,
:func:`~core.simulation.scene.delivered_model`, :func:`~core.simulation.realistic.realistic_truth`)
once per pass, as real products of one segment have them: the lens of the pass's instrument,
its attitude jitter, the attitude biases and drift of its telemetry (a drift rate as large as
one scene's), the profile, ephemeris and clock errors of its orbit determination. Each scene's
metadata are then its own product: the pass's measurements over its own lines (with realistic
errors, sampled and quantised by the scene's own product, as a DIMAP file holds them). Passes
and dates are independent draws.

Pure numerics on the pushbroom model; the DEM heights come in through a callable.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass, replace
from datetime import date, timedelta

import numpy as np

from core.dem import GeoDEM
from core.errors import InputError
from core.geodesy import BBox, enu_rotation, geodetic_to_ecef, metres_per_degree
from core.geoid import GeoidGrid
from core.points import GeoPoint
from core.sensors.pushbroom import PushbroomModel
from core.simulation.hashing import derive_seed
from core.simulation.realistic import measured_model, realistic_truth
from core.simulation.scene import (
    ErrorConfig,
    ImageModels,
    ImageSpec,
    InjectedErrors,
    Preset,
    centre_displacement_m,
    delivered_model,
    scale_relief,
    truth_model,
)

HeightAt = Callable[[float, float], float]  # (lon, lat) -> ellipsoidal terrain height, m

#: the views of dates beyond the preset's two: across-track incidence, pitch, date, sun
EXTRA_DATES = (
    ImageSpec("d2", 10.0, 0.0, "2023-09-20", 165.0, 43.0),
    ImageSpec("d3", -6.0, 0.0, "2023-05-30", 135.0, 66.0),
)
MAX_DATES = 2 + len(EXTRA_DATES)


@dataclass(frozen=True)
class BlockLayout:
    """R x C scenes (``rows`` along track, ``cols`` across) over ``dates`` dates, adjacent
    scenes sharing ``overlap`` of their lines (along) or of the narrowest swath (across)."""

    rows: int
    cols: int
    dates: int
    overlap: float = 0.10

    def __post_init__(self) -> None:
        if not (1 <= self.rows <= 9 and 1 <= self.cols <= 9):
            raise InputError(f"--block must be RxC with 1 <= R, C <= 9, got "
                             f"{self.rows}x{self.cols}")
        if not 1 <= self.dates <= MAX_DATES:
            raise InputError(f"--dates must be 1..{MAX_DATES}, got {self.dates}")
        if self.rows * self.cols * self.dates < 2:
            raise InputError("a block needs at least two images: raise --block or --dates")
        if not 0.02 <= self.overlap <= 0.5:
            raise InputError(f"the block's overlap must be in [0.02, 0.5], got {self.overlap}")

    @classmethod
    def parse(cls, block: str, dates: int, overlap: float = 0.10) -> BlockLayout:
        """From ``--block RxC`` and ``--dates K``."""
        m = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", block)
        if m is None:
            raise InputError(f"--block must read RxC (rows x columns, e.g. 2x2), got {block!r}")
        return cls(int(m.group(1)), int(m.group(2)), int(dates), float(overlap))

    def check_scene(self, scene: str, option: str = "--flat-scene") -> str:
        """``scene`` (``r{row}c{col}``) when the block holds it, else InputError."""
        m = re.fullmatch(r"r(\d+)c(\d+)", scene)
        if m is None or int(m.group(1)) >= self.rows or int(m.group(2)) >= self.cols:
            raise InputError(f"{option} must name a scene r<row>c<col> of the {self.rows}x"
                             f"{self.cols} block (r0c0 .. r{self.rows - 1}c{self.cols - 1}), "
                             f"got {scene!r}")
        return scene

    def names(self) -> tuple[str, ...]:
        """Every image's name, date by date, column by column, row by row."""
        return tuple(image_name(r, c, d) for d in range(self.dates) for c in range(self.cols)
                     for r in range(self.rows))

    def step_rows(self, n_rows: int) -> int:
        """Lines from one scene's first line to the next's along a pass."""
        return round((1.0 - self.overlap) * n_rows)

    def pass_rows(self, n_rows: int) -> int:
        """Lines of a pass of ``rows`` scenes of ``n_rows`` lines."""
        return self.step_rows(n_rows) * (self.rows - 1) + n_rows


def image_name(row: int, col: int, date_index: int) -> str:
    return f"r{row}c{col}d{date_index}"


def pass_name(col: int, date_index: int) -> str:
    return f"c{col}d{date_index}"


_NAME = re.compile(r"r(\d+)c(\d+)d(\d+)")


def parse_image_name(name: str) -> tuple[int, int, int]:
    """(row, col, date) of ``r{row}c{col}d{date}``."""
    m = _NAME.fullmatch(name)
    if m is None:
        raise InputError(f"{name!r} is not a block image name (r<row>c<col>d<date>, e.g. r0c1d0)")
    return int(m.group(1)), int(m.group(2)), int(m.group(3))


def date_views(preset: Preset, dates: int) -> tuple[ImageSpec, ...]:
    """The view and sun of each date: the preset's two images', then :data:`EXTRA_DATES`."""
    views = (*preset.images, *EXTRA_DATES)
    return tuple(replace(v, name=f"d{d}") for d, v in enumerate(views[:dates]))


def pass_view(view: ImageSpec, col: int, date_index: int) -> ImageSpec:
    """The view of column ``col``'s pass on date ``date_index``: the date's, ``col`` days
    later (adjacent orbits)."""
    day = date.fromisoformat(view.date) + timedelta(days=col)
    return replace(view, name=pass_name(col, date_index), date=day.isoformat())


# ---------------------------------------------------------------------------- the world


def block_window(preset: Preset, layout: BlockLayout, lon: float, lat: float) -> BBox:
    """A lon/lat box around the block centre wide enough for the whole block (its passes'
    lines along track and its passes across, 1.6 times for the obliquity of the views, plus
    3 km, as :func:`core.simulation.scene.dem_window` sizes a pair's)."""
    half_m = (0.5 * max(layout.pass_rows(preset.n_rows), layout.cols * preset.n_cols)
              * preset.gsd_m * 1.6 + 3000.0)
    m_lon, m_lat = (float(v) for v in metres_per_degree(lat))
    return BBox(lon - half_m / m_lon, lat - half_m / m_lat, lon + half_m / m_lon,
                lat + half_m / m_lat)


def world_heights(H_m: np.ndarray, transform: tuple[float, ...], relief_factor: float,
                  H_ref_m: float, geoid: GeoidGrid) -> HeightAt:
    """(lon, lat) -> the world's ellipsoidal terrain height: the DEM's orthometric heights with
    their relief scaled, plus the geoid (as :func:`core.simulation.scene.terrain_levels`)."""
    dem = GeoDEM.from_transform(scale_relief(H_m, H_ref_m, relief_factor), transform)
    return lambda lon, lat: float(dem.height_m(lon, lat) + geoid.undulation_m(lon, lat))


# ---------------------------------------------------------------------------- pass geometry


def _enu_offset(lon: float, lat: float, east_m: float, north_m: float) -> tuple[float, float]:
    m_lon, m_lat = metres_per_degree(lat)
    return lon + east_m / float(m_lon), lat + north_m / float(m_lat)


def _swath(model: PushbroomModel, h_m: float) -> tuple[float, np.ndarray]:
    """(width in metres, East-North unit vector from the first detector to the last) of the
    centre line at height h."""
    r = 0.5 * (model.n_rows - 1)
    lon, lat = model.localize(np.array([0.0, model.n_cols - 1.0]), np.array([r, r]),
                              np.array([h_m, h_m]))
    g = np.stack(geodetic_to_ecef(lon, lat, np.array([h_m, h_m])), axis=1)
    e, n, _ = enu_rotation(float(lon.mean()), float(lat.mean()))
    d = g[1] - g[0]
    en = np.array([d @ e, d @ n])
    return float(np.linalg.norm(d)), en / np.linalg.norm(en)


def pass_centres(preset: Preset, layout: BlockLayout, centre: GeoPoint,
                 height_at: HeightAt) -> list[GeoPoint]:
    """Where each column's pass points its centre pixel (its middle line): the block centre
    moved across track by ``(c - (C - 1) / 2) (1 - overlap) W``, W the narrowest swath of the
    dates at the block centre, along the first date's detector line."""
    views = date_views(preset, layout.dates)
    probe = replace(preset, n_rows=layout.pass_rows(preset.n_rows))
    swaths = [_swath(truth_model(v, probe, (centre.lon_deg, centre.lat_deg, centre.h_m),
                                 ErrorConfig(), np.random.default_rng(0)), centre.h_m)
              for v in views]
    width = min(w for w, _ in swaths)
    across = swaths[0][1]
    out = []
    for c in range(layout.cols):
        k = (c - 0.5 * (layout.cols - 1)) * (1.0 - layout.overlap) * width
        lon, lat = _enu_offset(centre.lon_deg, centre.lat_deg, k * across[0], k * across[1])
        out.append(GeoPoint(lon, lat, float(height_at(lon, lat))))
    return out


# ---------------------------------------------------------------------------- pass models


@dataclass(frozen=True, eq=False)
class PassModels:
    """One pass (a column on a date): its truth over all its lines, the model its satellite's
    own measurements describe (``ideal``: with realistic errors, before a product samples it;
    else the delivered model itself) and what was drawn."""

    name: str
    col: int
    date: int
    view: ImageSpec
    centre: GeoPoint
    truth: PushbroomModel
    ideal: PushbroomModel
    injected: InjectedErrors


def pass_models(col: int, date_index: int, view: ImageSpec, preset: Preset, layout: BlockLayout,
                centre: GeoPoint, errors: ErrorConfig, seed: int) -> PassModels:
    """Truth and delivered models of one pass, drawn from ``seed`` and the pass's name as the
    pair simulator draws an image's (the drift scaled so its rate is that of one scene); the
    view is the date's, ``col`` days later."""
    view = pass_view(view, col, date_index)
    n_pass = layout.pass_rows(preset.n_rows)
    probe = replace(preset, n_rows=n_pass)
    cfg = replace(errors, drift_m=errors.drift_m * n_pass / preset.n_rows)
    rng = np.random.default_rng(derive_seed(seed, "block-geometry", view.name))
    where = (centre.lon_deg, centre.lat_deg, centre.h_m)
    truth = truth_model(view, probe, where, errors, rng)
    delivered, injected = delivered_model(truth, probe, cfg, rng, centre.h_m)
    if errors.realistic:
        truth, delivered, real = realistic_truth(
            truth, delivered, np.random.default_rng(derive_seed(seed, "block-realistic",
                                                                view.name)),
            preset.spot_mission)
        injected = replace(injected, realistic=real)
    return PassModels(view.name, col, date_index, view, centre, truth, delivered, injected)


def scene_of_pass(p: PassModels, row: int, preset: Preset, layout: BlockLayout,
                  errors: ErrorConfig, height_at: HeightAt) -> ImageModels:
    """The scene ``row`` of a pass: the pass's truth over its lines, and the metadata its own
    product gives (with realistic errors, the pass's measurements sampled over its lines)."""
    row0 = row * layout.step_rows(preset.n_rows)
    truth = p.truth.with_image_window(0, row0, preset.n_cols, preset.n_rows)
    ideal = p.ideal.with_image_window(0, row0, preset.n_cols, preset.n_rows)
    delivered = (measured_model(ideal, preset.spot_mission, preset.spot_instrument)
                 if errors.realistic else ideal)
    c, r = 0.5 * (preset.n_cols - 1), 0.5 * (preset.n_rows - 1)
    lon, lat = truth.localize(c, r, p.centre.h_m)
    h = float(height_at(float(lon), float(lat)))
    return ImageModels(truth, delivered, replace(
        p.injected, centre_error_m=centre_displacement_m(truth, delivered, h)))


@dataclass(frozen=True, eq=False)
class BlockImage:
    """One image of a block: where it sits, its pass and its models."""

    name: str
    row: int
    col: int
    date: int
    pass_name: str
    first_line_in_pass: int
    models: ImageModels


def block_models(preset: Preset, layout: BlockLayout, centre: GeoPoint, errors: ErrorConfig,
                 seed: int, height_at: HeightAt) -> tuple[list[PassModels], list[BlockImage]]:
    """Every pass and every image of the block."""
    centres = pass_centres(preset, layout, centre, height_at)
    passes, images = [], []
    for d, view in enumerate(date_views(preset, layout.dates)):
        for c in range(layout.cols):
            p = pass_models(c, d, view, preset, layout, centres[c], errors, seed)
            passes.append(p)
            for r in range(layout.rows):
                images.append(BlockImage(
                    image_name(r, c, d), r, c, d, p.name, r * layout.step_rows(preset.n_rows),
                    scene_of_pass(p, r, preset, layout, errors, height_at)))
    return passes, images


# ---------------------------------------------------------------------------- a flat scene

FLAT_RELIEF = 0.02  # the flattened scene's relief factor (--relief-factor 0.02 orient refuses)
FLAT_TAPER_M = 2000.0  # from the flat ground back to the world's over this distance


def _outside_m(x: np.ndarray, y: np.ndarray, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """How far each point lies outside the convex polygon (px, py) (metres, the largest of its
    distances beyond the edges' lines; <= 0 inside)."""
    if np.sum(px * np.roll(py, -1) - np.roll(px, -1) * py) < 0:  # make it counter-clockwise
        px, py = px[::-1], py[::-1]
    out = np.full(x.shape, -np.inf)
    for i in range(px.size):
        ex, ey = px[(i + 1) % px.size] - px[i], py[(i + 1) % px.size] - py[i]
        norm = np.hypot(ex, ey)
        out = np.maximum(out, ((x - px[i]) * ey - (y - py[i]) * ex) / norm)
    return out


def flatten_region(H_m: np.ndarray, transform: tuple[float, ...],
                   footprints: list[tuple[np.ndarray, np.ndarray]], relief: float = FLAT_RELIEF,
                   taper_m: float = FLAT_TAPER_M) -> tuple[np.ndarray, float]:
    """The heights of a north-up lon/lat DEM (``H_m`` on ``transform``) with their relief
    scaled by ``relief`` around the median height inside the convex footprints (lon, lat corner
    arrays), back to the world's over ``taper_m`` outside them; and that median."""
    a, _, c, _, e, f = transform[:6]
    rows, cols = np.mgrid[0:H_m.shape[0], 0:H_m.shape[1]]
    lon, lat = c + (cols + 0.5) * a, f + (rows + 0.5) * e
    lon0, lat0 = float(np.mean(footprints[0][0])), float(np.mean(footprints[0][1]))
    m_lon, m_lat = (float(v) for v in metres_per_degree(lat0))
    x, y = (lon - lon0) * m_lon, (lat - lat0) * m_lat
    d = np.min([_outside_m(x, y, (fl - lon0) * m_lon, (fa - lat0) * m_lat)
                for fl, fa in footprints], axis=0)
    w = np.clip(1.0 - d / taper_m, 0.0, 1.0)
    inside = d <= 0
    if not inside.any():
        raise InputError("the scene to flatten lies outside the DEM read; choose another scene")
    h_loc = float(np.nanmedian(H_m[inside]))
    flat = h_loc + (1.0 - w * (1.0 - relief)) * (H_m - h_loc)
    return np.where(w > 0, flat, H_m), h_loc  # the world's own heights beyond the taper
