"""``gcpfree prepare-reference``: DEM tiles (SRTM, NASADEM, Copernicus DEM...) + their geoid ->
the WGS84 ellipsoidal reference DEM (flow ``prepare-reference``, :mod:`flows.prepare_reference`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from flows.commands._pair import GEOID_HELP, add_vertical_argument


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "prepare-reference",
        help="DEM tiles (SRTM, NASADEM, Copernicus) + geoid -> WGS84 ellipsoidal reference DEM "
             "(Cloud-Optimized GeoTIFF)",
        description=(
            "Mosaic the DEM tiles covering a lon/lat box on their own lattice: SRTM (.hgt or "
            "GeoTIFF, 1\" or 3\"), NASADEM (NASADEM_HGT_*), Copernicus DEM GLO-30 / GLO-90 "
            "(Copernicus_DSM_*_DEM.tif, 1\" x 1\" south of 50 N, wider cells north of it), or "
            "lon/lat GeoTIFFs whose tag or CRS says their datum. Voids become NaN, and so do "
            "water and cells of large height error where Copernicus' own masks (AUXFILES "
            "_WBM, _HEM, _EDM) are beside its tiles. Orthometric heights H become ellipsoidal "
            "h = H + N through their geoid: the bundled EGM96 for SRTM and NASADEM, the "
            "EGM2008 grid given with --geoid (or PROJ's) for Copernicus. Writes a float32 COG "
            "with overviews, REF.voids.tif (0 valid, 1 void, 2 no tile, 3 water, 4 height "
            "error) and REF.json (the printed summary and the datum decision)."
        ),
    )
    p.add_argument("--bbox", nargs=4, type=float, required=True,
                   metavar=("LON_MIN", "LAT_MIN", "LON_MAX", "LAT_MAX"),
                   help="box in WGS84 degrees")
    p.add_argument("--dem-dir", "--srtm-dir", dest="srtm_dir", type=Path, default=None,
                   metavar="DIR",
                   help="folder of DEM tiles named as distributed (N44E005.hgt, "
                        "NASADEM_HGT_n44e005.hgt, Copernicus_DSM_COG_10_N54_00_W165_00_DEM.tif, "
                        "...) or of tagged lon/lat GeoTIFFs (default: the bundled N44E005 SRTM "
                        "tile over Mont Ventoux)")
    p.add_argument("--out", type=Path, required=True, help="output COG path (REF.tif)")
    p.add_argument("--margin-deg", type=float, default=0.0,
                   help="widen the box by this many degrees on every side (default 0)")
    p.add_argument("--allow-missing-tiles", action="store_true",
                   help="treat absent tiles (e.g. open sea) as voids instead of failing")
    p.add_argument("--geoid", type=Path, default=None, metavar="GRID", help=GEOID_HELP)
    add_vertical_argument(p, "--dem-vertical",
                          help="heights of tagged DEMs that do not say their datum (named "
                               "tiles say their own)")
    p.add_argument("--max-height-error", type=float, default=10.0, metavar="M",
                   help="void Copernicus cells whose height-error mask (HEM, 1 sigma) exceeds "
                        "this, metres (default 10)")
    p.add_argument("--hillshade", type=Path, default=None,
                   help="also write a shaded-relief PNG here")


def run(args: argparse.Namespace) -> int:
    from flows._env import prefect_api

    with prefect_api() as api:  # a temporary Prefect server boots meanwhile
        from flows.prepare_reference import ReferenceParams, prepare_reference
        from tasks.io.geoid import read_geoid
        from tasks.io.reference import locate_tiles

        params = ReferenceParams(
            bbox=tuple(args.bbox), out=args.out, srtm_dir=args.srtm_dir,
            margin_deg=args.margin_deg, allow_missing_tiles=args.allow_missing_tiles,
            geoid=args.geoid, hillshade_png=args.hillshade, vertical=args.dem_vertical,
            max_height_error_m=args.max_height_error)
        box = params.box()
        # check inputs before the flow starts, so bad input is one clean line
        if args.geoid is not None:
            read_geoid(args.geoid, box)
        tiles = locate_tiles.fn(params.source(), box, args.allow_missing_tiles, "--dem-vertical")
        print(f"heights        {tiles.describe()}")
        api.ready()
        summary = prepare_reference(params)
        print("\n".join(summary.lines()))
        if args.hillshade:
            print(f"hillshade      {args.hillshade}")
    return 0
