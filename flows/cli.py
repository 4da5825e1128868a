"""The ``gcpfree`` command line."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from flows import evaluate as evaluate_command
from flows._env import configure_environment, one_line_errors
from flows.commands import archive as archive_command
from flows.commands import coregister as coregister_command
from flows.commands import dsm as dsm_command
from flows.commands import fill_voids as fill_voids_command
from flows.commands import orient as orient_command
from flows.commands import ortho as ortho_command
from flows.commands import ortho_compare as ortho_compare_command
from flows.commands import pair as pair_command
from flows.commands import relative as relative_command
from flows.commands import report as report_command
from flows.commands import serve as serve_command
from flows.commands._pair import VERTICAL_HELP, VERTICALS, OneLineParser


def _add_prepare_reference(sub: argparse._SubParsersAction) -> None:
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


def _run_prepare_reference(args: argparse.Namespace) -> int:
    from core.geodesy import BBox
    from tasks.io.geoid import BUNDLED_SRTM_DIR
    from tasks.io.srtm import find_tiles

    params_box = BBox(*args.bbox).expanded(args.margin_deg)
    # check inputs before starting Prefect, so bad input is one clean line
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

    summary = prepare_reference(ReferenceParams(
        bbox=tuple(args.bbox), out=args.out, srtm_dir=args.srtm_dir, margin_deg=args.margin_deg,
        allow_missing_tiles=args.allow_missing_tiles, geoid=args.geoid,
        hillshade_png=args.hillshade,
    ))
    print("\n".join(summary.lines()))
    if args.hillshade:
        print(f"hillshade      {args.hillshade}")
    return 0


def _add_simulate(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "simulate",
        help="render a SPOT-like stereo pair with known truth over a real DEM",
        description=(
            "Simulate a SPOT-like stereo pair over a DEM: truth DSM/DTM/land cover (COG), two "
            "8- or 12-bit images with the fitted RPC of their delivered metadata inside and the "
            "delivered pushbroom model (JSON) beside them, truth models, check points and lidar "
            "(LAZ) under DIR/truth/. Same seed, same bytes; a rerun resumes."
        ),
    )
    p.add_argument("--dem", type=Path, default=None,
                   help="DEM in EPSG:4326 (GeoTIFF or .hgt); default: the bundled SRTM tile "
                        "N44E005")
    p.add_argument("--dem-vertical", choices=VERTICALS, default="auto",
                   help=VERTICAL_HELP.replace("REF", "DEM"))
    p.add_argument("--out", type=Path, required=True, help="output folder DIR")
    p.add_argument("--preset", choices=("tiny", "spot", "hrs"), default="tiny",
                   help="tiny: 600x600 px at 40 m (CI); spot: 6000x6000 px at 10 m, "
                        "across-track +25.5/-20 deg from two dates; hrs: along-track +-20 deg")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--center", nargs=2, type=float, metavar=("LON", "LAT"), default=None,
                   help="scene centre in degrees (default: the DEM's centre)")
    p.add_argument("--lens", action="store_true",
                   help="truth camera has lens distortion the delivered metadata lack")
    p.add_argument("--jitter", action="store_true",
                   help="truth attitude has high-frequency jitter the metadata lack")
    p.add_argument("--date-change", type=float, default=0.0, metavar="F",
                   help="fraction of the scene changed between the dates (vegetation, snow, "
                        "cloud); default 0")
    p.add_argument("--relief-factor", type=float, default=1.0, metavar="K",
                   help="scale the relief by K (0.05: nearly flat); default 1")
    p.add_argument("--bits", type=int, choices=(8, 12), default=8, help="image depth (default 8)")
    p.add_argument("--no-lidar", action="store_true", help="skip the truth lidar")


def _run_simulate(args: argparse.Namespace) -> int:
    from tasks.simulate.io import check_dem

    dem = args.dem
    if dem is None:
        from flows.simulate_scene import BUNDLED_DEM
        dem = BUNDLED_DEM
    check_dem(dem)
    from tasks.io.dem import dem_datum

    print(f"DEM              {dem}: "
          f"{dem_datum(dem, args.dem_vertical, what='DEM', option='--dem-vertical').describe()}")
    from flows.simulate_scene import SimulationParams, simulate_scene

    summary = simulate_scene(SimulationParams(
        out=args.out, dem=dem, preset=args.preset, seed=args.seed, lens=args.lens,
        jitter=args.jitter, date_change=args.date_change, relief_factor=args.relief_factor,
        bits=args.bits, center=tuple(args.center) if args.center else None,
        lidar=not args.no_lidar, dem_vertical=args.dem_vertical,
    ))
    print("\n".join(summary.lines()))
    return 0




def _add_info(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "info",
        help="sensor model, corners, viewing angles, GSD of an image; B/H and overlap of a pair",
        description=(
            "Find and read the sensor model of an image (SPOT METADATA.DIM or .DIM beside it, "
            "gcpfree pushbroom .json of the same name, RPC .geom or RPC tags) or read a model "
            "file given alone (.DIM, .json, .geom, DIMAP v2 RPC .XML), and print: the model, "
            "the acquisition time, the corners at h = 0 (WGS84 ellipsoid), the incidence, "
            "azimuth and GSD at the image centre, the SPOT metadata self-check (stated corners "
            "against the model), the mean terrain height and the corners at that height "
            "(--reference). With two images: convergence angle, B/H and overlap."
        ),
    )
    p.add_argument("image", type=Path, metavar="IMAGE_OR_MODEL",
                   help="an image (GeoTIFF...) or a model file (.DIM, .json, .geom, RPC .XML)")
    p.add_argument("image2", type=Path, nargs="?", default=None, metavar="IMAGE2",
                   help="a second image or model file: adds the pair geometry")
    p.add_argument("--json", type=Path, default=None, metavar="FILE",
                   help="also write everything as JSON to FILE")
    p.add_argument("--band", type=int, default=None, metavar="N",
                   help="SPOT band (BAND_INDEX, 1-based) whose look angles to use, for both "
                        "images (default: the first band)")
    p.add_argument("--model", type=Path, default=None, metavar="FILE",
                   help="the sensor model file of IMAGE_OR_MODEL (default: found beside it)")
    p.add_argument("--model2", type=Path, default=None, metavar="FILE",
                   help="the sensor model file of IMAGE2 (default: found beside it)")
    p.add_argument("--reference", type=Path, default=None, metavar="REF",
                   help="DEM in EPSG:4326 (GeoTIFF or .hgt): mean terrain height under each "
                        "footprint, corners and view at that height")
    p.add_argument("--reference-vertical", choices=VERTICALS, default="auto",
                   help=VERTICAL_HELP)


def _run_info(args: argparse.Namespace) -> int:
    # plain functions, no Prefect: info answers in about a second
    from tasks.io.sensor_info import check_json_target, gather_info, write_info_json

    if args.json is not None:
        check_json_target(args.json)
    report = gather_info(
        args.image, args.image2, model=args.model, model2=args.model2, band=args.band,
        reference=args.reference, vertical=args.reference_vertical,
    )
    print("\n".join(report.lines()))
    if args.json is not None:
        write_info_json(report, args.json)
        print(f"{'json':<14} {args.json}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(
        prog="gcpfree",
        description="Orient satellite stereo pairs without ground control points, using SRTM.",
    )
    parser.add_argument("--verbose", action="store_true",
                        help="show Prefect's and Dask's progress logs (off by default)")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    _add_prepare_reference(sub)
    _add_simulate(sub)
    _add_info(sub)
    for module in COMMAND_MODULES.values():
        module.add_parser(sub)
    return parser


COMMAND_MODULES = {"relative": relative_command, "evaluate": evaluate_command,
                   "coregister": coregister_command, "dsm": dsm_command,
                   "orient": orient_command, "pair": pair_command,
                   "report": report_command, "ortho": ortho_command,
                   "ortho-compare": ortho_compare_command, "fill-voids": fill_voids_command,
                   "archive": archive_command, "serve": serve_command}
COMMANDS = {"prepare-reference": _run_prepare_reference, "simulate": _run_simulate,
            "info": _run_info, **{name: m.run for name, m in COMMAND_MODULES.items()}}


def main(argv: Sequence[str] | None = None) -> int:
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as exc:  # --help (0), or a one-line argument error (2)
        return int(exc.code or 0)
    configure_environment(verbose=args.verbose)
    from core.errors import GcpFreeError

    try:
        with one_line_errors():
            return COMMANDS[args.command](args)
    except GcpFreeError as exc:
        print(f"gcpfree {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("gcpfree: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
