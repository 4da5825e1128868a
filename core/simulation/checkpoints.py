"""Check points of a simulated scene: bare-soil truth points that both images see (a pair), or
that two or more images see (a block).

Candidates are drawn uniformly over the truth grid, kept on bare soil, inside every image
(``margin_px`` from the edges; for a block, inside each image that keeps it) and visible: the
first hit of each image's line of sight through the point's true pixel on the truth DSM lies
within 1.5 cells of the point (no tree or roof in front). The image coordinates come from the
truth models.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from numpy.typing import NDArray

from core.points import CheckPoint, ImagePoint
from core.sensors.pushbroom import PushbroomModel
from core.simulation.landcover import LandCover
from core.simulation.raycast import SurfaceReader, ToXY, cast_on_surface, image_rays
from core.simulation.scene import TruthGrid
from core.simulation.surface import SurfaceSpec, ToLonLat, sample_surface

FloatArray = NDArray[np.float64]


def is_visible(model: PushbroomModel, col: float, row: float, x_m: float, y_m: float,
               read_surface: SurfaceReader, levels: tuple[float, float, float], to_xy: ToXY,
               cell_m: float) -> bool:
    """Whether pixel (col, row) of ``model`` sees ground point (x, y): its line of sight first
    meets the surface within 1.5 cells of the point."""
    rays = image_rays(model, np.array([row]), np.array([col]), levels, to_xy)
    hit = cast_on_surface(rays, read_surface, tol_m=1e-3)
    if hit is None:
        return False
    hx, hy = hit
    return bool(np.isfinite(hx[0]) and np.hypot(hx[0] - x_m, hy[0] - y_m) < 1.5 * cell_m)


def _candidates(spec: SurfaceSpec, grid: TruthGrid, rng: np.random.Generator, batch: int,
                to_lonlat: ToLonLat) -> tuple[FloatArray, ...]:
    """(x, y, h, lon, lat) of a batch of bare-soil truth points drawn over the grid."""
    x_min, y_min, x_max, y_max = grid.bounds_m()
    x = rng.uniform(x_min, x_max, batch)
    y = rng.uniform(y_min, y_max, batch)
    s = sample_surface(spec, x, y, to_lonlat)
    ok = (s.classes == LandCover.BARE_SOIL) & np.isfinite(s.dtm_m)
    x, y, h = x[ok], y[ok], s.dtm_m[ok]
    lon, lat = to_lonlat(x, y)
    return x, y, h, lon, lat


def _point(k: int, ident: int, x: FloatArray, y: FloatArray, h: FloatArray, lon: FloatArray,
           lat: FloatArray, spec: SurfaceSpec,
           image_points: dict[str, ImagePoint]) -> CheckPoint:
    return CheckPoint(
        id=ident, lon_deg=float(lon[k]), lat_deg=float(lat[k]), h_m=float(h[k]),
        H_egm96_m=float(spec.geoid.ellipsoidal_to_orthometric(lon[k], lat[k], h[k])),
        x_m=float(x[k]), y_m=float(y[k]), land_cover="bare_soil", image_points=image_points)


def select_block_checkpoints(
    spec: SurfaceSpec, models: Mapping[str, PushbroomModel], grid: TruthGrid,
    rng: np.random.Generator, to_lonlat: ToLonLat, to_xy: ToXY, read_surface: SurfaceReader,
    levels: tuple[float, float, float], n_wanted: int, min_views: int = 2, margin_px: int = 10,
    batch: int = 4000, max_rounds: int = 40,
) -> list[CheckPoint]:
    """Up to ``n_wanted`` bare-soil check points of a block, each with its true position in
    every image that sees it (inside the image and visible), kept when ``min_views`` images or
    more do; otherwise as :func:`select_checkpoints`."""
    chosen: list[CheckPoint] = []
    for _ in range(max_rounds):
        x, y, h, lon, lat = _candidates(spec, grid, rng, batch, to_lonlat)
        seen: dict[str, tuple[FloatArray, FloatArray, NDArray[np.bool_]]] = {}
        count = np.zeros(x.shape, dtype=np.int64)
        for name, m in models.items():
            c, r = m.project(lon, lat, h)
            inside = ((c > margin_px) & (c < m.n_cols - margin_px - 1)
                      & (r > margin_px) & (r < m.n_rows - margin_px - 1))
            seen[name] = (c, r, inside)
            count += inside
        for k in np.flatnonzero(count >= min_views):
            views = {n: ImagePoint(float(c[k]), float(r[k])) for n, (c, r, inside) in seen.items()
                     if inside[k] and is_visible(models[n], c[k], r[k], x[k], y[k], read_surface,
                                                 levels, to_xy, grid.res_m)}
            if len(views) < min_views:
                continue
            chosen.append(_point(k, len(chosen) + 1, x, y, h, lon, lat, spec, views))
            if len(chosen) >= n_wanted:
                return chosen
    return chosen


def select_checkpoints(
    spec: SurfaceSpec, models: Mapping[str, PushbroomModel], grid: TruthGrid,
    rng: np.random.Generator, to_lonlat: ToLonLat, to_xy: ToXY, read_surface: SurfaceReader,
    levels: tuple[float, float, float], n_wanted: int = 100, margin_px: int = 10,
    batch: int = 4000, max_rounds: int = 20,
) -> list[CheckPoint]:
    """Up to ``n_wanted`` visible bare-soil check points, in batches of ``batch`` candidates
    (at most ``max_rounds``). ``to_lonlat``/``to_xy`` convert the grid's projected frame;
    ``read_surface`` gives the truth DSM over some ground bounds (:mod:`raycast`)."""
    chosen: list[CheckPoint] = []
    for _ in range(max_rounds):
        x, y, h, lon, lat = _candidates(spec, grid, rng, batch, to_lonlat)
        img = {name: m.project(lon, lat, h) for name, m in models.items()}
        inside = np.ones(x.shape, dtype=bool)
        for name, m in models.items():
            c, r = img[name]
            inside &= ((c > margin_px) & (c < m.n_cols - margin_px - 1)
                       & (r > margin_px) & (r < m.n_rows - margin_px - 1))
        for k in np.flatnonzero(inside):
            if not all(is_visible(m, img[n][0][k], img[n][1][k], x[k], y[k], read_surface,
                                  levels, to_xy, grid.res_m) for n, m in models.items()):
                continue
            chosen.append(_point(k, len(chosen) + 1, x, y, h, lon, lat, spec,
                                 {n: ImagePoint(float(img[n][0][k]), float(img[n][1][k]))
                                  for n in models}))
            if len(chosen) >= n_wanted:
                return chosen
    return chosen
