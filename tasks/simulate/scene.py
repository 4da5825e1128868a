"""Tasks of the scene simulator: scene, truth surface, radiance, rendering, check points (the
reference and the lidar, its surveys, are :mod:`tasks.simulate.survey`'s, named here too).

Every raster is computed block by block with Dask from the deterministic functions of
:mod:`core.simulation` (no full-scene array), written as COG through a temporary file.
The per-block functions only slice, call one core function and return arrays; reading
raster windows, projections (pyproj) and writing stay here, the scene folder's layout and the
reading of the DEM the world stands on are in :mod:`tasks.simulate.io`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import lru_cache, partial
from pathlib import Path

import dask.array as darr
import laspy
import numpy as np
import rasterio
from prefect import task
from rasterio.rpc import RPC

from core.errors import InputError, InsufficientDataError
from core.geodesy import utm_epsg
from core.jsonio import parse_json
from core.points import CheckPoint, CheckPointSet, GeoPoint
from core.sensors.pushbroom import PushbroomModel
from core.sensors.rpcfit import fit_rpc
from core.sensors.spot import spot_scene_from_model
from core.simulation.checkpoints import select_checkpoints
from core.simulation.hashing import derive_seed
from core.simulation.landcover import LandCover
from core.simulation.raycast import ray_levels
from core.simulation.realistic import metadata_scene
from core.simulation.render import ground_radiance, render_dn
from core.simulation.scene import (
    PRESETS,
    ErrorConfig,
    SceneDef,
    TruthGrid,
    check_window_covers,
    dem_window,
    footprint_points,
    scene_models,
    terrain_levels,
)
from core.simulation.surface import sample_surface
from tasks.io.crs import Projection
from tasks.io.dem import dem_datum
from tasks.io.dimap import write_dimap
from tasks.io.geoid import load_geoid
from tasks.io.rasters import (
    CHUNK,
    CogItem,
    CogOptions,
    atomic_write_json,
    atomic_write_text,
    open_raster,
    read_surface_window,
    read_window,
    write_arrays_cog,
)
from tasks.simulate.io import (
    ScenePaths,
    check_dem,
    products_exist,
    read_dem_window,
    surface_spec,
)
from tasks.simulate.survey import lidar_bounds, make_lidar, make_reference  # noqa: F401

NOISE_DN = {8: 1.0, 12: 6.0}


@lru_cache(maxsize=8)
def _model(text: str) -> PushbroomModel:
    return PushbroomModel.from_json(text)


# ---------------------------------------------------------------------------- A. scene


def check_world_options(preset_name: str, relief_factor: float, date_change: float,
                        bits: int) -> None:
    """InputError, in one line, on a preset or a world setting the simulator cannot make."""
    if preset_name not in PRESETS:
        raise InputError(f"unknown preset {preset_name!r}; choose one of {sorted(PRESETS)}")
    if not 0 < relief_factor <= 10:
        raise InputError(f"--relief-factor must be in (0, 10], got {relief_factor}")
    if not 0 <= date_change <= 1:
        raise InputError(f"--date-change must be a fraction in [0, 1], got {date_change}")
    if bits not in (8, 12):
        raise InputError(f"--bits must be 8 or 12, got {bits}")


def world_centre(dem: Path, centre_lonlat: tuple[float, float] | None) -> tuple[float, float]:
    """The centre asked for, else the DEM's (which is checked first)."""
    check_dem(dem)
    if centre_lonlat is None:
        with rasterio.open(dem) as src:
            b = src.bounds
        centre_lonlat = (0.5 * (b.left + b.right), 0.5 * (b.bottom + b.top))
    return float(centre_lonlat[0]), float(centre_lonlat[1])


def earlier_scene(paths: ScenePaths, scene: SceneDef) -> SceneDef | None:
    """The scene an earlier run wrote in ``paths`` when it is ``scene`` (resume), None when
    there is none; InputError when it is another one."""
    if not paths.scene_json.exists():
        return None
    try:
        old = SceneDef.from_json(paths.scene_json.read_text())
    except InputError as exc:
        raise InputError(f"{paths.scene_json} is unreadable ({exc}); remove {paths.root} "
                         "or choose another --out") from exc
    if replace(old, dsm_range_m=None).to_json() == scene.to_json():
        return old
    raise InputError(f"{paths.root} already holds a different simulated scene; choose another "
                     "--out or remove that folder")


@task(name="define-scene")
def define_scene(
    dem: Path, out: Path, preset_name: str, seed: int, errors: ErrorConfig,
    relief_factor: float = 1.0, bits: int = 8, date_change: float = 0.0,
    centre_lonlat: tuple[float, float] | None = None, dem_vertical: str = "auto",
) -> SceneDef:
    """Choose the scene, build truth and delivered models, save them with scene.json; the
    DEM's heights are read in the datum the one rule gives (:func:`tasks.io.dem.dem_datum`,
    ``dem_vertical`` as ``--dem-vertical``)."""
    check_world_options(preset_name, relief_factor, date_change, bits)
    preset = PRESETS[preset_name]
    paths = ScenePaths(Path(out))
    dem = Path(dem)
    clon, clat = world_centre(dem, centre_lonlat)
    datum = dem_datum(dem, dem_vertical, what="DEM", option="--dem-vertical")
    H, tr, window = read_dem_window(dem, dem_window(preset, clon, clat), datum.datum)
    levels = terrain_levels(H, tr, load_geoid(), clon, clat, relief_factor)
    centre = GeoPoint(clon, clat, levels.h_centre_m)
    models = scene_models(preset, centre, errors, seed)
    lon, lat = footprint_points([m.truth for m in models.values()], levels.h_lo_m, levels.h_hi_m)
    check_window_covers(window, lon, lat, dem.name)
    epsg = utm_epsg(clon, clat)
    x, y = Projection(epsg).to_xy(lon, lat)
    res = preset.truth_res_m
    scene = SceneDef(
        preset=preset_name, seed=int(seed), dem_path=str(dem.resolve()), dem_window=window,
        relief_factor=float(relief_factor), H_ref_m=levels.H_ref_m, centre=centre, epsg=epsg,
        grid=TruthGrid.covering(x, y, res, 10 * res), water_level_m=levels.water_level_m,
        bits=int(bits), date_change=float(date_change), errors=errors,
        image_names=tuple(models), injected={n: m.injected for n, m in models.items()},
        dem_vertical=datum.datum, dem_vertical_source=datum.source,
    )
    old = earlier_scene(paths, scene)
    if old is not None:
        return old  # same scene: resume, keep the products already made
    paths.truth.mkdir(parents=True, exist_ok=True)
    for n, m in models.items():
        atomic_write_text(paths.truth_model(n), m.truth.to_json(indent=1))
        atomic_write_text(paths.delivered(n), m.delivered.to_json(indent=1))
    atomic_write_text(paths.scene_json, scene.to_json())
    return SceneDef.from_json(scene.to_json())  # the same value a resumed run reads back


@task(name="spot-metadata")
def write_spot_metadata(scene: SceneDef, out: Path) -> tuple[Path, ...]:
    """Each delivered model also as SPOT Level 1A metadata (``DIR/<image>.DIM``, SPOT 1-4 style,
    or SPOT 5 style for the hrs preset), so the chain reads simulated scenes as archive ones."""
    paths = ScenePaths(Path(out))
    preset = scene.preset_spec
    for i, (name, spec) in enumerate(zip(scene.image_names, preset.images, strict=True)):
        if products_exist(paths.dimap(name)):
            continue
        delivered = PushbroomModel.from_json(paths.delivered(name).read_text())
        # realistic: the speeds stated as the satellite quantised them (the delivered model was
        # read from them, so this gives them back)
        write = metadata_scene if scene.errors.realistic else spot_scene_from_model
        spot = write(
            delivered, mission_index=preset.spot_mission, instrument=preset.spot_instrument,
            instrument_index=i + 1, dataset_name=(f"SIMULATED {scene.preset} {name} seed "
                                                  f"{scene.seed} (gcpfree simulate)"),
            sun_azimuth_deg=spec.sun_azimuth_deg, sun_elevation_deg=spec.sun_elevation_deg)
        write_dimap(spot, paths.dimap(name), image_name=paths.image(name).name)
    return tuple(paths.dimap(n) for n in scene.image_names)


# ---------------------------------------------------------------------------- B. truth surface


def truth_block(block: np.ndarray, scene: SceneDef, block_info: dict | None = None) -> np.ndarray:
    """(3, h, w) float32: DTM, DSM, land cover of one block of the truth grid."""
    (r0, r1), (c0, c1) = block_info[0]["array-location"][-2:]
    xx, yy = scene.grid.cell_centres(r0, r1, c0, c1)
    s = sample_surface(surface_spec(scene), xx, yy, Projection(scene.epsg).to_lonlat)
    return np.stack([s.dtm_m, s.dsm_m, s.classes.astype(np.float64)]).astype(np.float32)


def _georef(scene: SceneDef, **kw: object) -> CogOptions:
    return CogOptions(transform=scene.grid.geotransform(), crs=f"EPSG:{scene.epsg}", **kw)


@task(name="truth-surface")
def build_truth_surface(scene: SceneDef, out: Path) -> SceneDef:
    """Write the truth DTM, DSM (ellipsoidal, COG) and land cover; record the DSM range."""
    paths = ScenePaths(Path(out))
    if scene.dsm_range_m is not None and products_exist(paths.dtm, paths.dsm, paths.landcover):
        return scene
    surface_spec(scene)  # read the DEM once here, before the Dask threads need it
    base = darr.zeros(scene.grid.shape, chunks=CHUNK, dtype=np.float32)
    stack = darr.map_blocks(truth_block, base, scene=scene, new_axis=0,
                            chunks=((3,),) + base.chunks, dtype=np.float32)
    tags = {"vertical_datum": "WGS84 ellipsoid", "units": "m", "seed": str(scene.seed)}
    dsm = stack[1]
    with rasterio.Env(GDAL_CACHEMAX=SIM_CACHE_MB):
        lo, hi = write_arrays_cog(
            [
                CogItem(stack[0], paths.dtm, _georef(scene, nodata=np.nan, tags=tags)),
                CogItem(dsm, paths.dsm, _georef(scene, nodata=np.nan, tags=tags)),
                CogItem(stack[2].astype(np.uint8), paths.landcover,
                        _georef(scene, nodata=0, resampling="nearest",
                                tags={c.name: str(int(c)) for c in LandCover})),
            ],
            extra=[darr.nanmin(dsm), darr.nanmax(dsm)],
        )
    scene = replace(scene, dsm_range_m=(float(lo), float(hi)))
    atomic_write_text(paths.scene_json, scene.to_json())
    return scene


# ---------------------------------------------------------------------------- C. radiance


RADIANCE_HALO = 1  # cells around each block: the slopes of its edge cells
# GDAL's block cache while the simulator reads and writes its rasters (MB). GDAL's default is
# 5 % of the machine's memory (1.2 GB on 24 GB) and the radiance, rendering and truth stages
# read and write whole-scene rasters through it, so it filled with the scene (2.9 GB peak on
# hrg): bounded, memory stays that of the blocks in flight.
SIM_CACHE_MB = 128


def halo_cells(r0: int, r1: int, n: int, halo: int = RADIANCE_HALO) -> np.ndarray:
    """The grid indices of cells ``r0 - halo .. r1 + halo - 1`` along an axis of ``n`` cells,
    those beyond the grid repeating its edge cell (``map_overlap``'s ``boundary="nearest"``)."""
    return np.clip(np.arange(r0 - halo, r1 + halo), 0, n - 1)


def _read_halo(path: str, r0: int, r1: int, c0: int, c1: int, nan_masked: bool,
               halo: int = RADIANCE_HALO) -> np.ndarray:
    """Cells ``[r0, r1) x [c0, c1)`` of a raster with ``halo`` cells around them, the edge
    repeated beyond the raster; float64 with NaN for nodata when ``nan_masked``, else raw."""
    with open_raster(path, "truth raster") as src:
        rows, cols = halo_cells(r0, r1, src.height, halo), halo_cells(c0, c1, src.width, halo)
        box = (int(cols[0]), int(rows[0]), int(cols[-1]) + 1, int(rows[-1]) + 1)
        part = read_window(src, box, nan_masked=nan_masked, what="truth raster")
    return part[np.ix_(rows - rows[0], cols - cols[0])]


@dataclass(frozen=True)
class DateLight:
    """The sun of one date and how much of the ground has changed since the first date
    (``change``), in the pattern ``change_seed`` draws."""

    sun_azimuth_deg: float
    sun_elevation_deg: float
    change: float
    change_seed: int


def date_light(scene: SceneDef, image_index: int) -> DateLight:
    """A pair's date: its image's sun; the second date changed by ``scene.date_change``."""
    sun = scene.preset_spec.images[image_index]
    return DateLight(sun.sun_azimuth_deg, sun.sun_elevation_deg,
                     scene.date_change if image_index == 1 else 0.0, scene.seed)


def radiance_block(block: np.ndarray, scene: SceneDef, light: DateLight, dsm_path: str,
                   landcover_path: str, block_info: dict | None = None) -> np.ndarray:
    """Ground radiance of one block of the truth grid: its DSM and land cover read from the
    truth rasters with a one-cell halo (the slopes at its edge), at the grid's own cells."""
    (r0, r1), (c0, c1) = block_info[None]["array-location"]
    h = RADIANCE_HALO
    dsm = _read_halo(dsm_path, r0, r1, c0, c1, nan_masked=True)
    classes = _read_halo(landcover_path, r0, r1, c0, c1, nan_masked=False)
    xx, yy = scene.grid.cell_centres(r0 - h, r1 + h, c0 - h, c1 + h)
    rad = ground_radiance(xx, yy, classes, dsm, scene.grid.res_m, light.sun_azimuth_deg,
                          light.sun_elevation_deg, scene.seed, light.change,
                          change_seed=light.change_seed)
    return rad[h:-h, h:-h].astype(np.float32)


def radiance(scene: SceneDef, date: int | DateLight, dsm_path: Path, landcover_path: Path,
             chunks: int | tuple[int, int] | None = None) -> darr.Array:
    """The ground radiance of one date (a pair's image index, or its light) over the truth
    grid (the DSM raster's shape), a Dask array of ``chunks`` (default :data:`CHUNK`) whose
    blocks each read their own cells (no block waits for another: memory holds the blocks in
    flight, whatever the scene's size)."""
    light = date if isinstance(date, DateLight) else date_light(scene, date)
    with open_raster(dsm_path, "truth DSM") as src:
        shape = (src.height, src.width)
    base = darr.zeros(shape, chunks=chunks or CHUNK, dtype=np.float32)
    return darr.map_blocks(radiance_block, base, scene=scene, light=light,
                           dsm_path=str(dsm_path), landcover_path=str(landcover_path),
                           dtype=np.float32)


def write_radiance(scene: SceneDef, paths: ScenePaths, date: int | DateLight,
                   target: Path) -> Path:
    """The ground radiance of one date on the truth grid, written to ``target`` (COG, kept
    for reruns)."""
    if products_exist(target):
        return target
    rad = radiance(scene, date, paths.dsm, paths.landcover)
    with rasterio.Env(GDAL_CACHEMAX=SIM_CACHE_MB):
        write_arrays_cog([CogItem(rad, target, _georef(scene, nodata=np.nan))])
    return target


@task(name="radiance")
def build_radiance(scene: SceneDef, out: Path, image_index: int) -> Path:
    """The ground radiance of one date of a pair on the truth grid (COG, kept for reruns)."""
    paths = ScenePaths(Path(out))
    return write_radiance(scene, paths, image_index,
                          paths.radiance(scene.image_names[image_index]))


# ---------------------------------------------------------------------------- D. rendering


def render_block(block: np.ndarray, scene: SceneDef, model_json: str, noise_seed: int,
                 dsm_path: str, radiance_path: str, block_info: dict | None = None) -> np.ndarray:
    """DN of one image block (:func:`core.simulation.render.render_dn`)."""
    (r0, r1), (c0, c1) = block_info[0]["array-location"]
    return render_dn(
        _model(model_json), np.arange(r0, r1), np.arange(c0, c1), ray_levels(scene.dsm_range_m),
        Projection(scene.epsg).to_xy, partial(read_surface_window, dsm_path),
        partial(read_surface_window, radiance_path), NOISE_DN[scene.bits], scene.bits,
        noise_seed,
    )


@dataclass(frozen=True)
class RenderJob:
    """One image to render: its name (its models' and file's, where the paths put them), its
    date's radiance and the seed of its sensor noise."""

    name: str
    radiance_path: Path
    noise_seed: int


def _image_item(scene: SceneDef, paths: ScenePaths, job: RenderJob) -> CogItem:
    """The image's DN, tile by tile, as a COG item with the RPC of its delivered metadata."""
    truth_json = paths.truth_model(job.name).read_text()
    delivered = PushbroomModel.from_json(paths.delivered(job.name).read_text())
    truth = _model(truth_json)
    dtype = np.uint8 if scene.bits == 8 else np.uint16
    base = darr.zeros((truth.n_rows, truth.n_cols), chunks=CHUNK, dtype=dtype)
    img = darr.map_blocks(
        render_block, base, scene=scene, model_json=truth_json, noise_seed=job.noise_seed,
        dsm_path=str(paths.dsm), radiance_path=str(job.radiance_path), dtype=dtype,
    )
    lo, hi = scene.dsm_range_m
    rpc, report = fit_rpc(delivered, truth.n_cols, truth.n_rows, (lo - 100.0, hi + 100.0))
    tags = {"rpc_fit_max_px": f"{report.max_px:.2e}", "rpc_fit_rms_px": f"{report.rms_px:.2e}",
            "metadata": paths.delivered(job.name).name, "seed": str(scene.seed)}
    return CogItem(img, paths.image(job.name), CogOptions(
        rpcs=RPC.from_gdal(rpc.to_gdal_tags()), nodata=0, tags=tags))


def render_images(scene: SceneDef, paths: ScenePaths, jobs: list[RenderJob]) -> list[Path]:
    """Render the images (each on its truth model and its date's radiance) in one pass of
    tiles, so that small images render side by side, and write each with the RPC of its
    delivered metadata, where ``paths`` put them; images made earlier are kept."""
    todo = [j for j in jobs if not products_exist(paths.image(j.name))]
    if todo:
        with rasterio.Env(GDAL_CACHEMAX=SIM_CACHE_MB):
            write_arrays_cog([_image_item(scene, paths, j) for j in todo])
    return [paths.image(j.name) for j in jobs]


@task(name="render-image")
def render_image(scene: SceneDef, out: Path, image_index: int) -> Path:
    """Render one image of a pair tile by tile and write it with the RPC of its delivered
    metadata."""
    paths = ScenePaths(Path(out))
    name = scene.image_names[image_index]
    return render_images(scene, paths, [RenderJob(
        name, paths.radiance(name), derive_seed(scene.seed, "sensor-noise", image_index))])[0]


# ---------------------------------------------------------------------------- E. check points


@task(name="check-points")
def make_checkpoints(scene: SceneDef, out: Path, n_wanted: int = 100) -> Path:
    """Independent check points on bare soil, visible in both images, with true image coords."""
    return write_checkpoints(scene, ScenePaths(Path(out)), select_checkpoints, "checkpoints",
                             n_wanted, 50, "in the overlap", "scene")


def write_checkpoints(scene: SceneDef, paths: ScenePaths, select: Callable[..., list[CheckPoint]],
                      seed_label: str, n_wanted: int, needed: int, where: str, world: str
                      ) -> Path:
    """``paths.checkpoints``: the points ``select`` (:mod:`core.simulation.checkpoints`) finds
    through the truth models and DSM, drawn from the seed ``seed_label``; fewer than ``needed``
    is an InsufficientDataError saying ``where`` they were looked for. Kept when made earlier."""
    if products_exist(paths.checkpoints):
        return paths.checkpoints
    models = {
        n: PushbroomModel.from_json(paths.truth_model(n).read_text()) for n in scene.image_names}
    proj = Projection(scene.epsg)
    points = select(
        surface_spec(scene), models, scene.grid,
        np.random.default_rng(derive_seed(scene.seed, seed_label)), proj.to_lonlat, proj.to_xy,
        partial(read_surface_window, paths.dsm), ray_levels(scene.dsm_range_m),
        n_wanted=n_wanted)
    if len(points) < needed:
        raise InsufficientDataError(
            f"only {len(points)} visible bare-soil check points found {where} ({needed} "
            f"needed); the {world} is mostly water, forest or town: choose another --center")
    doc = CheckPointSet(f"EPSG:{scene.epsg}", scene.image_names, tuple(points))
    atomic_write_json(paths.checkpoints, doc.to_dict())
    return paths.checkpoints


@dataclass(frozen=True)
class SimulationSummary:
    """What ``simulate`` made, for printing."""

    out: str
    preset: str
    seed: int
    centre_error_m: dict[str, float]
    images: tuple[str, ...]
    checkpoints: int
    lidar_points: int
    dsm_range_m: tuple[float, float]
    errors: str = "simple"

    def lines(self) -> list[str]:
        errs = ", ".join(f"{k} {v:.1f} m" for k, v in self.centre_error_m.items())
        return [
            (f"simulated scene  {self.out} (preset {self.preset}, seed {self.seed}, "
             f"{self.errors} errors)"),
            f"images           {', '.join(self.images)} (RPC tags inside, metadata .json beside)",
            f"metadata error   at the scene centre: {errs}",
            (f"truth            DSM/DTM {self.dsm_range_m[0]:.0f}..{self.dsm_range_m[1]:.0f} m "
             f"ellipsoidal, {self.checkpoints} check points, {self.lidar_points} lidar points"),
        ]


@task(name="summarize-scene")
def summarize(scene: SceneDef, out: Path) -> SimulationSummary:
    paths = ScenePaths(Path(out))
    n_cp = len(parse_json(paths.checkpoints.read_text(), str(paths.checkpoints))["points"])
    n_lidar = 0
    if paths.lidar.exists():
        with laspy.open(paths.lidar) as f:
            n_lidar = int(f.header.point_count)
    return SimulationSummary(
        out=str(paths.root), preset=scene.preset, seed=scene.seed,
        centre_error_m={k: v.centre_error_m for k, v in scene.injected.items()},
        images=tuple(str(paths.image(n)) for n in scene.image_names), checkpoints=n_cp,
        lidar_points=n_lidar, dsm_range_m=scene.dsm_range_m,
        errors="realistic" if scene.errors.realistic else "simple",
    )
