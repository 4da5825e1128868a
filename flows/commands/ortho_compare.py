"""Flow and command ``gcpfree ortho-compare``: the two orthos of a pair correlated on a grid of
windows, the discrepancy reported (the quality control that needs no ground truth).

two orthos on one lattice -> windows every STEP cells over the common area -> each searched for
by normalised cross-correlation with a sub-pixel peak -> ``OUT`` (JSON: median and 95th
percentile of the discrepancy in px and m, every window) and the optional map (COG) and quiver
plot (PNG).

Importing this module is light (no Prefect, rasterio or OpenCV): :func:`run` checks the
inputs, then builds and runs the Prefect flow (:func:`ortho_compare_flow`).
"""

from __future__ import annotations

import argparse
import functools
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from flows._env import one_line_errors

if TYPE_CHECKING:
    from core.ortho_compare import CompareConfig
    from tasks.ortho.compare import CompareSummary


@dataclass(frozen=True)
class CompareOptions:
    """Inputs of ``gcpfree ortho-compare`` (see its ``--help``)."""

    left: Path
    right: Path
    out: Path
    map: Path | None = None
    quiver: Path | None = None
    window_px: int = 64
    step_px: int = 128
    search_px: int = 8
    min_ncc: float = 0.5
    workers: int | None = None

    def config(self) -> CompareConfig:
        from core.ortho_compare import CompareConfig

        return CompareConfig(window_px=self.window_px, step_px=self.step_px,
                             search_px=self.search_px, min_ncc=self.min_ncc)


@functools.cache
def ortho_compare_flow() -> Callable[[CompareOptions], CompareSummary]:
    """The Prefect flow ``ortho-compare``, built on first use."""
    from prefect import flow

    from tasks.ortho.compare import CompareSummary, compare_orthos, plan_compare

    def ortho_compare(options: CompareOptions) -> CompareSummary:
        plan = plan_compare(options.left, options.right, options.config())
        return compare_orthos(plan, options.out, options.map, options.quiver, options.workers)

    ortho_compare.__annotations__ = {"options": CompareOptions, "return": CompareSummary}
    return flow(name="ortho-compare", log_prints=True)(ortho_compare)


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "ortho-compare",
        help="discrepancy between the two orthos of a pair (correlation on a grid of windows)",
        description=(
            "Correlate windows of the left ortho (WINDOW cells every STEP cells over the "
            "common area) with the right ortho within +-SEARCH cells (normalised "
            "cross-correlation, sub-pixel peak refined on the resampled right ortho) and "
            "report the discrepancy: median dx (east), dy (north) and norm, 95th percentile "
            "and RMS of the norm, in cells and metres. The orthos must share CRS, cell size "
            "and lattice (gcpfree ortho with the same --resolution and --crs). Writes OUT "
            "(JSON with every window) and, when asked, a map of the norm per window (COG) "
            "and a quiver plot (PNG)."),
    )
    p.add_argument("--left", type=Path, required=True, metavar="LO",
                   help="ortho of the left image")
    p.add_argument("--right", type=Path, required=True, metavar="RO",
                   help="ortho of the right image")
    p.add_argument("--out", type=Path, required=True, metavar="CMP.json", help="output JSON")
    p.add_argument("--map", type=Path, default=None, metavar="CMP.tif",
                   help="also write the discrepancy norm per window (px) as a COG")
    p.add_argument("--quiver", type=Path, default=None, metavar="CMP.png",
                   help="also draw the window shifts as arrows (PNG)")
    p.add_argument("--window", type=int, default=64, metavar="N",
                   help="correlation window, cells (default 64)")
    p.add_argument("--step", type=int, default=128, metavar="N",
                   help="spacing of the windows, cells (default 128)")
    p.add_argument("--search", type=int, default=8, metavar="N",
                   help="search radius, cells (default 8)")
    p.add_argument("--min-ncc", type=float, default=0.5, metavar="R",
                   help="correlation below which a window is not used (default 0.5)")
    p.add_argument("--workers", type=int, default=None,
                   help="parallel blocks of windows (default: one per core)")


def run(args: argparse.Namespace) -> int:
    from core.errors import InputError
    from tasks.io.sensor_info import check_json_target
    from tasks.ortho.compare import plan_compare

    options = CompareOptions(
        left=args.left, right=args.right, out=args.out, map=args.map, quiver=args.quiver,
        window_px=args.window, step_px=args.step, search_px=args.search,
        min_ncc=args.min_ncc, workers=args.workers)
    plan_compare.fn(options.left, options.right, options.config())  # bad input: one line
    check_json_target(options.out)
    for path, what in ((options.map, "--map"), (options.quiver, "--quiver")):
        if path is not None and not Path(path).resolve().parent.is_dir():
            raise InputError(f"the folder of {what} ({Path(path).resolve().parent}) does not "
                             "exist; create it first")
    with one_line_errors():
        summary = ortho_compare_flow()(options)
    print("\n".join(summary.lines()))
    return 0
