"""``gcpfree ortho-compare``: the two orthos of a pair correlated on a grid of windows, the
discrepancy reported (flow ``ortho-compare``, :mod:`flows.ortho`).

Importing this module is light (no Prefect, rasterio or OpenCV): :func:`run` checks the
inputs, then runs the flow.
"""

from __future__ import annotations

import argparse
from pathlib import Path


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
    from flows._env import prefect_api

    with prefect_api() as api:  # a temporary Prefect server boots meanwhile
        from core.errors import InputError
        from core.ortho.ortho_compare import CompareConfig
        from flows.ortho import CompareOptions, ortho_compare_flow
        from tasks.io.sensor_info import check_json_target
        from tasks.ortho.compare import plan_compare

        options = CompareOptions(
            left=args.left, right=args.right, out=args.out, map=args.map, quiver=args.quiver,
            compare=CompareConfig(window_px=args.window, step_px=args.step,
                                  search_px=args.search, min_ncc=args.min_ncc),
            workers=args.workers)
        plan_compare.fn(options.left, options.right, options.compare)  # bad input: one line
        check_json_target(options.out)
        for path, what in ((options.map, "--map"), (options.quiver, "--quiver")):
            if path is not None and not Path(path).resolve().parent.is_dir():
                raise InputError(f"the folder of {what} ({Path(path).resolve().parent}) does not "
                                 "exist; create it first")
        api.ready()
        summary = ortho_compare_flow(options)
        print("\n".join(summary.lines()))
    return 0
