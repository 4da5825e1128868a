"""Tasks of the scene simulator: the surveys of its world, what SRTM and an airborne lidar would
give of it (``DIR/reference.tif``, ``DIR/truth/lidar.laz``), for a pair or a block alike."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict
from datetime import date
from functools import partial
from pathlib import Path

import laspy
import numpy as np
import pyproj
from prefect import task

from core.geodesy import ARCSEC, metres_per_degree
from core.simulation.hashing import derive_seed
from core.simulation.lidar import lidar_extent, lidar_tile
from core.simulation.reference import ReferenceErrors, radar_voids, seen_surface, srtm_like
from core.simulation.scene import SceneDef
from core.simulation.surface import sample_surface, slope_deg
from tasks.io.crs import Projection
from tasks.io.rasters import CogItem, CogOptions, atomic_write_json, write_arrays_cog
from tasks.scheduling import schedule
from tasks.simulate.io import ScenePaths, products_exist, surface_spec

# ---------------------------------------------------------------------------- G. reference


@task(name="srtm-like-reference")
def make_reference(scene: SceneDef, out: Path, errors: ReferenceErrors | None = None) -> Path:
    """``DIR/reference.tif``: the world as SRTM would show it (3" posting, correlated noise,
    misregistration, voids; ellipsoidal heights, EPSG:4326), the reference the chain should be
    tested against: the bare terrain with voids on steep slopes, or with ``--errors realistic``
    partial canopy, noise growing with slope, radar shadow and layover voids and a tilt
    (:mod:`core.simulation.reference`); the errors drawn go to
    ``truth/reference_errors.json``."""
    paths = ScenePaths(Path(out))
    target = paths.root / "reference.tif"
    if products_exist(target):
        return target
    proj = Projection(scene.epsg)
    if errors is None and scene.errors.realistic:
        cx, cy = proj.to_xy(np.array([scene.centre.lon_deg]), np.array([scene.centre.lat_deg]))
        x0, _, x1, _ = scene.grid.bounds_m()
        errors = ReferenceErrors.drawn_realistic(derive_seed(scene.seed, "reference"),
                                                 (float(cx[0]), float(cy[0])), x1 - x0)
    errors = errors or ReferenceErrors.drawn(derive_seed(scene.seed, "reference"))
    d = 3.0 * ARCSEC
    w = scene.dem_window
    lons = np.arange(np.ceil(w.lon_min / d), np.floor(w.lon_max / d) + 1) * d
    lats = np.arange(np.floor(w.lat_max / d), np.ceil(w.lat_min / d) - 1, -1) * d
    lon, lat = np.meshgrid(lons, lats)
    m_lon, m_lat = metres_per_degree(lat)
    seen_lon = lon - errors.shift_east_m / m_lon  # the node shows the terrain moved
    seen_lat = lat - errors.shift_north_m / m_lat
    x, y = proj.to_xy(seen_lon.ravel(), seen_lat.ravel())
    spec = surface_spec(scene)
    s = sample_surface(spec, x, y, proj.to_lonlat)
    seed = derive_seed(scene.seed, "reference")
    seen = seen_surface(s.dtm_m, s.dsm_m, x, y, seed, errors)
    h = srtm_like(seen, x, y, slope_deg(spec, seen_lon.ravel(), seen_lat.ravel()),
                  seed, errors).reshape(lon.shape)
    mid = lon.shape[0] // 2
    voids = radar_voids(s.dtm_m.reshape(lon.shape), d * float(m_lon[mid, 0]),
                        d * float(m_lat[mid, 0]), errors)
    h[voids] = np.nan
    tags = {"vertical_datum": "WGS84 ellipsoid", "units": "m",
            "source": "SRTM-like reference of the simulated world (gcpfree simulate)"}
    write_arrays_cog([CogItem(h.astype(np.float32), target, CogOptions(
        transform=(d, 0.0, lons[0] - d / 2, 0.0, -d, lats[0] + d / 2), crs="EPSG:4326",
        nodata=np.nan, tags=tags))])
    atomic_write_json(paths.truth / "reference_errors.json", asdict(errors))
    return target


# ---------------------------------------------------------------------------- F. lidar


def lidar_bounds(scene: SceneDef) -> tuple[float, float, float, float]:
    """The lidar strip (x_min, y_min, x_max, y_max) in the truth grid's CRS."""
    cx, cy = Projection(scene.epsg).to_xy(np.array([scene.centre.lon_deg]),
                                          np.array([scene.centre.lat_deg]))
    return lidar_extent(scene.grid.bounds_m(), float(cx[0]), float(cy[0]),
                        scene.preset_spec.lidar_strip_m)


@task(name="lidar")
def make_lidar(scene: SceneDef, out: Path, tile_m: float = 1000.0) -> Path:
    """Truth lidar as LAZ (LAS 1.4), tile by tile: heights EGM96 orthometric, LAS classes."""
    paths = ScenePaths(Path(out))
    if products_exist(paths.lidar):
        return paths.lidar
    spec = surface_spec(scene)
    xmin, ymin, xmax, ymax = lidar_bounds(scene)
    crs = pyproj.CRS.from_user_input(f"EPSG:{scene.epsg}+5773")  # UTM + EGM96 height
    header = laspy.LasHeader(point_format=6, version="1.4")
    header.scales = np.array([0.001, 0.001, 0.001])
    header.offsets = np.array([np.floor(xmin), np.floor(ymin), 0.0])
    header.add_crs(crs)
    header.creation_date = date.fromisoformat(scene.preset_spec.images[0].date)  # same bytes
    header.system_identifier = "gcpfree simulate"
    header.generating_software = "gcpfree"
    tmp = paths.lidar.with_name(f".{paths.lidar.name}.tmp")
    seed = derive_seed(scene.seed, "lidar")
    boxes = [(tx, ty, min(tx + tile_m, xmax), min(ty + tile_m, ymax))
             for ty in np.arange(ymin, ymax, tile_m) for tx in np.arange(xmin, xmax, tile_m)]
    survey = partial(lidar_tile, spec, seed=seed, spacing_m=scene.preset_spec.lidar_spacing_m,
                     to_lonlat=Projection(scene.epsg).to_lonlat)
    workers = schedule(len(boxes)).workers
    try:
        # the temporary name ends in .tmp: say LAZ, or laspy writes an uncompressed LAS
        with (laspy.open(tmp, mode="w", header=header, do_compress=True) as writer,
              ThreadPoolExecutor(workers) as pool):
            for g in range(0, len(boxes), 4 * workers):  # a few tiles in flight per thread
                # tiles surveyed in threads, written in their order: the bytes of one thread
                for t in pool.map(survey, boxes[g:g + 4 * workers]):
                    if t is None:
                        continue
                    rec = laspy.ScaleAwarePointRecord.zeros(len(t.returns), header=header)
                    rec.x, rec.y, rec.z = t.returns.x_m, t.returns.y_m, t.z_orthometric_m
                    rec.classification = t.returns.las_class
                    writer.write_points(rec)
        tmp.replace(paths.lidar)
    finally:
        tmp.unlink(missing_ok=True)
    return paths.lidar
