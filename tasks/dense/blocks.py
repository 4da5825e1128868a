"""The per-tile and per-block functions of the DEM tasks (:mod:`tasks.dense.dem`).

Sensor windows read boundless, the region of interest checked and cut into tiles, one tile
matched and triangulated into a point file (:func:`dense_block`), one block of the DEM grid
made from the point files (:func:`grid_block`). The block functions run in Dask workers
(threads, or spawned processes), so they live at module level, take picklable arguments,
only read, slice and call one core function, and hand freed memory back when done.
"""

from __future__ import annotations

import ctypes
import math
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np

from core.errors import InputError
from core.geoid import GeoidGrid
from core.jsonio import parse_json, to_json
from core.matching.dense import MatchingConfig, PixelStatus
from core.matching.dense_tile import (
    SensorWindow,
    TileMatches,
    TileStats,
    dense_tile,
    retriangulate,
)
from core.matching.fusion import FusionConfig, fuse_heights
from core.matching.grid import GridSpec, grid_dem, median_per_cell
from core.matching.rectify import TilePlan, TileRectification
from core.sensors.base import SensorModel
from core.sensors.footprint import PixelBox
from tasks.io.crs import Projection
from tasks.io.rasters import open_raster
from tasks.io.rasters import read_window as read_raster_window

# ---------------------------------------------------------------------------- reading


def read_window(path: str | Path, box: PixelBox) -> tuple[np.ndarray, float | None]:
    """Sensor pixels ``box`` (col0, row0, col1, row1) of band 1 as float32, the nodata value
    (or 0) beyond the image (:func:`tasks.io.rasters.read_window`); and the image's nodata
    value."""
    with open_raster(path, "image") as src:
        nodata = src.nodata
        return read_raster_window(src, box, what="image").astype(np.float32), nodata


@dataclass(frozen=True, eq=False)
class SensorImage:
    """An image of the pair as the tiles read it: its raster, its model (the right one
    oriented) and its size (cols, rows)."""

    path: str
    model: SensorModel
    size: tuple[int, int]

    def window(self, box: PixelBox) -> SensorWindow:
        """The sensor pixels ``box`` (:func:`read_window`) with the model."""
        image, nodata = read_window(self.path, box)
        return SensorWindow(image, (int(box[0]), int(box[1])), self.model, self.size, nodata)


@dataclass(frozen=True)
class PairPoints:
    """A pair's point files for the multi-view grid: its folder ``work``, its tiles' figures,
    its fusion weight ((B/H)^2) and its two images (indices into the views)."""

    work: str
    stats: tuple[TileStats, ...]
    weight: float
    images: tuple[int, int]


# ---------------------------------------------------------------------------- tiles


def tile_boxes(roi: PixelBox, tile_px: int) -> list[PixelBox]:
    """The ROI cut into tiles of about ``tile_px`` (equal sizes, none thinner than half)."""
    c0, r0, c1, r1 = roi
    nc = max(1, round((c1 - c0) / tile_px))
    nr = max(1, round((r1 - r0) / tile_px))
    cs = np.linspace(c0, c1, nc + 1).round().astype(int)
    rs = np.linspace(r0, r1, nr + 1).round().astype(int)
    return [(int(cs[j]), int(rs[i]), int(cs[j + 1]), int(rs[i + 1]))
            for i in range(nr) for j in range(nc)]


def check_roi(roi: tuple[int, int, int, int] | None, size: tuple[int, int]) -> PixelBox:
    """The command line's ``--roi COL ROW WIDTH HEIGHT`` in the left image -> the
    :data:`~core.sensors.footprint.PixelBox` (col0, row0, col1, row1) every step uses after it
    (``DensePlan.roi``, the ``roi`` of DEM.json); the whole image for None."""
    cols, rows = size
    if roi is None:
        return (0, 0, cols, rows)
    col, row, w, h = (int(v) for v in roi)
    if w < 16 or h < 16:
        raise InputError(f"--roi {col} {row} {w} {h} is too small; give a width and height of "
                         "at least 16 px")
    box = (max(col, 0), max(row, 0), min(col + w, cols), min(row + h, rows))
    if box[2] - box[0] < 16 or box[3] - box[1] < 16:
        raise InputError(f"--roi {col} {row} {w} {h} lies outside the left image ({cols} x "
                         f"{rows} px); give COL ROW WIDTH HEIGHT inside it")
    return box


def tile_points_path(work: Path, index: int) -> Path:
    """The point file of tile ``index`` in the work folder."""
    return Path(work) / f"tile_{index:05d}.npz"


def _trim_heap() -> None:
    """Hand the memory a block freed back to the system (glibc ``malloc_trim``): the blocks'
    large temporaries otherwise stay in the allocator's arenas and the resident size creeps
    up with the number of blocks a worker has run (measured: +1 GB over a SPOT scene)."""
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):  # not glibc
        pass


# ---------------------------------------------------------------------------- blocks


def dense_block(plan: TilePlan, left: SensorImage, right: SensorImage, epsg: int,
                origin_m: tuple[float, float], geoid: GeoidGrid | None, cfg: MatchingConfig,
                out: str) -> TileStats:
    """One tile: read both sensor windows, :func:`dense_tile`, save the points (float32
    offsets from ``origin_m``, heights, status) to ``out``; return the tile's figures."""
    cv2.setNumThreads(1)
    lw, rw = left.window(plan.left_read), right.window(plan.right_read)
    res = dense_tile(plan, lw, rw, Projection(epsg).to_xy, geoid=geoid, cfg=cfg)
    m = res.matches
    np.savez(out, dx=(res.x_m - origin_m[0]).astype(np.float32),
             dy=(res.y_m - origin_m[1]).astype(np.float32), h=res.h_m, status=res.status,
             d=m.d_px, rect=to_json(m.rect.to_dict(), indent=None), window=np.array(m.window),
             core=np.array(m.core), d_range=np.array(m.d_range_px))
    stats = res.stats
    del res, lw, rw
    _trim_heap()
    return stats


def retriangulate_block(stats: TileStats, work_in: str, work_out: str, left: SensorModel,
                        right: SensorModel, epsg: int, origin_m: tuple[float, float],
                        geoid: GeoidGrid | None) -> TileStats:
    """One tile's saved matches intersected with other models (:func:`retriangulate`) into
    a point file of the same layout in ``work_out``; the tile's figures with its new ground
    bounds and miss distance."""
    with np.load(tile_points_path(Path(work_in), stats.index)) as f:
        rect = parse_json(str(f["rect"]), "a tile's rectification")
        matches = TileMatches(f["d"], TileRectification.from_dict(rect),
                              tuple(int(v) for v in f["window"]),
                              tuple(int(v) for v in f["core"]),
                              (float(f["d_range"][0]), float(f["d_range"][1])))
        status = f["status"]
    pts = retriangulate(matches, left, right, Projection(epsg).to_xy, geoid)
    valid = status == PixelStatus.VALID
    np.savez(tile_points_path(Path(work_out), stats.index),
             dx=(pts.x_m - origin_m[0]).astype(np.float32),
             dy=(pts.y_m - origin_m[1]).astype(np.float32),
             h=np.where(valid, pts.h_m, np.nan).astype(np.float32), status=status)
    bounds = (None if not pts.x_m.size else
              (float(pts.x_m.min()), float(pts.y_m.min()), float(pts.x_m.max()),
               float(pts.y_m.max())))
    miss = float(np.median(pts.miss_m[valid])) if valid.any() else math.nan
    _trim_heap()
    return replace(stats, bounds_m=bounds, miss_median_m=miss)


def geoid_block(z: np.ndarray, spec: GridSpec, epsg: int, geoid: GeoidGrid,
                block_info: dict | None = None) -> np.ndarray:
    """float32 orthometric heights ``H = h - N`` of a block of an ellipsoidal DEM grid ``z``
    (its position in ``block_info``), N interpolated (:meth:`GeoidGrid.undulation_m`) at each
    cell's centre; NaN stays NaN."""
    (r0, r1), (c0, c1) = block_info[0]["array-location"][-2:]
    out = np.full(z.shape, np.nan, dtype=np.float32)
    rows, cols = np.nonzero(np.isfinite(z))
    if rows.size:
        x = spec.x0_m + (cols + c0 + 0.5) * spec.res_m
        y = spec.y0_m - (rows + r0 + 0.5) * spec.res_m
        lon, lat = Projection(epsg).to_lonlat(x, y)
        out[rows, cols] = geoid.ellipsoidal_to_orthometric(lon, lat, z[rows, cols])
    return out


def _points_in(bounds: tuple[float, float, float, float], stats: tuple[TileStats, ...],
               work: str, origin_m: tuple[float, float]) -> dict[str, np.ndarray]:
    """The points (x, y, h, status) of the tiles in ``work`` that fall in ``bounds``."""
    xmin, ymin, xmax, ymax = bounds
    parts: dict[str, list[np.ndarray]] = {"x": [], "y": [], "h": [], "s": []}
    for s in stats:
        b = s.bounds_m
        if b is None or b[0] > xmax or b[2] < xmin or b[1] > ymax or b[3] < ymin:
            continue
        with np.load(tile_points_path(Path(work), s.index)) as f:
            x = f["dx"].astype(np.float64) + origin_m[0]
            y = f["dy"].astype(np.float64) + origin_m[1]
            keep = (x >= xmin) & (x < xmax) & (y > ymin) & (y <= ymax)
            parts["x"].append(x[keep])
            parts["y"].append(y[keep])
            parts["h"].append(f["h"][keep])
            parts["s"].append(f["status"][keep])
    return {k: np.concatenate(v) if v else np.zeros(0) for k, v in parts.items()}


def grid_block(block: np.ndarray, spec: GridSpec, stats: tuple[TileStats, ...], work: str,
               origin_m: tuple[float, float], halo: int, max_hole_cells: int,
               min_island_cells: int, block_info: dict | None = None) -> np.ndarray:
    """(3, h, w) float32: heights, mask and overlap of the DEM grid's ``block`` (its position),
    from the point files of the tiles whose ground reaches the block, with a ``halo`` of cells
    for the hole filling."""
    (r0, r1), (c0, c1) = block_info[0]["array-location"][-2:]
    xmin, ymin, xmax, ymax = spec.bounds_of(r0 - halo, r1 + halo, c0 - halo, c1 + halo)
    cat = _points_in((xmin, ymin, xmax, ymax), stats, work, origin_m)
    shape = (r1 - r0 + 2 * halo, c1 - c0 + 2 * halo)
    cells = grid_dem(cat["x"], cat["y"], cat["h"], cat["s"].astype(np.uint8), xmin, ymax,
                     spec.res_m, shape, max_hole_cells=max_hole_cells,
                     min_island_cells=min_island_cells)
    inner = (slice(halo, shape[0] - halo), slice(halo, shape[1] - halo))
    out = np.stack([cells.z_m[inner], cells.mask[inner].astype(np.float32),
                    cells.overlap[inner].astype(np.float32)])
    del cells, cat
    _trim_heap()
    return out


def views_block(block: np.ndarray, spec: GridSpec, pairs: tuple[PairPoints, ...],
                origin_m: tuple[float, float], halo: int, max_hole_cells: int,
                min_island_cells: int, fusion: FusionConfig, heights_only: bool = False,
                block_info: dict | None = None) -> np.ndarray:
    """(4 + n_pairs, h, w) float32 of a multi-view DEM grid's ``block``: the fused heights
    (:func:`core.matching.fusion.fuse_heights`), mask, overlap and count of views, then each
    pair's own median heights; with ``heights_only`` (n_pairs, h, w), the pairs' heights
    alone. The points of every pair's tiles that reach the block, with a ``halo``."""
    (r0, r1), (c0, c1) = block_info[0]["array-location"][-2:]
    bounds = spec.bounds_of(r0 - halo, r1 + halo, c0 - halo, c1 + halo)
    cats = [_points_in(bounds, p.stats, p.work, origin_m) for p in pairs]
    shape = (r1 - r0 + 2 * halo, c1 - c0 + 2 * halo)
    inner = (slice(None), slice(halo, shape[0] - halo), slice(halo, shape[1] - halo))
    z_pairs = np.stack([median_per_cell(c["x"], c["y"], c["h"], bounds[0], bounds[3],
                                        spec.res_m, shape) for c in cats])
    if heights_only:
        _trim_heap()
        return z_pairs[inner]
    fused = fuse_heights(z_pairs, [p.weight for p in pairs], [p.images for p in pairs], fusion)
    cat = {k: np.concatenate([c[k] for c in cats]) for k in ("x", "y", "h", "s")}
    cells = grid_dem(cat["x"], cat["y"], cat["h"], cat["s"].astype(np.uint8), bounds[0],
                     bounds[3], spec.res_m, shape, max_hole_cells=max_hole_cells,
                     min_island_cells=min_island_cells, z_m=fused.z_m)
    views = np.where(np.isfinite(fused.z_m) & np.isfinite(cells.z_m), fused.views, 0)
    out = np.concatenate([np.stack([cells.z_m, cells.mask.astype(np.float32),
                                    cells.overlap.astype(np.float32),
                                    views.astype(np.float32)]), z_pairs])[inner]
    del cells, cat, cats, z_pairs
    _trim_heap()
    return out
