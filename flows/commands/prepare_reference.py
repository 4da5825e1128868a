"""``gcpfree prepare-reference``: SRTM tiles + EGM96 -> the WGS84 ellipsoidal reference DEM
(flow ``prepare-reference``, :mod:`flows.prepare_reference`)."""

from __future__ import annotations

import argparse
from pathlib import Path


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "prepare-reference",
        help="SRTM tiles + EGM96 -> WGS84 ellipsoidal reference DEM (Cloud-Optimized GeoTIFF)",
        description=(
            "Mosaic the SRTM tiles (.hgt or GeoTIFF, 1\" or 3\") covering a lon/lat box, mark "
            "voids (-32768) as NaN, convert orthometric heights H to ellipsoidal heights "
            "h = H + N (EGM96) and write a float32 COG with overviews, plus REF.voids.tif "
            "(0 valid, 1 void, 2 no tile) and REF.json (the printed summary)."
        ),
    )
    p.add_argument("--bbox", nargs=4, type=float, required=True,
                   metavar=("LON_MIN", "LAT_MIN", "LON_MAX", "LAT_MAX"),
                   help="box in WGS84 degrees")
    p.add_argument("--srtm-dir", type=Path, default=None,
                   help="folder of SRTM tiles named like N44E005.hgt (default: the bundled "
                        "N44E005 tile over Mont Ventoux)")
    p.add_argument("--out", type=Path, required=True, help="output COG path (REF.tif)")
    p.add_argument("--margin-deg", type=float, default=0.0,
                   help="widen the box by this many degrees on every side (default 0)")
    p.add_argument("--allow-missing-tiles", action="store_true",
                   help="treat absent tiles (e.g. open sea) as voids instead of failing")
    p.add_argument("--geoid", type=Path, default=None,
                   help="geoid grid in GTX format (default: bundled EGM96 15')")
    p.add_argument("--hillshade", type=Path, default=None,
                   help="also write a shaded-relief PNG here")


def run(args: argparse.Namespace) -> int:
    from flows._env import prefect_api

    with prefect_api() as api:  # a temporary Prefect server boots meanwhile
        from core.geodesy import BBox
        from tasks.io.geoid import BUNDLED_SRTM_DIR
        from tasks.io.srtm import find_tiles

        params_box = BBox(*args.bbox).expanded(args.margin_deg)
        # check inputs before the flow starts, so bad input is one clean line
        tiles = find_tiles(args.srtm_dir or BUNDLED_SRTM_DIR, params_box,
                           allow_missing=args.allow_missing_tiles)
        from tasks.io.dem import check_srtm_tiles

        check_srtm_tiles(tiles)
        print(f"heights        {len(tiles)} SRTM tile(s): EGM96 orthometric heights, converted with "
              "h = H + N")
        if args.geoid is not None:
            from tasks.io.geoid import read_gtx
            read_gtx(args.geoid)

        from flows.prepare_reference import ReferenceParams, prepare_reference

        api.ready()
        summary = prepare_reference(ReferenceParams(
            bbox=tuple(args.bbox), out=args.out, srtm_dir=args.srtm_dir, margin_deg=args.margin_deg,
            allow_missing_tiles=args.allow_missing_tiles, geoid=args.geoid,
            hillshade_png=args.hillshade,
        ))
        print("\n".join(summary.lines()))
        if args.hillshade:
            print(f"hillshade      {args.hillshade}")
    return 0
