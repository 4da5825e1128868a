"""Tasks of the ortho-versus-ortho check: two orthos of a pair on one lattice correlated on a
grid of windows (:mod:`core.ortho.ortho_compare`), block by block with Dask.

1. :func:`plan_compare`: both orthos read as georeferenced rasters in one projected CRS, with
   the same square cells on the same lattice (``gcpfree ortho`` aligns its grids on multiples
   of the cell size, so two orthos at one ``--resolution`` and ``--crs`` always are); their
   common area and the windows in it. Anything else stops here in one line.
2. :func:`compare_orthos`: blocks of windows read the two orthos over their windows and search
   areas (band 1, nodata as NaN) and run :func:`core.ortho.ortho_compare.match_windows`
   (:func:`compare_block`); writes ``OUT`` (JSON: statistics, status counts, every window),
   and when asked a map of the discrepancy norm per window (COG, one cell per window centred
   on it) and a quiver plot (PNG).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import dask.array as darr
import numpy as np
from prefect import task
from prefect.cache_policies import NO_CACHE

from core.errors import InputError
from core.matching.grid import GridSpec
from core.ortho.ortho_compare import (
    CompareConfig,
    DiscrepancyStats,
    ShiftStatus,
    WindowShifts,
    discrepancy_stats,
    match_windows,
    window_origins,
)
from tasks.io.rasters import (
    CogItem,
    CogOptions,
    atomic_write_bytes,
    atomic_write_json,
    open_raster,
    read_window,
    write_arrays_cog,
)
from tasks.scheduling import schedule, threads

DEFAULT_CONFIG = CompareConfig()
BLOCK_WINDOWS = 8  # windows per side of a Dask block
ALIGN_TOL = 1e-3  # cells: lattice offsets further than this from whole cells are refused


@dataclass(frozen=True)
class _Raster:
    path: str
    crs: Any
    transform: tuple[float, ...]
    width: int
    height: int


def _open(path: str | Path, which: str) -> _Raster:
    path = Path(path)
    with open_raster(path, f"{which} ortho", "give a gcpfree ortho GeoTIFF") as src:
        crs, t, w, h = src.crs, src.transform, src.width, src.height
    if crs is None or not crs.is_projected:
        raise InputError(f"{which} ortho {path} is not in a projected CRS (CRS {crs}); give an "
                         "ortho made by gcpfree ortho")
    if t.b != 0 or t.d != 0 or not math.isclose(abs(t.a), abs(t.e), rel_tol=1e-9) or t.e >= 0:
        raise InputError(f"{which} ortho {path} is not a north-up grid of square cells; give "
                         "an ortho made by gcpfree ortho")
    return _Raster(str(path), crs, tuple(t)[:6], w, h)


@dataclass(frozen=True)
class ComparePlan:
    """Two orthos on one lattice: the common area ``grid`` (cells of ``res_m``), its first
    cell in each raster (``left_origin``, ``right_origin`` as (row, col)), and the first
    cells of the windows in it (``rows``, ``cols``)."""

    left: str
    right: str
    crs_wkt: str
    epsg: int | None
    grid: GridSpec
    left_origin: tuple[int, int]
    right_origin: tuple[int, int]
    rows: tuple[int, ...]
    cols: tuple[int, ...]
    config: CompareConfig


@task(name="plan-ortho-compare", cache_policy=NO_CACHE)
def plan_compare(left: str | Path, right: str | Path,
                 config: CompareConfig = DEFAULT_CONFIG) -> ComparePlan:
    """The common area and its windows (see the module docstring).

    Raises:
        InputError: unreadable orthos, different CRS or cells, grids off one lattice, or a
            common area too small for one window and its search.
    """
    a, b = _open(left, "left"), _open(right, "right")
    if a.crs != b.crs:
        raise InputError(f"the orthos are in different CRS ({a.crs} and {b.crs}); make both "
                         "with the same --crs")
    res = a.transform[0]
    if not math.isclose(res, b.transform[0], rel_tol=1e-6):
        raise InputError(f"the orthos have different cells ({res:g} m and "
                         f"{b.transform[0]:g} m); make both with the same --resolution")
    off_c = (b.transform[2] - a.transform[2]) / res
    off_r = (a.transform[5] - b.transform[5]) / res
    if abs(off_c - round(off_c)) > ALIGN_TOL or abs(off_r - round(off_r)) > ALIGN_TOL:
        raise InputError(f"the orthos' grids are not on one lattice (offset {off_c:.3f}, "
                         f"{off_r:.3f} cells); make both with gcpfree ortho at the same "
                         "--resolution and --crs")
    off_c, off_r = round(off_c), round(off_r)  # right's cell (0, 0) in left's cells
    r0, c0 = max(0, off_r), max(0, off_c)
    r1, c1 = min(a.height, off_r + b.height), min(a.width, off_c + b.width)
    rows = window_origins(0, r1 - r0, config)
    cols = window_origins(0, c1 - c0, config)
    if rows.size == 0 or cols.size == 0:
        raise InputError(
            f"the orthos' common area ({max(c1 - c0, 0)} x {max(r1 - r0, 0)} cells) is too "
            f"small for one {config.window_px}-cell window with its +-{config.search_px}-cell "
            "search; check that they are the two images of one pair")
    grid = GridSpec(a.transform[2] + c0 * res, a.transform[5] - r0 * res, res, c1 - c0,
                    r1 - r0)
    return ComparePlan(a.path, b.path, a.crs.to_wkt(), a.crs.to_epsg(), grid, (r0, c0),
                       (r0 - off_r, c0 - off_c), tuple(int(v) for v in rows),
                       tuple(int(v) for v in cols), config)


def _read(path: str, row0: int, col0: int, n_rows: int, n_cols: int) -> np.ndarray:
    """Band 1 over a window, float64, NaN for nodata."""
    with open_raster(path, "ortho") as src:
        return read_window(src, (col0, row0, col0 + n_cols, row0 + n_rows), nan_masked=True,
                           what="ortho")


def compare_block(block: np.ndarray, plan: ComparePlan, block_info: dict | None = None
                  ) -> np.ndarray:
    """(4, h, w) of one block of windows: dx (east), dy (north), ncc, status."""
    (a0, a1), (b0, b1) = block_info[0]["array-location"][-2:]
    cfg = plan.config
    rows = np.asarray(plan.rows[a0:a1])
    cols = np.asarray(plan.cols[b0:b1])
    m, w = cfg.margin_px, cfg.window_px
    top, left_col = int(rows[0]) - m, int(cols[0]) - m
    n_r, n_c = int(rows[-1]) + w + m - top, int(cols[-1]) + w + m - left_col
    lo, ro = plan.left_origin, plan.right_origin
    left = _read(plan.left, lo[0] + top, lo[1] + left_col, n_r, n_c)
    right = _read(plan.right, ro[0] + top, ro[1] + left_col, n_r, n_c)
    s = match_windows(left, right, rows - top, cols - left_col, cfg)
    return np.stack([s.dx_px, s.dy_px, s.ncc, s.status.astype(np.float64)])


@dataclass(frozen=True)
class CompareSummary:
    """What :func:`compare_orthos` wrote and measured."""

    json_path: str
    map_path: str | None
    quiver_path: str | None
    left: str
    right: str
    stats: DiscrepancyStats
    status_counts: dict[str, int]

    def lines(self) -> list[str]:
        s = self.stats
        out = [f"windows        {s.n_valid} of {s.n_windows} matched ("
               + ", ".join(f"{k} {v}" for k, v in self.status_counts.items() if v) + ")"]
        if s.n_valid:
            out += [
                (f"discrepancy    median {s.median_norm_px:.3f} px "
                 f"({s.median_norm_px * s.cell_m:.2f} m), 95th percentile {s.p95_norm_px:.3f} px "
                 f"({s.p95_norm_px * s.cell_m:.2f} m), RMS {s.rms_norm_px:.3f} px"),
                (f"median shift   dx {s.median_dx_px:+.3f} px east, dy {s.median_dy_px:+.3f} px "
                 f"north (right relative to left, cells of {s.cell_m:g} m)"),
            ]
        out.append(f"json           {self.json_path}")
        if self.map_path:
            out.append(f"map            {self.map_path} (discrepancy norm per window, px)")
        if self.quiver_path:
            out.append(f"quiver         {self.quiver_path}")
        return out


def _centres(plan: ComparePlan) -> tuple[np.ndarray, np.ndarray]:
    """Map coordinates of the window centres (x along cols, y along rows)."""
    g, w = plan.grid, plan.config.window_px
    x = g.x0_m + (np.asarray(plan.cols) + 0.5 * w) * g.res_m
    y = g.y0_m - (np.asarray(plan.rows) + 0.5 * w) * g.res_m
    return x, y


@task(name="compare-orthos", cache_policy=NO_CACHE)
def compare_orthos(plan: ComparePlan, out: Path, map_path: Path | None = None,
                   quiver_path: Path | None = None,
                   num_workers: int | None = None) -> CompareSummary:
    """Correlate the windows of ``plan``; write ``out`` (JSON) and the optional map and
    quiver plot; return the summary."""
    shape = (len(plan.rows), len(plan.cols))
    base = darr.zeros(shape, chunks=BLOCK_WINDOWS, dtype=np.float64)
    stack = darr.map_blocks(compare_block, base, plan=plan, new_axis=0,
                            chunks=((4,),) + base.chunks, dtype=np.float64)
    # the windows' correlation is Python loops over small arrays: threads share one core,
    # so from 8 blocks on (and more than one worker) the blocks run in processes
    values = stack.compute(**schedule(base.npartitions, num_workers,
                                      processes=None).compute_kwargs())
    shifts = WindowShifts(values[0], values[1], values[2], values[3].astype(np.uint8))
    stats = discrepancy_stats(shifts, plan.grid.res_m)
    counts = {s.name.lower(): int((shifts.status == s).sum()) for s in ShiftStatus}
    x, y = _centres(plan)
    xx, yy = np.meshgrid(x, y)
    norm = np.hypot(shifts.dx_px, shifts.dy_px)
    cfg = plan.config
    doc = {
        "format": "gcpfree.ortho_compare", "version": 1, "left": plan.left,
        "right": plan.right, "epsg": plan.epsg, "cell_m": plan.grid.res_m,
        "convention": ("dx east, dy north, in cells and metres: what is at p in the left "
                       "ortho is at p + (dx, dy) in the right one"),
        "config": {"window_px": cfg.window_px, "step_px": cfg.step_px,
                   "search_px": cfg.search_px, "min_ncc": cfg.min_ncc,
                   "min_std": cfg.min_std},
        **stats.to_dict(), "status_counts": counts,
        "windows": {"x_m": xx.ravel(), "y_m": yy.ravel(), "dx_px": shifts.dx_px.ravel(),
                    "dy_px": shifts.dy_px.ravel(), "ncc": shifts.ncc.ravel(),
                    "status": shifts.status.ravel()},
    }
    if map_path is not None:
        step = cfg.step_px * plan.grid.res_m
        transform = (step, 0.0, float(x[0]) - 0.5 * step, 0.0, -step, float(y[0]) + 0.5 * step)
        with threads(num_workers):
            write_arrays_cog([CogItem(norm.astype(np.float32), Path(map_path), CogOptions(
                transform=transform, crs=plan.crs_wkt, nodata=math.nan,
                tags={"values": "discrepancy norm between the orthos per window, cells",
                      "cell_m": f"{plan.grid.res_m:g}", "software": "gcpfree ortho-compare"},
                blocksize=256))])
    if quiver_path is not None:
        atomic_write_bytes(quiver_path, _quiver_png(xx, yy, shifts, stats))
    atomic_write_json(out, doc)
    return CompareSummary(str(out), str(map_path) if map_path else None,
                          str(quiver_path) if quiver_path else None, plan.left, plan.right,
                          stats, counts)


def _quiver_png(xx: np.ndarray, yy: np.ndarray, s: WindowShifts,
                stats: DiscrepancyStats) -> bytes:
    """The window shifts as arrows coloured by their norm (PNG bytes)."""
    import io

    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    ok = s.status == ShiftStatus.OK
    fig = Figure(figsize=(7, 6), dpi=110)
    ax = fig.add_subplot()
    ax.set_aspect("equal")
    norm = np.hypot(s.dx_px, s.dy_px)
    ax.plot(xx[~ok], yy[~ok], "x", color="0.7", ms=3, label="no match")
    if ok.any():
        q = ax.quiver(xx[ok], yy[ok], s.dx_px[ok], s.dy_px[ok], norm[ok], cmap="viridis",
                      angles="xy")
        fig.colorbar(q, ax=ax, label="discrepancy (px)")
        ax.quiverkey(q, 0.85, 1.02, 1.0, "1 px", labelpos="E")
    ax.set_title(f"right vs left ortho: median {stats.median_norm_px:.2f} px, "
                 f"p95 {stats.p95_norm_px:.2f} px ({stats.n_valid} windows)", fontsize=9)
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return buf.getvalue()
