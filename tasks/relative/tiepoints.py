"""Task of step 1: tie points between the two images of a pair, tile by tile with Dask.

The left image is cut into ``cfg.tile_px`` blocks; each block is one Dask task that reads its
left window (with the template margin), finds interest points and their heights on the
reference DEM, reads the right window holding their search areas, matches them
(:mod:`core.matching.tiepoints`) and returns the small arrays of its matches. The best point per
ground cell is then kept over the whole overlap. Nothing whole-image is held in memory: only
windows, the reference DEM over the scene and the point arrays.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import cv2
import dask
import numpy as np
from prefect import task

from core.dem import GeoDEM
from core.errors import CoverageError, GeometryError, InputError
from core.jsonio import json_ready, parse_json
from core.matching.overlap import overlap_cell_m, overlap_cells
from core.matching.tiepoint_match import match_points
from core.matching.tiepoint_results import Matches, TiePointResult, tiepoint_report
from core.matching.tiepoints import (
    HeightPrior,
    TiePointConfig,
    cell_ids,
    check_consistency,
    choose_measure,
    detect_points,
    ground_sampling_m,
    ground_xy_m,
    predict_search,
    search_windows,
    select_tie_points,
    valid_pixels,
)
from core.sensors.base import SensorModel
from core.sensors.footprint import footprint_box, scene_height_range_m
from tasks.io.dem import dem_datum, read_reference
from tasks.io.rasters import atomic_write_json, open_raster, read_window
from tasks.io.sensors import LoadedModel
from tasks.scheduling import compute, schedule

# margin (degrees) around the left footprint when reading the reference DEM: the search
# radius and the parallax of the height range stay well inside it
DEFAULT_CONFIG = TiePointConfig()


@dataclass(frozen=True)
class Block:
    """A block of the left image: full-image pixels [row0:row1, col0:col1]."""

    col0: int
    row0: int
    col1: int
    row1: int


def blocks(size: tuple[int, int], tile_px: int) -> list[Block]:
    """The blocks tiling an image of ``size`` (cols, rows)."""
    n_cols, n_rows = size
    return [Block(c, r, min(c + tile_px, n_cols), min(r + tile_px, n_rows))
            for r in range(0, n_rows, tile_px) for c in range(0, n_cols, tile_px)]


# ---------------------------------------------------------------------------- reading


def raster_info(path: str | Path) -> tuple[tuple[int, int], float | None]:
    """(cols, rows) of a raster and the value of its saturated pixels (the maximum of an
    integer type; None for floating-point images)."""
    with open_raster(path, "image") as src:
        dtype = np.dtype(src.dtypes[0])
        sat = float(np.iinfo(dtype).max) if dtype.kind in "ui" else None
        return (src.width, src.height), sat


def _read(path: str | Path, box: tuple[int, int, int, int]) -> np.ndarray:
    """Pixels of ``box`` of band 1; 0 (nodata for the matching) beyond the raster."""
    with open_raster(path, "image") as src:
        return read_window(src, box, fill=0, what="image")


def reference_under(path: str | Path, left_model: SensorModel, left_size: tuple[int, int]
                    ) -> GeoDEM:
    """The part of a lon/lat reference DEM under the left image, as ellipsoidal heights (its
    datum by the one rule, :func:`tasks.io.dem.dem_datum`): read over the footprint at the
    heights the model allows, then again at the heights the DEM shows there."""
    datum = dem_datum(path).datum
    heights = scene_height_range_m([left_model])
    for _ in range(2):
        dem = read_reference(path, footprint_box([(left_model, (0, 0, *left_size))], heights),
                             datum)
        lo, hi = dem.height_range_m()
        if not np.isfinite(lo):
            raise CoverageError(f"reference DEM {path} has no height under the left image; "
                                "give a DEM covering the scene")
        if (lo, hi) == heights:
            break
        heights = (lo, hi)
    return dem


# ---------------------------------------------------------------------------- per block


def block_matches(block: Block, left_path: str, right_path: str, left_model: SensorModel,
                  right_model: SensorModel, heights: HeightPrior, cfg: TiePointConfig,
                  saturation: float | None) -> Matches:
    """Matches of the interest points of one left block: read, detect, predict, read, match."""
    cv2.setNumThreads(1)
    t = cfg.template_half_px
    img = _read(left_path, (block.col0 - t, block.row0 - t, block.col1 + t, block.row1 + t))
    area = (block.col1 - block.col0) * (block.row1 - block.row0)
    gsd_m = ground_sampling_m(left_model, 0.5 * (block.col0 + block.col1),
                              0.5 * (block.row0 + block.row1), heights.typical_h_m)
    col, row = detect_points(
        img, valid_pixels(img, 0, saturation), max_points=cfg.max_points(area, gsd_m),
        min_spacing_px=cfg.min_spacing_px, border_px=t, quality_level=cfg.quality_level,
        region=(t, t, img.shape[1] - t, img.shape[0] - t))
    del img
    col, row = col + (block.col0 - t), row + (block.row0 - t)
    h, h_lo, h_hi, g_col, g_row = heights.with_slopes(left_model, col, row, float(t))
    prior = predict_search(left_model, right_model, col, row, h, h_lo, h_hi, cfg.pair_radius_m,
                           dh_dcol=g_col, dh_drow=g_row)
    windows = search_windows(col, row, prior, t)
    if windows is None:
        return match_points(np.zeros((1, 1)), (0, 0), np.zeros((1, 1)), (0, 0), col, row,
                            prior, cfg)
    lw, rw = windows
    with open_raster(right_path, "image") as src:  # the right window stays near it
        rw = (max(rw[0], -t - 2), max(rw[1], -t - 2), min(rw[2], src.width + t + 2),
              min(rw[3], src.height + t + 2))
    if rw[2] <= rw[0] or rw[3] <= rw[1]:
        rw = (0, 0, 1, 1)
    left = _read(left_path, lw)
    right = _read(right_path, rw)
    return match_points(left, lw[:2], right, rw[:2], col, row, prior, cfg)


def run_matches(run: list[Block], left_path: str, right_path: str, left_model: SensorModel,
                right_model: SensorModel, heights: HeightPrior, cfg: TiePointConfig,
                saturation: float | None) -> Matches:
    """The matches of a run of blocks (:func:`block_matches`), in their order: one worker's
    task."""
    return Matches.concat([block_matches(b, left_path, right_path, left_model, right_model,
                                         heights, cfg, saturation) for b in run])


#: runs of blocks per worker process (:func:`block_runs`): enough for the load to even out
RUNS_PER_WORKER = 3


def block_runs(all_blocks: list[Block], workers: int | None
               ) -> tuple[list[list[Block]], bool]:
    """The blocks as the workers take them, and whether in processes: one per task in
    threads; in processes (from
    :data:`tasks.scheduling.PROCESS_MIN_TASKS` blocks on, more than one worker),
    :data:`RUNS_PER_WORKER` contiguous runs per worker, so that the models and the reference
    heights are sent to a process a few times, not once per block. The matching's loop over
    points holds Python's lock (thousands of small OpenCV calls and their NumPy
    bookkeeping): threads gave 1.4-1.6 CPU per second of wall on 2 cores."""
    s = schedule(len(all_blocks), workers, processes=None)
    if s.scheduler != "processes":
        return [[b] for b in all_blocks], False
    n = min(len(all_blocks), RUNS_PER_WORKER * s.workers)
    cut = np.linspace(0, len(all_blocks), n + 1).round().astype(int)
    return [all_blocks[a:b] for a, b in zip(cut[:-1], cut[1:], strict=True)], True


# ---------------------------------------------------------------------------- task


def tie_measure(requested: str, left_sun: tuple[float, float] | None,
                right_sun: tuple[float, float] | None) -> tuple[str, str]:
    """The tie points' measure for ``--tie-measure`` and the suns (azimuth, elevation; deg)
    the pair's metadata state (``LoadedModel.sun``: None for models that carry none), and
    why: ``auto`` asks :func:`core.matching.tiepoints.choose_measure`; a measure given is used
    as it is."""
    if requested != "auto":
        return requested, "as asked"
    return choose_measure(left_sun, right_sun)


@task(name="find-tie-points")
def find_tie_points(
    left_image: str | Path,
    right_image: str | Path,
    left_model: SensorModel,
    right_model: SensorModel,
    reference: str | Path | GeoDEM | None = None,
    cfg: TiePointConfig = DEFAULT_CONFIG,
    *,
    h_range_m: tuple[float, float] | None = None,
    out: str | Path | None = None,
    num_workers: int | None = None,
) -> TiePointResult:
    """Tie points of a stereo pair, one per ``cfg.cell_m`` ground cell, and their report.

    A pair whose overlap holds fewer than ``cfg.min_cells_per_side`` squared cells of
    ``cfg.cell_m`` (crops smaller than the cell) gets smaller cells, that many over the
    overlap; the report states the cell used.

    ``reference`` is the ellipsoidal reference DEM (the COG of ``gcpfree prepare-reference``,
    or a :class:`GeoDEM`); without one, ``h_range_m`` (ellipsoidal metres) bounds the scene's
    heights. The left image is processed in ``cfg.tile_px`` blocks by ``num_workers`` (default
    one per core): worker processes of the command's shared pool from 8 blocks on, in runs of
    blocks (:func:`block_runs`), else threads. With ``out``, the result is also written there
    as JSON.
    """
    left_size, saturation = raster_info(left_image)
    right_size, _ = raster_info(right_image)
    if reference is None:
        if h_range_m is None:
            raise InputError("give a reference DEM or the scene's height range (h_range_m, "
                             "ellipsoidal metres) to search tie points")
        heights = HeightPrior.from_range(*h_range_m)
    else:
        dem = (reference if isinstance(reference, GeoDEM)
               else reference_under(reference, left_model, left_size))
        heights = HeightPrior.from_dem(dem, cfg.search_radius_m, cfg.height_margin_m)
    c_mid, r_mid = (left_size[0] - 1) / 2.0, (left_size[1] - 1) / 2.0
    h0 = float(np.nan_to_num(heights.heights(left_model, [c_mid], [r_mid])[0][0]))
    lon0, lat0 = left_model.localize(c_mid, r_mid, h0)
    origin = (float(lon0), float(lat0), h0)
    cell_m = overlap_cell_m(left_model, right_model, left_size, right_size, heights, cfg.cell_m,
                            cfg.min_cells_per_side)
    if cell_m < cfg.cell_m:  # a crop smaller than the cell: cells cut to fit the overlap
        cfg = replace(cfg, cell_m=cell_m)
    overlap = overlap_cells(left_model, right_model, left_size, right_size, heights, origin,
                            cfg.cell_m)
    if overlap.size == 0:
        raise GeometryError(
            f"{Path(left_image).name} and {Path(right_image).name} do not overlap under their "
            "sensor models; check that each model file belongs to its image")
    runs, in_processes = block_runs(blocks(left_size, cfg.tile_px), num_workers)
    parts = [dask.delayed(run_matches)(run, str(left_image), str(right_image), left_model,
                                       right_model, heights, cfg, saturation) for run in runs]
    matches = Matches.concat(compute(parts, workers=num_workers, processes=in_processes))
    x, y = ground_xy_m(left_model, matches.left_col, matches.left_row, matches.h_m, origin)
    matches = check_consistency(matches, x, y, cfg, heights_known=reference is not None)
    tie_points = select_tie_points(matches, x, y, cfg.cell_m)
    report = tiepoint_report(tie_points, matches.status,
                             cell_ids(x, y, cfg.cell_m), overlap, cfg.cell_m, cfg.measure)
    result = TiePointResult(tie_points, report)
    if out is not None:
        atomic_write_json(out, result.to_dict(), indent=None)
    return result


def _file_key(path: str | Path | None) -> list[Any] | None:
    """A file as a resume key: its resolved path, size and modification time."""
    if path is None or isinstance(path, GeoDEM):
        return None
    p = Path(path).resolve()
    st = p.stat() if p.exists() else None
    return [str(p), st.st_size if st else None, st.st_mtime_ns if st else None]


def resumed_tie_points(left: LoadedModel, right: LoadedModel, reference: str | Path | GeoDEM | None,
                       cfg: TiePointConfig, cache: Path, *,
                       h_range_m: tuple[float, float] | None = None,
                       reference_path: str | Path | None = None,
                       num_workers: int | None = None) -> tuple[TiePointResult, bool]:
    """:func:`find_tie_points` of two loaded images, kept in ``cache`` (JSON, written
    atomically) with what made them (the images and model files by path, size and time, the
    reference (``reference_path``: the file a GeoDEM ``reference`` was read from), the
    configuration, the height range): a rerun with the same inputs reads them
    back instead of matching again (``True`` beside the result), anything else changed or a
    damaged file matches again."""
    key = json_ready({"images": [_file_key(left.image or left.source),
                                 _file_key(right.image or right.source)],
                      "models": [_file_key(left.source), _file_key(right.source)],
                      "band": [left.band, right.band],
                      "reference": _file_key(reference_path or reference),
                      "config": asdict(cfg), "h_range_m": h_range_m})
    if cache.is_file():
        try:
            doc = parse_json(cache.read_text(encoding="utf-8"), str(cache))
            if doc.get("key") == key:
                return TiePointResult.from_dict(doc["result"]), True
        except (InputError, AttributeError, TypeError, KeyError):
            pass  # damaged or from other inputs: matched again
    result = find_tie_points(left.image or left.source, right.image or right.source,
                             left.model, right.model, reference, cfg, h_range_m=h_range_m,
                             num_workers=num_workers)
    atomic_write_json(cache, {"key": key, "result": result.to_dict()}, indent=None)
    return result, False
