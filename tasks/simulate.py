"""Tasks of the scene simulator: truth surface, radiance, rendering, check points, lidar.

Every raster is computed block by block with Dask from the deterministic functions of
:mod:`core.simulation` (no full-scene array), written as COG through a temporary file.
The per-block functions only slice, transform coordinates, call core and return arrays.
"""

from __future__ import annotations

import json
import threading
from dataclasses import asdict, dataclass, field, replace
from datetime import date
from functools import lru_cache
from pathlib import Path
from typing import Any

import dask.array as darr
import laspy
import numpy as np
import pyproj
import rasterio
import rioxarray
from affine import Affine
from prefect import task
from rasterio.fill import fillnodata
from rasterio.rpc import RPC
from rasterio.windows import Window, from_bounds
from scipy.ndimage import map_coordinates

from core.dem import GeoDEM
from core.errors import InputError
from core.sensors.pushbroom import PushbroomModel
from core.sensors.rpcfit import fit_rpc
from core.simulation.hashing import derive_seed
from core.simulation.landcover import LandCover, LandCoverConfig, water_level_for_fraction
from core.simulation.lidar import LidarConfig, lidar_points, lidar_returns
from core.simulation.raycast import Rays, SurfaceGrid, first_hit
from core.simulation.render import (
    ChangeKind,
    apply_date_change,
    date_change_kind,
    date_change_weight,
    hillshade,
    radiance_to_dn,
    texture,
)
from core.simulation.scene import PRESETS, ErrorConfig, Preset, delivered_model, truth_model
from core.simulation.surface import SurfaceSpec, sample_surface
from tasks.geoid import load_geoid
from tasks.raster_io import atomic_write_text, write_arrays_cog

CHUNK = 1024
COL_STEP = 8  # lines of sight are localised every COL_STEP columns and interpolated
NOISE_DN = {8: 1.0, 12: 6.0}
DEM_MARGIN_DEG = 0.02


@dataclass(frozen=True)
class SceneDef:
    """Everything later steps need, saved as DIR/truth/scene.json."""

    preset: str
    seed: int
    dem_path: str
    dem_window: tuple[float, float, float, float]  # lon_min, lat_min, lon_max, lat_max read
    relief_factor: float
    H_ref_m: float  # relief is scaled around this orthometric height
    centre: tuple[float, float, float]  # lon, lat, ellipsoidal h
    epsg: int  # UTM zone of the truth grids
    grid: tuple[float, float, float, int, int]  # x_left, y_top, res_m, width, height
    water_level_m: float | None
    bits: int
    date_change: float
    errors: dict[str, Any]
    image_names: tuple[str, str]
    dsm_range_m: tuple[float, float] | None = None
    injected: dict[str, Any] = field(default_factory=dict)

    @property
    def preset_obj(self) -> Preset:
        return PRESETS[self.preset]

    @property
    def transform(self) -> Affine:
        x0, y0, res, _, _ = self.grid
        return Affine(res, 0.0, x0, 0.0, -res, y0)

    @property
    def shape(self) -> tuple[int, int]:
        return int(self.grid[4]), int(self.grid[3])

    def to_json(self) -> str:
        return json.dumps(asdict(self), indent=1)

    @classmethod
    def from_json(cls, text: str) -> SceneDef:
        d = json.loads(text)
        for k in ("dem_window", "centre", "grid", "image_names", "dsm_range_m"):
            if d.get(k) is not None:
                d[k] = tuple(d[k])
        return cls(**d)


@dataclass(frozen=True)
class ScenePaths:
    """Where the products of a simulated scene live."""

    root: Path

    @property
    def truth(self) -> Path:
        return self.root / "truth"

    @property
    def work(self) -> Path:
        return self.root / "work"

    @property
    def scene_json(self) -> Path:
        return self.truth / "scene.json"

    def image(self, name: str) -> Path:
        return self.root / f"{name}.tif"

    def delivered(self, name: str) -> Path:
        return self.root / f"{name}.json"

    def truth_model(self, name: str) -> Path:
        return self.truth / f"{name}_truth.json"

    def radiance(self, name: str) -> Path:
        return self.work / f"radiance_{name}.tif"

    @property
    def dsm(self) -> Path:
        return self.truth / "dsm.tif"

    @property
    def dtm(self) -> Path:
        return self.truth / "dtm.tif"

    @property
    def landcover(self) -> Path:
        return self.truth / "landcover.tif"

    @property
    def checkpoints(self) -> Path:
        return self.truth / "checkpoints.json"

    @property
    def lidar(self) -> Path:
        return self.truth / "lidar.laz"


# ---------------------------------------------------------------------------- coordinates

_local = threading.local()


def _transformer(epsg: int, inverse: bool) -> pyproj.Transformer:
    """A per-thread cached UTM <-> lon/lat transformer."""
    cache = _local.__dict__.setdefault("tr", {})
    key = (epsg, inverse)
    if key not in cache:
        src, dst = (f"EPSG:{epsg}", "EPSG:4326") if inverse else ("EPSG:4326", f"EPSG:{epsg}")
        cache[key] = pyproj.Transformer.from_crs(src, dst, always_xy=True)
    return cache[key]


def to_lonlat(epsg: int):
    def f(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        lon, lat = _transformer(epsg, True).transform(x, y)
        return np.asarray(lon), np.asarray(lat)
    return f


def to_xy(epsg: int, lon: np.ndarray, lat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    x, y = _transformer(epsg, False).transform(lon, lat)
    return np.asarray(x), np.asarray(y)


def utm_epsg(lon: float, lat: float) -> int:
    zone = int((lon + 180.0) // 6.0) % 60 + 1
    return (32600 if lat >= 0 else 32700) + zone


# ---------------------------------------------------------------------------- the DEM


def _read_dem_window(path: Path, window_deg: tuple[float, float, float, float] | None):
    """(H array float64 NaN voids, transform, bounds) of a geographic DEM, optionally a window."""
    try:
        src = rasterio.open(path)
    except rasterio.errors.RasterioIOError as exc:
        raise InputError(f"cannot read DEM {path}: {exc}; give a GeoTIFF or .hgt file") from exc
    with src:
        if src.crs is None or not src.crs.is_geographic:
            raise InputError(
                f"DEM {path} is not in geographic coordinates (CRS {src.crs}); reproject it "
                "to EPSG:4326 (e.g. gdalwarp -t_srs EPSG:4326)"
            )
        win = None
        if window_deg is not None:
            win = from_bounds(*window_deg, transform=src.transform).round_offsets().round_lengths()
            win = win.intersection(Window(0, 0, src.width, src.height))
        H = src.read(1, window=win, masked=True).astype(np.float64).filled(np.nan)
        tr = src.window_transform(win) if win is not None else src.transform
        bounds = src.bounds
    H[H <= -1000] = np.nan  # SRTM voids (-32768) when no nodata is declared
    voids = np.isnan(H)
    if voids.any() and not voids.all():
        # the simulated world has no holes: fill voids by GDAL's inverse-distance fill
        H = fillnodata(H, mask=(~voids).astype(np.uint8), max_search_distance=max(H.shape),
                       smoothing_iterations=0)
    return H, tr, bounds


def check_dem(path: Path) -> None:
    """Fail early, in one line, on a DEM that cannot serve the simulator."""
    path = Path(path)
    if not path.exists():
        raise InputError(f"DEM {path} does not exist; give a GeoTIFF (EPSG:4326) or .hgt file")
    try:
        with rasterio.open(path) as src:
            crs = src.crs
    except rasterio.errors.RasterioIOError as exc:
        raise InputError(f"cannot read DEM {path}: {exc}; give a GeoTIFF or .hgt file") from exc
    if crs is None or not crs.is_geographic:
        raise InputError(
            f"DEM {path} is not in geographic coordinates (CRS {crs}); reproject it to "
            "EPSG:4326 (e.g. gdalwarp -t_srs EPSG:4326)"
        )


@lru_cache(maxsize=4)
def load_surface_spec(scene_json: str) -> SurfaceSpec:
    """The truth-surface definition of a scene (reads its DEM window once per process)."""
    scene = SceneDef.from_json(scene_json)
    H, tr, _ = _read_dem_window(Path(scene.dem_path), scene.dem_window)
    H = scene.H_ref_m + scene.relief_factor * (H - scene.H_ref_m)
    preset = scene.preset_obj
    return SurfaceSpec(
        dem_H=GeoDEM.from_transform(H, tuple(tr)[:6]),
        geoid=load_geoid(),
        seed=scene.seed,
        landcover=LandCoverConfig(water_level_m=scene.water_level_m),
        detail_amplitude_m=3.0 * scene.relief_factor,
        detail_min_wavelength_m=2.0 * preset.truth_res_m,
    )


def _spec(scene: SceneDef) -> SurfaceSpec:
    return load_surface_spec(scene.to_json())


# ---------------------------------------------------------------------------- A. scene


def _footprint_lonlat(model: PushbroomModel, h_lo: float, h_hi: float) -> tuple[np.ndarray, np.ndarray]:
    n = 21
    c = np.linspace(0, model.n_cols - 1, n)
    r = np.linspace(0, model.n_rows - 1, n)
    border_c = np.concatenate([c, c, np.zeros(n), np.full(n, model.n_cols - 1)])
    border_r = np.concatenate([np.zeros(n), np.full(n, model.n_rows - 1), r, r])
    lons, lats = [], []
    for h in (h_lo, h_hi):
        lo, la = model.localize(border_c, border_r, np.full(border_c.shape, h))
        lons.append(lo)
        lats.append(la)
    return np.concatenate(lons), np.concatenate(lats)


@task(name="define-scene")
def define_scene(
    dem: Path, out: Path, preset_name: str, seed: int, errors: ErrorConfig,
    relief_factor: float = 1.0, bits: int = 8, date_change: float = 0.0,
    centre_lonlat: tuple[float, float] | None = None,
) -> SceneDef:
    """Choose the scene, build truth and delivered models, save them with scene.json."""
    if preset_name not in PRESETS:
        raise InputError(f"unknown preset {preset_name!r}; choose one of {sorted(PRESETS)}")
    if not 0 < relief_factor <= 10:
        raise InputError(f"--relief-factor must be in (0, 10], got {relief_factor}")
    if not 0 <= date_change <= 1:
        raise InputError(f"--date-change must be a fraction in [0, 1], got {date_change}")
    if bits not in (8, 12):
        raise InputError(f"--bits must be 8 or 12, got {bits}")
    preset = PRESETS[preset_name]
    paths = ScenePaths(Path(out))
    dem = Path(dem)
    check_dem(dem)
    with rasterio.open(dem) as src:
        bounds = src.bounds
    if centre_lonlat is None:
        centre_lonlat = (0.5 * (bounds.left + bounds.right), 0.5 * (bounds.bottom + bounds.top))
    clon, clat = map(float, centre_lonlat)
    # read a window large enough for both footprints (grown below if too small)
    half_m = 0.5 * max(preset.n_cols, preset.n_rows) * preset.gsd_m * 1.6 + 3000.0
    half_lat = half_m / 110_574.0
    half_lon = half_m / (111_320.0 * np.cos(np.radians(clat)))
    window = (clon - half_lon, clat - half_lat, clon + half_lon, clat + half_lat)
    H, tr, _ = _read_dem_window(dem, window)
    window = (tr.c, tr.f + tr.e * H.shape[0], tr.c + tr.a * H.shape[1], tr.f)
    if np.isnan(H).all():
        raise InputError(f"DEM {dem} has no valid height around {clon:.4f}, {clat:.4f}")
    H_ref = float(np.nanmedian(H))
    Hs = H_ref + relief_factor * (H - H_ref)
    geoid = load_geoid()
    demH = GeoDEM.from_transform(Hs, tuple(tr)[:6])
    h_centre = float(demH.height_m(clon, clat) + geoid.undulation_m(clon, clat))
    if not np.isfinite(h_centre):
        raise InputError(f"the scene centre {clon:.4f}, {clat:.4f} falls on a DEM void or "
                         "outside the DEM; choose another --center")
    rows, cols = np.mgrid[0 : H.shape[0], 0 : H.shape[1]]
    node_lon = tr.c + (cols + 0.5) * tr.a
    node_lat = tr.f + (rows + 0.5) * tr.e
    h_nodes = Hs + geoid.undulation_m(node_lon, node_lat)
    h_lo = float(np.nanmin(h_nodes)) - 20.0
    h_hi = float(np.nanmax(h_nodes)) + 60.0  # canopy, buildings, detail
    water = water_level_for_fraction(h_nodes, 0.02)

    names = tuple(s.name for s in preset.images)
    truths, delivered, injected = {}, {}, {}
    for spec in preset.images:
        rng = np.random.default_rng(derive_seed(seed, "geometry", spec.name))
        t = truth_model(spec, preset, (clon, clat, h_centre), errors, rng)
        d, inj = delivered_model(t, preset, errors, rng, h_centre)
        truths[spec.name], delivered[spec.name], injected[spec.name] = t, d, inj.to_dict()

    lons, lats = zip(*(_footprint_lonlat(m, h_lo, h_hi) for m in truths.values()))
    lon_all, lat_all = np.concatenate(lons), np.concatenate(lats)
    need = (lon_all.min(), lat_all.min(), lon_all.max(), lat_all.max())
    if (need[0] < window[0] - 1e-9 or need[1] < window[1] - 1e-9
            or need[2] > window[2] + 1e-9 or need[3] > window[3] + 1e-9):
        raise InputError(
            f"the DEM does not cover the simulated scene: it needs lon {need[0]:.4f}..{need[2]:.4f}, "
            f"lat {need[1]:.4f}..{need[3]:.4f} but {dem.name} gives lon {window[0]:.4f}.."
            f"{window[2]:.4f}, lat {window[1]:.4f}..{window[3]:.4f}; use a larger DEM, a smaller "
            "preset or another --center"
        )
    epsg = utm_epsg(clon, clat)
    x, y = to_xy(epsg, lon_all, lat_all)
    res = preset.truth_res_m
    margin = 10 * res
    x0 = np.floor((x.min() - margin) / res) * res
    y1 = np.ceil((y.max() + margin) / res) * res
    width = int(np.ceil((x.max() + margin - x0) / res))
    height = int(np.ceil((y1 - (y.min() - margin)) / res))

    scene = SceneDef(
        preset=preset_name, seed=int(seed), dem_path=str(dem.resolve()),
        dem_window=tuple(float(v) for v in window), relief_factor=float(relief_factor),
        H_ref_m=H_ref, centre=(clon, clat, h_centre), epsg=epsg,
        grid=(float(x0), float(y1), float(res), width, height),
        water_level_m=float(water), bits=int(bits), date_change=float(date_change),
        errors=asdict(errors), image_names=names, injected=injected,
    )
    if paths.scene_json.exists():
        try:
            old = SceneDef.from_json(paths.scene_json.read_text())
        except (ValueError, TypeError) as exc:
            raise InputError(f"{paths.scene_json} is unreadable ({exc}); remove {paths.root} "
                             "or choose another --out") from exc
        if replace(old, dsm_range_m=None).to_json() == scene.to_json():
            return old  # same scene: resume, keep the products already made
        raise InputError(
            f"{paths.root} already holds a different simulated scene; choose another --out "
            "or remove that folder"
        )
    paths.truth.mkdir(parents=True, exist_ok=True)
    for n in names:
        atomic_write_text(paths.truth_model(n), truths[n].to_json(indent=1))
        atomic_write_text(paths.delivered(n), delivered[n].to_json(indent=1))
    atomic_write_text(paths.scene_json, scene.to_json())
    return SceneDef.from_json(scene.to_json())  # the same value a resumed run reads back


# ---------------------------------------------------------------------------- B. truth surface


def truth_block(block: np.ndarray, scene: SceneDef, block_info: dict | None = None) -> np.ndarray:
    """(3, h, w) float32: DTM, DSM, land cover of one block of the truth grid."""
    (r0, r1), (c0, c1) = block_info[0]["array-location"][-2:]
    x0, y0, res, _, _ = scene.grid
    x = x0 + (np.arange(c0, c1) + 0.5) * res
    y = y0 - (np.arange(r0, r1) + 0.5) * res
    xx, yy = np.meshgrid(x, y)
    s = sample_surface(_spec(scene), xx, yy, to_lonlat(scene.epsg))
    return np.stack([s.dtm_m, s.dsm_m, s.classes.astype(np.float64)]).astype(np.float32)


@task(name="truth-surface")
def build_truth_surface(scene: SceneDef, out: Path) -> SceneDef:
    """Write the truth DTM, DSM (ellipsoidal, COG) and land cover; record the DSM range."""
    paths = ScenePaths(Path(out))
    if scene.dsm_range_m is not None and _exist(paths.dtm, paths.dsm, paths.landcover):
        return scene
    shape = scene.shape
    base = darr.zeros(shape, chunks=CHUNK, dtype=np.float32)
    stack = darr.map_blocks(truth_block, base, scene=scene, new_axis=0,
                            chunks=((3,),) + base.chunks, dtype=np.float32)
    crs = f"EPSG:{scene.epsg}"
    kw = {"transform": scene.transform, "crs": crs}
    tags = {"vertical_datum": "WGS84 ellipsoid", "units": "m", "seed": str(scene.seed)}
    dsm = stack[1]
    lo, hi = write_arrays_cog(
        [
            (stack[0], paths.dtm, dict(kw, nodata=np.nan, tags=tags)),
            (dsm, paths.dsm, dict(kw, nodata=np.nan, tags=tags)),
            (stack[2].astype(np.uint8), paths.landcover,
             dict(kw, nodata=0, resampling="nearest",
                  tags={c.name: str(int(c)) for c in LandCover})),
        ],
        extra=[darr.nanmin(dsm), darr.nanmax(dsm)],
    )
    scene = replace(scene, dsm_range_m=(float(lo), float(hi)))
    atomic_write_text(paths.scene_json, scene.to_json())
    return scene


def _exist(*paths: Path) -> bool:
    """Products of an earlier run of the same scene (written atomically, so complete)."""
    return all(p.exists() for p in paths)


# ---------------------------------------------------------------------------- C. radiance


def radiance_block(dsm: np.ndarray, classes: np.ndarray, scene: SceneDef, image_index: int,
                   block_info: dict | None = None) -> np.ndarray:
    """Ground radiance (reflectance x illumination) of one block with its 1-cell halo."""
    (r0, r1), (c0, c1) = block_info[0]["array-location"][-2:]
    x0, y0, res, _, _ = scene.grid
    spec = scene.preset_obj.images[image_index]
    # the block arrives with a 1-cell halo (map_overlap, boundary "nearest")
    x = x0 + (np.arange(c0 - 1, c1 - 1) + 0.5) * res
    y = y0 - (np.arange(r0 - 1, r1 - 1) + 0.5) * res
    xx, yy = np.meshgrid(x, y)
    dem = np.where(np.isfinite(dsm), dsm, np.nanmean(dsm) if np.isfinite(dsm).any() else 0.0)
    shade = hillshade(dem, res, -res, spec.sun_azimuth_deg, spec.sun_elevation_deg)
    cls = classes.astype(np.uint8)
    refl = texture(xx, yy, cls, scene.seed)
    if image_index == 1 and scene.date_change > 0:
        w = date_change_weight(xx, yy, derive_seed(scene.seed, "date-change"), scene.date_change)
        kind = date_change_kind(xx, yy, derive_seed(scene.seed, "date-change-kind"))
        refl = apply_date_change(refl, w, kind)
        cloud = w * (kind == ChangeKind.CLOUD)
        shade = shade * (1 - cloud) + cloud  # clouds are not shaded by the terrain below
    ambient = 0.2
    return (refl * (ambient + (1 - ambient) * shade)).astype(np.float32)


@task(name="radiance")
def build_radiance(scene: SceneDef, out: Path, image_index: int) -> Path:
    paths = ScenePaths(Path(out))
    name = scene.image_names[image_index]
    if _exist(paths.radiance(name)):
        return paths.radiance(name)
    dsm = rioxarray.open_rasterio(paths.dsm, chunks=CHUNK, masked=True).squeeze("band", drop=True)
    cls = rioxarray.open_rasterio(paths.landcover, chunks=CHUNK).squeeze("band", drop=True)
    rad = darr.map_overlap(
        radiance_block, dsm.data.astype(np.float64), cls.data, depth=1, boundary="nearest",
        dtype=np.float32, scene=scene, image_index=image_index, trim=True,
    )
    write_arrays_cog([(rad, paths.radiance(name), {"transform": scene.transform,
                                                   "crs": f"EPSG:{scene.epsg}", "nodata": np.nan})])
    return paths.radiance(name)


# ---------------------------------------------------------------------------- D. rendering


def _rays(model: PushbroomModel, rows: np.ndarray, cols: np.ndarray, epsg: int,
          levels: tuple[float, float, float]) -> Rays:
    """Lines of sight of an image block, localised every COL_STEP columns and interpolated."""
    sub = np.unique(np.concatenate([cols[::COL_STEP], cols[-1:]])).astype(np.float64)
    rr, cc = np.meshgrid(rows.astype(np.float64), sub, indexing="ij")
    xs, ys = [], []
    for h in levels:
        lon, lat = model.localize(cc.ravel(), rr.ravel(), np.full(cc.size, h))
        x, y = to_xy(epsg, lon, lat)
        x = x.reshape(rr.shape)
        y = y.reshape(rr.shape)
        fx = np.stack([np.interp(cols, sub, xr) for xr in x])
        fy = np.stack([np.interp(cols, sub, yr) for yr in y])
        xs.append(fx.ravel())
        ys.append(fy.ravel())
    return Rays(np.stack(xs), np.stack(ys), levels)


def _read_window(path: Path, transform: Affine, xmin: float, ymin: float, xmax: float,
                 ymax: float) -> tuple[np.ndarray, float, float]:
    """Float64 window (NaN outside) of a truth-grid raster and its top-left cell centre."""
    res = transform.a
    c0 = int(np.floor((xmin - transform.c) / res)) - 2
    c1 = int(np.ceil((xmax - transform.c) / res)) + 2
    r0 = int(np.floor((transform.f - ymax) / res)) - 2
    r1 = int(np.ceil((transform.f - ymin) / res)) + 2
    with rasterio.open(path) as src:
        a = src.read(1, window=Window(c0, r0, c1 - c0, r1 - r0), boundless=True,
                     fill_value=np.nan, masked=False).astype(np.float64)
    return a, transform.c + (c0 + 0.5) * res, transform.f - (r0 + 0.5) * res


def _ray_levels(scene: SceneDef) -> tuple[float, float, float]:
    """Heights at which lines of sight are localised: just below, across and above the DSM."""
    lo, hi = scene.dsm_range_m
    return lo - 5.0, 0.5 * (lo + hi), hi + 5.0


Bounds = tuple[float, float, float, float]


def _cast_on_dsm(rays: Rays, scene: SceneDef, dsm_path: Path,
                 tol_m: float) -> tuple[np.ndarray, np.ndarray, Bounds] | None:
    """First hit (x, y) of each ray on the truth DSM, and the rays' ground bounds;
    None when the DSM holds no height under them."""
    bounds = (float(np.nanmin(rays.x_m)), float(np.nanmin(rays.y_m)),
              float(np.nanmax(rays.x_m)), float(np.nanmax(rays.y_m)))
    z, zx0, zy0 = _read_window(Path(dsm_path), scene.transform, *bounds)
    if not np.isfinite(z).any():
        return None
    res = scene.transform.a
    x, y, _ = first_hit(rays, SurfaceGrid(z, zx0, zy0, res, res),
                        float(np.nanmax(z)) + 0.5, float(np.nanmin(z)) - 0.5, tol_m=tol_m)
    return x, y, bounds


def render_block(block: np.ndarray, scene: SceneDef, model_json: str, image_index: int,
                 dsm_path: str, radiance_path: str, block_info: dict | None = None) -> np.ndarray:
    """DN of one image block: ray-cast each pixel on the truth DSM, sample the radiance."""
    (r0, r1), (c0, c1) = block_info[0]["array-location"]
    model = _model(model_json)
    rows, cols = np.arange(r0, r1), np.arange(c0, c1)
    rays = _rays(model, rows, cols, scene.epsg, _ray_levels(scene))
    shape = (r1 - r0, c1 - c0)
    bits = scene.bits
    hit = _cast_on_dsm(rays, scene, Path(dsm_path), tol_m=0.01)
    if hit is None:
        return np.zeros(shape, dtype=np.uint8 if bits == 8 else np.uint16)
    x, y, bounds = hit
    tr = scene.transform
    res = tr.a
    rad, rx0, ry0 = _read_window(Path(radiance_path), tr, *bounds)
    fj = (x - rx0) / res
    fi = (ry0 - y) / res
    ok = np.isfinite(fi) & np.isfinite(fj)
    L = np.full(x.shape, np.nan)
    L[ok] = map_coordinates(rad, [fi[ok], fj[ok]], order=1, mode="nearest", prefilter=False)
    rr, cc = np.meshgrid(rows, cols, indexing="ij")
    dn = radiance_to_dn(L.reshape(shape), 1.0, NOISE_DN[bits], bits,
                        derive_seed(scene.seed, "sensor-noise", image_index), rr, cc)
    return dn


@lru_cache(maxsize=8)
def _model(text: str) -> PushbroomModel:
    return PushbroomModel.from_json(text)


@task(name="render-image")
def render_image(scene: SceneDef, out: Path, image_index: int) -> Path:
    """Render one image tile by tile and write it with the RPC of its delivered metadata."""
    paths = ScenePaths(Path(out))
    name = scene.image_names[image_index]
    if _exist(paths.image(name)):
        return paths.image(name)
    truth_json = paths.truth_model(name).read_text()
    delivered = PushbroomModel.from_json(paths.delivered(name).read_text())
    truth = _model(truth_json)
    dtype = np.uint8 if scene.bits == 8 else np.uint16
    base = darr.zeros((truth.n_rows, truth.n_cols), chunks=CHUNK, dtype=dtype)
    img = darr.map_blocks(
        render_block, base, scene=scene, model_json=truth_json, image_index=image_index,
        dsm_path=str(paths.dsm), radiance_path=str(paths.radiance(name)), dtype=dtype,
    )
    lo, hi = scene.dsm_range_m
    rpc, report = fit_rpc(delivered, truth.n_cols, truth.n_rows, (lo - 100.0, hi + 100.0))
    tags = {"rpc_fit_max_px": f"{report.max_px:.2e}", "rpc_fit_rms_px": f"{report.rms_px:.2e}",
            "metadata": paths.delivered(name).name, "seed": str(scene.seed)}
    write_arrays_cog([(img, paths.image(name), {"rpcs": RPC.from_gdal(rpc.to_gdal_tags()),
                                                "nodata": 0, "tags": tags})])
    return paths.image(name)


# ---------------------------------------------------------------------------- E. check points


@task(name="check-points")
def make_checkpoints(scene: SceneDef, out: Path, n_wanted: int = 100) -> Path:
    """Independent check points on bare soil, visible in both images, with true image coords."""
    paths = ScenePaths(Path(out))
    if _exist(paths.checkpoints):
        return paths.checkpoints
    models = [PushbroomModel.from_json(paths.truth_model(n).read_text()) for n in scene.image_names]
    rng = np.random.default_rng(derive_seed(scene.seed, "checkpoints"))
    x0, y0, res, w, h = scene.grid
    spec = _spec(scene)
    chosen: list[dict[str, Any]] = []
    for _ in range(20):
        n = 4000
        x = rng.uniform(x0, x0 + w * res, n)
        y = rng.uniform(y0 - h * res, y0, n)
        s = sample_surface(spec, x, y, to_lonlat(scene.epsg))
        ok = (s.classes == LandCover.BARE_SOIL) & np.isfinite(s.dtm_m)
        x, y, hh = x[ok], y[ok], s.dtm_m[ok]
        lon, lat = to_lonlat(scene.epsg)(x, y)
        img = [m.project(lon, lat, hh) for m in models]
        inside = np.ones(x.shape, dtype=bool)
        for (c, r), m in zip(img, models):
            inside &= (c > 10) & (c < m.n_cols - 11) & (r > 10) & (r < m.n_rows - 11)
        idx = np.flatnonzero(inside)
        geoid = spec.geoid
        for k in idx:
            if not _visible(scene, paths, models, img, x, y, k):
                continue
            chosen.append({
                "id": len(chosen) + 1,
                "lon_deg": float(lon[k]), "lat_deg": float(lat[k]), "h_m": float(hh[k]),
                "H_egm96_m": float(hh[k] - geoid.undulation_m(lon[k], lat[k])),
                "x_m": float(x[k]), "y_m": float(y[k]),
                "land_cover": "bare_soil",
                **{name: {"col": float(img[i][0][k]), "row": float(img[i][1][k])}
                   for i, name in enumerate(scene.image_names)},
            })
            if len(chosen) >= n_wanted:
                break
        if len(chosen) >= n_wanted:
            break
    if len(chosen) < 50:
        raise InputError(
            f"only {len(chosen)} visible bare-soil check points found in the overlap (50 "
            "needed); the scene is mostly water, forest or town: choose another --center"
        )
    doc = {
        "crs": f"EPSG:{scene.epsg}", "heights": "h_m WGS84 ellipsoidal, H_egm96_m orthometric",
        "image_coordinates": "0-based, pixel centres at integers, (col, row)",
        "images": list(scene.image_names), "points": chosen,
    }
    atomic_write_text(paths.checkpoints, json.dumps(doc, indent=1))
    return paths.checkpoints


def _visible(scene: SceneDef, paths: ScenePaths, models: list[PushbroomModel],
             img: list[tuple[np.ndarray, np.ndarray]], px: np.ndarray, py: np.ndarray,
             k: int) -> bool:
    """Whether point ``k`` is what its pixels see in every image (no tree or roof in front):
    the first hit of each line of sight on the truth DSM lies within 1.5 cells of it."""
    res = scene.grid[2]
    for (c, r), m in zip(img, models, strict=True):
        rays = _rays(m, np.array([r[k]]), np.array([c[k]]), scene.epsg, _ray_levels(scene))
        hit = _cast_on_dsm(rays, scene, paths.dsm, tol_m=1e-3)
        if hit is None:
            return False
        hx, hy, _ = hit
        if not (np.isfinite(hx[0]) and np.hypot(hx[0] - px[k], hy[0] - py[k]) < 1.5 * res):
            return False
    return True


# ---------------------------------------------------------------------------- F. lidar


def lidar_bounds(scene: SceneDef) -> tuple[float, float, float, float]:
    """The lidar strip (x_min, y_min, x_max, y_max) in the truth grid's CRS."""
    x0, y0, res, w, h = scene.grid
    strip = scene.preset_obj.lidar_strip_m
    if strip is None:
        return x0, y0 - h * res, x0 + w * res, y0
    cx, cy = to_xy(scene.epsg, np.array([scene.centre[0]]), np.array([scene.centre[1]]))
    across, along = strip
    return (float(cx[0]) - across / 2, float(cy[0]) - along / 2, float(cx[0]) + across / 2,
            float(cy[0]) + along / 2)


@task(name="lidar")
def make_lidar(scene: SceneDef, out: Path, tile_m: float = 1000.0) -> Path:
    """Truth lidar as LAZ (LAS 1.4), tile by tile: heights EGM96 orthometric, LAS classes."""
    paths = ScenePaths(Path(out))
    if _exist(paths.lidar):
        return paths.lidar
    spec = _spec(scene)
    xmin, ymin, xmax, ymax = lidar_bounds(scene)
    spacing = scene.preset_obj.lidar_spacing_m
    crs = pyproj.CRS.from_user_input(f"EPSG:{scene.epsg}+5773")  # UTM + EGM96 height
    header = laspy.LasHeader(point_format=6, version="1.4")
    header.scales = np.array([0.001, 0.001, 0.001])
    header.offsets = np.array([np.floor(xmin), np.floor(ymin), 0.0])
    header.add_crs(crs)
    header.creation_date = date.fromisoformat(scene.preset_obj.images[0].date)  # same bytes
    header.system_identifier = "gcpfree simulate"
    header.generating_software = "gcpfree"
    tmp = paths.lidar.with_name(f".{paths.lidar.name}.tmp")
    seed = derive_seed(scene.seed, "lidar")
    n_total = 0
    try:
        with laspy.open(tmp, mode="w", header=header) as writer:
            for ty in np.arange(ymin, ymax, tile_m):
                for tx in np.arange(xmin, xmax, tile_m):
                    pts = lidar_points(tx, ty, min(tx + tile_m, xmax), min(ty + tile_m, ymax),
                                       seed, spacing_m=spacing)
                    if len(pts) == 0:
                        continue
                    s = sample_surface(spec, pts.x_m, pts.y_m, to_lonlat(scene.epsg))
                    ret = lidar_returns(pts, s.dtm_m, s.dsm_m, s.classes, s.building_m > 0,
                                        s.dark_roof, seed, LidarConfig())
                    lon, lat = to_lonlat(scene.epsg)(ret.x_m, ret.y_m)
                    H = ret.z_m - spec.geoid.undulation_m(lon, lat)
                    rec = laspy.ScaleAwarePointRecord.zeros(len(ret.x_m), header=header)
                    rec.x, rec.y, rec.z = ret.x_m, ret.y_m, H
                    rec.classification = ret.las_class
                    writer.write_points(rec)
                    n_total += len(ret.x_m)
        tmp.replace(paths.lidar)
    finally:
        tmp.unlink(missing_ok=True)
    return paths.lidar


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

    def lines(self) -> list[str]:
        errs = ", ".join(f"{k} {v:.1f} m" for k, v in self.centre_error_m.items())
        return [
            f"simulated scene  {self.out} (preset {self.preset}, seed {self.seed})",
            f"images           {', '.join(self.images)} (RPC tags inside, metadata .json beside)",
            f"metadata error   at the scene centre: {errs}",
            (f"truth            DSM/DTM {self.dsm_range_m[0]:.0f}..{self.dsm_range_m[1]:.0f} m "
             f"ellipsoidal, {self.checkpoints} check points, {self.lidar_points} lidar points"),
        ]


@task(name="summarize-scene")
def summarize(scene: SceneDef, out: Path) -> SimulationSummary:
    paths = ScenePaths(Path(out))
    n_cp = len(json.loads(paths.checkpoints.read_text())["points"])
    n_lidar = 0
    if paths.lidar.exists():
        with laspy.open(paths.lidar) as f:
            n_lidar = int(f.header.point_count)
    return SimulationSummary(
        out=str(paths.root), preset=scene.preset, seed=scene.seed,
        centre_error_m={k: float(v["centre_error_m"]) for k, v in scene.injected.items()},
        images=tuple(str(paths.image(n)) for n in scene.image_names), checkpoints=n_cp,
        lidar_points=n_lidar, dsm_range_m=scene.dsm_range_m,
    )
