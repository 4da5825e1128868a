"""``gcpfree fill-voids``: an SRTM tile's voids filled from the oriented DSM (flow
``fill-voids``, :mod:`flows.fill_voids`).

Importing this module is light (no Prefect, rasterio or pyproj): :func:`run` checks the
inputs, then runs the flow.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from flows.commands._pair import add_vertical_argument


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "fill-voids",
        help="fill an SRTM tile's voids with the oriented DSM (delta surface fill)",
        description=(
            "Fill the void cells (-32768) of an SRTM tile with the DSM's heights, converted to "
            "the tile's orthometric (EGM96) heights with H = h - N and resampled onto the "
            "tile's nodes (averaged to about the node spacing when the DSM is finer, then "
            "bilinear). Each void gets the DSM plus the SRTM-minus-DSM difference measured on "
            "the valid cells around it and interpolated smoothly across it (delta surface "
            "fill), so the fill joins the SRTM at the border and carries no DSM bias or "
            "canopy offset. Void cells the DSM does not cover stay void. Writes OUT in the "
            "tile's own format and grid (.hgt: big-endian int16, same size; GeoTIFF: same "
            "profile), atomically, and OUT.json: filled and still-void counts, bias and NMAD "
            "of DSM - SRTM on the border ring."),
    )
    p.add_argument("--srtm", type=Path, required=True, metavar="TILE",
                   help="SRTM tile: .hgt named like N44E005.hgt (1201 or 3601 nodes a side), "
                        "or a lon/lat GeoTIFF")
    p.add_argument("--dem", type=Path, required=True, metavar="DSM",
                   help="the oriented DSM (gcpfree dsm output: projected GeoTIFF, NaN nodata)")
    p.add_argument("--out", type=Path, required=True, metavar="FILLED",
                   help="output tile, same format as TILE (.hgt or .tif); a .hgt keeps the "
                        "tile's name, in another folder (e.g. filled/N44E005.hgt), since its "
                        "name is what places it")
    p.add_argument("--border-cells", type=int, default=3, metavar="N",
                   help="width of the valid ring around the voids where DSM - SRTM is "
                        "reported and screened for outliers, in tile cells (default 3)")
    p.add_argument("--outlier-nmad", type=float, default=5.0, metavar="K",
                   help="ring differences further than K NMADs from their median are not used "
                        "(default 5; 0 keeps all)")
    p.add_argument("--smooth-cells", type=int, default=0, metavar="N",
                   help="average the ring differences over 2N+1 cells before interpolating "
                        "them (default 0: as measured; raise it for a tile noisy from cell to "
                        "cell)")
    add_vertical_argument(p, "--dem-vertical", "DSM")
    add_vertical_argument(p, "--srtm-vertical", "TILE")
    p.add_argument("--geoid", type=Path, default=None,
                   help="geoid grid in GTX format (default: bundled EGM96 15')")


def run(args: argparse.Namespace) -> int:
    from flows._env import prefect_api

    with prefect_api() as api:  # a temporary Prefect server boots meanwhile
        from core.evaluation.void_fill import FillConfig
        from tasks.evaluation.void_fill import FillOptions, plan_fill
        from tasks.io.sensor_info import check_json_target

        options = FillOptions(
            srtm=args.srtm, dem=args.dem, out=args.out, srtm_vertical=args.srtm_vertical,
            dem_vertical=args.dem_vertical, geoid=args.geoid,
            config=FillConfig(border_cells=args.border_cells, outlier_nmad=args.outlier_nmad,
                              smooth_cells=args.smooth_cells))
        # the tile, the DSM and the output checked before the flow: bad input is one line
        plan_fill(options)
        check_json_target(options.json_path)
        if args.geoid is not None:
            from tasks.io.geoid import read_gtx
            read_gtx(args.geoid)
        from flows.fill_voids import fill_voids_flow

        api.ready()
        summary = fill_voids_flow(options)
        print("\n".join(summary.lines()))
    return 0
