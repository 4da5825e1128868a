"""``gcpfree info``: the sensor model of an image (corners, viewing angles, GSD) and the
geometry of a pair.

No flow, by design: info reads one or two model files and answers in about a second, where
Prefect would add its own start (an ephemeral API server, several seconds) for nothing a
dashboard would show or a rerun would resume. Plain functions of :mod:`tasks.io.sensor_info`."""

from __future__ import annotations

import argparse
from pathlib import Path

from flows.commands._pair import add_vertical_argument


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "info",
        help="sensor model, corners, viewing angles, GSD of an image; B/H and overlap of a pair",
        description=(
            "Find and read the sensor model of an image (SPOT METADATA.DIM or .DIM beside it, "
            "gcpfree pushbroom .json of the same name, RPC .geom or RPC tags) or read a model "
            "file given alone (.DIM, .json, .geom, DIMAP v2 RPC .XML, Sentinel-1 annotation "
            ".xml), and print: the model, the acquisition time, the corners at h = 0 (WGS84 "
            "ellipsoid), the incidence, "
            "azimuth and GSD at the image centre, the SPOT metadata self-check (stated corners "
            "against the model), the Sentinel-1 grid check (the SAR model against the "
            "annotation's geolocation grid), the mean terrain height and the corners at that "
            "height (--reference). With two images: convergence angle, B/H and overlap."
        ),
    )
    p.add_argument("image", type=Path, metavar="IMAGE_OR_MODEL",
                   help="an image (GeoTIFF...) or a model file (.DIM, .json, .geom, RPC .XML, "
                        "Sentinel-1 annotation .xml)")
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
    add_vertical_argument(p, "--reference-vertical")


def run(args: argparse.Namespace) -> int:
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
