"""Tasks of the block simulator (``gcpfree simulate --block RxC --dates K``): R x C scenes over
K dates of one world (:mod:`core.simulation.block` says how they are laid out and drawn).

``DIR/images/r{row}c{col}d{date}.tif`` with its delivered model (``.json``) and SPOT metadata
(``.DIM``) beside; ``DIR/truth/``: each image's truth model (``<name>_truth.json``), the world's
``scene.json`` (every image's injected errors), ``block.json`` (the layout, each image's pass,
segment and date, the passes' errors, the overlaps and B/H), ``checkpoints.json`` (each point's
position in every image that sees it), the truth DSM/DTM and land cover; ``DIR/reference.tif``
the SRTM-like reference, degraded from the block's truth as the pair simulator degrades a
pair's. The world, its truth rasters and reference are made by the pair simulator's own tasks
(:mod:`tasks.simulate.scene`) on the block's world.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from prefect import task

from core.geodesy import BBox, utm_epsg
from core.jsonio import parse_json
from core.points import GeoPoint
from core.sensors.pushbroom import PushbroomModel
from core.sensors.spot import spot_scene_from_model
from core.sensors.viewing import image_corners_px, pair_geometry
from core.simulation.block import (
    FLAT_RELIEF,
    BlockImage,
    BlockLayout,
    PassModels,
    block_models,
    block_window,
    date_views,
    flatten_region,
    parse_image_name,
    world_heights,
)
from core.simulation.checkpoints import select_block_checkpoints
from core.simulation.hashing import derive_seed
from core.simulation.realistic import metadata_scene
from core.simulation.scene import (
    PRESETS,
    ErrorConfig,
    SceneDef,
    TruthGrid,
    check_window_covers,
    footprint_points,
    terrain_levels,
)
from tasks.io.crs import Projection
from tasks.io.dem import dem_datum
from tasks.io.dimap import write_dimap
from tasks.io.geoid import load_geoid
from tasks.io.rasters import (
    CogItem,
    CogOptions,
    atomic_write_json,
    atomic_write_text,
    write_arrays_cog,
)
from tasks.simulate.io import ScenePaths, products_exist, read_dem_window
from tasks.simulate.scene import (
    DateLight,
    RenderJob,
    check_world_options,
    earlier_scene,
    render_images,
    world_centre,
    write_checkpoints,
    write_radiance,
)

BLOCK_FORMAT = "gcpfree.simulated_block"
CHECKPOINTS_PER_SCENE = 50


@dataclass(frozen=True)
class BlockPaths(ScenePaths):
    """Where a block's products live: the images and their models under ``DIR/images/``, the
    truth (shared with a pair's layout) under ``DIR/truth/``."""

    @property
    def images(self) -> Path:
        return self.root / "images"

    def date_radiance(self, date_index: int) -> Path:
        return self.work / f"radiance_d{date_index}.tif"

    @property
    def block_json(self) -> Path:
        return self.truth / "block.json"

    @property
    def world_dem(self) -> Path:
        return self.work / "world_dem.tif"


@dataclass(frozen=True)
class BlockOptions:
    """What ``gcpfree simulate --block`` was asked (the world's settings are a pair's)."""

    layout: BlockLayout
    preset: str = "tiny"
    seed: int = 0
    errors: ErrorConfig = field(default_factory=ErrorConfig)
    relief_factor: float = 1.0
    bits: int = 8
    date_change: float = 0.0
    centre_lonlat: tuple[float, float] | None = None
    dem_vertical: str = "auto"
    flat_scene: str | None = None  # "r{row}c{col}": that scene's ground made too flat

    def __post_init__(self) -> None:
        check_world_options(self.preset, self.relief_factor, self.date_change, self.bits)
        if self.flat_scene is not None:
            self.layout.check_scene(self.flat_scene)


# ---------------------------------------------------------------------------- the world


def _footprints(images: list[BlockImage], flat: str, h_m: float
                ) -> list[tuple[np.ndarray, np.ndarray]]:
    col, row = image_corners_px(images[0].models.truth.n_cols, images[0].models.truth.n_rows)
    out = []
    for im in images:
        if f"r{im.row}c{im.col}" == flat:
            lon, lat = im.models.truth.localize(col, row, np.full(4, h_m))
            out.append((np.asarray(lon), np.asarray(lat)))
    return out


def _flat_world(opts: BlockOptions, paths: BlockPaths, H: np.ndarray, tr: tuple,
                window: BBox, images: list[BlockImage], h_m: float) -> tuple[np.ndarray, dict]:
    """The DEM with the flat scene's ground flattened, written as the world's DEM and read
    back (its heights are the world's, float32 as written)."""
    flat, h_loc = flatten_region(H, tr, _footprints(images, opts.flat_scene, h_m))
    paths.work.mkdir(parents=True, exist_ok=True)
    write_arrays_cog([CogItem(flat.astype(np.float32), paths.world_dem, CogOptions(
        transform=tr, crs="EPSG:4326", nodata=None,
        tags={"vertical_datum": "EGM96 geoid (orthometric heights)", "units": "m",
              "source": f"the block's world: scene {opts.flat_scene} flattened "
                        f"(relief x {FLAT_RELIEF} around {h_loc:.1f} m)"}))])
    world, _, _ = read_dem_window(paths.world_dem, window, "egm96")
    return world, {"scene": opts.flat_scene, "relief_factor": FLAT_RELIEF, "around_H_m": h_loc,
                   "dem": paths.world_dem.relative_to(paths.root).as_posix()}


@dataclass(frozen=True, eq=False)
class BlockWorld:
    """The block's world (a pair's scene definition of all its images), passes and images."""

    scene: SceneDef
    passes: list[PassModels]
    images: list[BlockImage]
    flat: dict | None


def _world(opts: BlockOptions, dem: Path, paths: BlockPaths) -> BlockWorld:
    """Read the DEM (flatten a scene), draw the passes, size the truth grid."""
    preset = PRESETS[opts.preset]
    clon, clat = world_centre(dem, opts.centre_lonlat)
    datum = dem_datum(dem, opts.dem_vertical, what="DEM", option="--dem-vertical")
    H, tr, window = read_dem_window(dem, block_window(preset, opts.layout, clon, clat),
                                    datum.datum)
    flat, dem_path, vertical = None, dem, (datum.datum, datum.source)
    for attempt in range(2 if opts.flat_scene else 1):
        levels = terrain_levels(H, tr, load_geoid(), clon, clat, opts.relief_factor)
        centre = GeoPoint(clon, clat, levels.h_centre_m)
        height_at = world_heights(H, tr, opts.relief_factor, levels.H_ref_m, load_geoid())
        passes, images = block_models(preset, opts.layout, centre, opts.errors, opts.seed,
                                      height_at)
        if attempt == 0 and opts.flat_scene:  # the world flattened, its models drawn on it
            H, flat = _flat_world(opts, paths, H, tr, window, images, levels.h_centre_m)
            dem_path, vertical = paths.world_dem, (
                "egm96", f"the block's world ({dem.name}, scene {opts.flat_scene} flattened)")
    lon, lat = footprint_points([im.models.truth for im in images], levels.h_lo_m,
                                levels.h_hi_m)
    check_window_covers(window, lon, lat, dem.name)
    epsg = utm_epsg(clon, clat)
    x, y = Projection(epsg).to_xy(lon, lat)
    res = preset.truth_res_m
    scene = SceneDef(
        preset=opts.preset, seed=int(opts.seed), dem_path=str(Path(dem_path).resolve()),
        dem_window=window, relief_factor=float(opts.relief_factor), H_ref_m=levels.H_ref_m,
        centre=centre, epsg=epsg, grid=TruthGrid.covering(x, y, res, 10 * res),
        water_level_m=levels.water_level_m, bits=int(opts.bits),
        date_change=float(opts.date_change), errors=opts.errors,
        image_names=tuple(im.name for im in images),
        injected={im.name: im.models.injected for im in images},
        dem_vertical=vertical[0], dem_vertical_source=vertical[1],
    )
    return BlockWorld(scene, passes, images, flat)


# ---------------------------------------------------------------------------- block.json


def _figures(images: list[BlockImage], h_m: float) -> dict:
    """Overlaps of adjacent scenes (along and across track, on the first date) and the B/H of
    each scene's dates, at the block centre's height."""
    by = {(im.row, im.col, im.date): im for im in images}
    size = (images[0].models.truth.n_cols, images[0].models.truth.n_rows)

    def geometry(a: BlockImage, b: BlockImage) -> dict:
        g = pair_geometry(a.models.truth, size, b.models.truth, size, h_m)
        return {"left": a.name, "right": b.name, "overlap_pct": round(g.overlap_pct, 2),
                "b_over_h": round(g.b_over_h, 4), "convergence_deg": round(g.convergence_deg, 3)}

    along = [geometry(im, by[(im.row + 1, im.col, im.date)]) for im in images
             if im.date == 0 and (im.row + 1, im.col, im.date) in by]
    across = [geometry(im, by[(im.row, im.col + 1, im.date)]) for im in images
              if im.date == 0 and (im.row, im.col + 1, im.date) in by]
    dates = [geometry(im, by[(im.row, im.col, d)]) for im in images if im.date == 0
             for d in range(1, 1 + max(i.date for i in images)) if (im.row, im.col, d) in by]
    return {"h_m": h_m, "along_track": along, "across_track": across, "stereo": dates}


def _block_doc(opts: BlockOptions, world: BlockWorld, paths: BlockPaths) -> dict:
    lay, preset = opts.layout, PRESETS[opts.preset]

    def rel(p: Path) -> str:
        return p.relative_to(paths.root).as_posix()

    return {
        "format": BLOCK_FORMAT, "version": 1, "preset": opts.preset, "seed": opts.seed,
        "rows": lay.rows, "cols": lay.cols, "dates": lay.dates, "overlap": lay.overlap,
        "errors": "realistic" if opts.errors.realistic else "simple",
        "lens": opts.errors.lens, "jitter": opts.errors.jitter,
        "errors_drawn": "per pass (one orbit, attitude, instrument and clock for the scenes of "
                        "a segment); each scene's metadata its own product's",
        "flat_scene": world.flat,
        "date_views": [{"date": d, "incidence_deg": v.incidence_deg, "pitch_deg": v.pitch_deg,
                        "date_utc": v.date, "sun_azimuth_deg": v.sun_azimuth_deg,
                        "sun_elevation_deg": v.sun_elevation_deg}
                       for d, v in enumerate(date_views(preset, lay.dates))],
        "passes": [{"pass": p.name, "col": p.col, "date": p.date, "date_utc": p.view.date,
                    "centre": p.centre.to_list(), "lines": p.truth.n_rows,
                    "scenes": [im.name for im in world.images if im.pass_name == p.name],
                    "injected": p.injected.to_dict()} for p in world.passes],
        "images": [{"name": im.name, "row": im.row, "col": im.col, "date": im.date,
                    "pass": im.pass_name, "segment": im.pass_name, "scene_in_segment": im.row,
                    "first_line_in_pass": im.first_line_in_pass,
                    "image": rel(paths.image(im.name)), "model": rel(paths.delivered(im.name)),
                    "dimap": rel(paths.dimap(im.name)),
                    "truth_model": rel(paths.truth_model(im.name)),
                    "centre_error_m": im.models.injected.centre_error_m}
                   for im in world.images],
        "figures": _figures(world.images, world.scene.centre.h_m),
    }


# ---------------------------------------------------------------------------- tasks


@task(name="define-block")
def define_block(dem: Path, out: Path, opts: BlockOptions) -> SceneDef:
    """Draw the block's passes and images, write their models, the world's scene.json and
    block.json; a rerun of the same block resumes, another block in ``out`` is refused."""
    paths = BlockPaths(Path(out))
    world = _world(opts, Path(dem), paths)
    old = earlier_scene(paths, world.scene)
    if old is not None and paths.block_json.exists():
        return old
    paths.truth.mkdir(parents=True, exist_ok=True)
    paths.images.mkdir(parents=True, exist_ok=True)
    for im in world.images:
        atomic_write_text(paths.truth_model(im.name), im.models.truth.to_json(indent=1))
        atomic_write_text(paths.delivered(im.name), im.models.delivered.to_json(indent=1))
    atomic_write_json(paths.block_json, _block_doc(opts, world, paths))
    atomic_write_text(paths.scene_json, world.scene.to_json())
    return SceneDef.from_json(world.scene.to_json())


@task(name="block-metadata")
def write_block_metadata(scene: SceneDef, out: Path) -> tuple[Path, ...]:
    """Each image's delivered model as SPOT Level 1A metadata beside it (as a pair's)."""
    paths = BlockPaths(Path(out))
    preset = scene.preset_spec
    views = date_views(preset, 1 + max(parse_image_name(n)[2] for n in scene.image_names))
    for name in scene.image_names:
        if products_exist(paths.dimap(name)):
            continue
        view = views[parse_image_name(name)[2]]
        write = metadata_scene if scene.errors.realistic else spot_scene_from_model
        spot = write(PushbroomModel.from_json(paths.delivered(name).read_text()),
                     mission_index=preset.spot_mission, instrument=preset.spot_instrument,
                     instrument_index=1, dataset_name=(f"SIMULATED {scene.preset} block {name} "
                                                       f"seed {scene.seed} (gcpfree simulate)"),
                     sun_azimuth_deg=view.sun_azimuth_deg,
                     sun_elevation_deg=view.sun_elevation_deg)
        write_dimap(spot, paths.dimap(name), image_name=paths.image(name).name)
    return tuple(paths.dimap(n) for n in scene.image_names)


def block_light(scene: SceneDef, date_index: int) -> DateLight:
    """A block's date: its sun; later dates changed by ``date_change``, the second as a pair's
    second date, the others each in their own pattern."""
    view = date_views(scene.preset_spec, date_index + 1)[date_index]
    seed = scene.seed if date_index <= 1 else derive_seed(scene.seed, "block-date", date_index)
    return DateLight(view.sun_azimuth_deg, view.sun_elevation_deg,
                     scene.date_change if date_index > 0 else 0.0, seed)


@task(name="block-radiance")
def build_block_radiance(scene: SceneDef, out: Path, date_index: int) -> Path:
    """The ground radiance of one date of the block on the truth grid (COG, kept for reruns)."""
    paths = BlockPaths(Path(out))
    return write_radiance(scene, paths, block_light(scene, date_index),
                          paths.date_radiance(date_index))


@task(name="render-block-images")
def render_block_images(scene: SceneDef, out: Path, date_index: int) -> list[Path]:
    """Render the block's images of one date on its radiance, side by side."""
    paths = BlockPaths(Path(out))
    names = [n for n in scene.image_names if parse_image_name(n)[2] == date_index]
    return render_images(scene, paths, [
        RenderJob(n, paths.date_radiance(date_index), derive_seed(scene.seed, "sensor-noise", n))
        for n in names])


@task(name="block-check-points")
def make_block_checkpoints(scene: SceneDef, out: Path) -> Path:
    """Bare-soil check points seen by two images or more, each with its true position in every
    image that sees it (``truth/checkpoints.json``, keyed by image name)."""
    n_scenes = len({parse_image_name(n)[:2] for n in scene.image_names})
    return write_checkpoints(scene, BlockPaths(Path(out)), select_block_checkpoints,
                             "block-checkpoints", CHECKPOINTS_PER_SCENE * n_scenes,
                             20 * n_scenes, "in the block", "world")


@dataclass(frozen=True)
class BlockSummary:
    """What ``simulate --block`` made, for printing."""

    out: str
    preset: str
    seed: int
    layout: tuple[int, int, int]
    images: int
    checkpoints: int
    dsm_range_m: tuple[float, float]
    overlap_along_pct: tuple[float, ...]
    overlap_across_pct: tuple[float, ...]
    b_over_h: tuple[float, ...]
    flat_scene: str | None
    errors: str

    def lines(self) -> list[str]:
        def span(v: tuple[float, ...], fmt: str) -> str:
            return "none" if not v else f"{min(v):{fmt}}..{max(v):{fmt}}"

        r, c, k = self.layout
        return [
            (f"simulated block  {self.out} (preset {self.preset}, {r}x{c} scenes over {k} "
             f"dates, seed {self.seed}, {self.errors} errors)"),
            (f"images           {self.images} in {self.out}/images (r<row>c<col>d<date>.tif, "
             "models beside); truth/block.json lists them"),
            (f"overlaps         along track {span(self.overlap_along_pct, '.1f')} %, across "
             f"{span(self.overlap_across_pct, '.1f')} %; B/H between dates "
             f"{span(self.b_over_h, '.2f')}"),
            (f"truth            DSM/DTM {self.dsm_range_m[0]:.0f}..{self.dsm_range_m[1]:.0f} m "
             f"ellipsoidal, {self.checkpoints} check points"
             + (f"; scene {self.flat_scene} flattened" if self.flat_scene else "")),
        ]


@task(name="summarize-block")
def summarize_block(scene: SceneDef, out: Path) -> BlockSummary:
    paths = BlockPaths(Path(out))
    doc = parse_json(paths.block_json.read_text(), str(paths.block_json))
    fig = doc["figures"]
    n_cp = len(parse_json(paths.checkpoints.read_text(), str(paths.checkpoints))["points"])
    return BlockSummary(
        out=str(paths.root), preset=scene.preset, seed=scene.seed,
        layout=(doc["rows"], doc["cols"], doc["dates"]), images=len(scene.image_names),
        checkpoints=n_cp, dsm_range_m=scene.dsm_range_m,
        overlap_along_pct=tuple(g["overlap_pct"] for g in fig["along_track"]),
        overlap_across_pct=tuple(g["overlap_pct"] for g in fig["across_track"]),
        b_over_h=tuple(g["b_over_h"] for g in fig["stereo"]),
        flat_scene=(doc["flat_scene"] or {}).get("scene"), errors=doc["errors"])

