"""``gcpfree relative``: tie points and the relative orientation of a stereo pair."""

from __future__ import annotations

import argparse
from pathlib import Path


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "relative",
        help="tie points and relative orientation of a stereo pair (right model adjusted)",
        description=(
            "Find tie points between two images of a stereo pair (interest points, correlation "
            "around the position the metadata predict, back-matching, the best point per "
            "ground cell) and adjust the right image's model to the left one so that their "
            "rays meet: y-parallax minimised by robust Gauss-Newton, outliers rejected. A "
            "correction along the epipolar lines cannot be seen by tie points: it is set from "
            "the reference DEM when one is given, else held at the metadata. Writes rel.json "
            "(figures, the correction, the adjusted right model) and rel.tiepoints.json."
        ),
    )
    p.add_argument("--left", type=Path, required=True, help="left image (its model stays fixed)")
    p.add_argument("--right", type=Path, required=True, help="right image (its model is adjusted)")
    p.add_argument("--left-model", type=Path, default=None,
                   help="model of the left image (.DIM, gcpfree .json, .geom or RPC .XML); "
                        "default: found beside the image")
    p.add_argument("--right-model", type=Path, default=None, help="model of the right image")
    p.add_argument("--band", type=int, default=None,
                   help="SPOT multispectral band whose look angles to use (default the first)")
    ref = p.add_mutually_exclusive_group()
    ref.add_argument("--reference", type=Path, default=None,
                     help="reference DEM in EPSG:4326 (the output of prepare-reference, or an "
                          "SRTM .hgt)")
    ref.add_argument("--srtm-dir", type=Path, default=None,
                     help="folder of SRTM tiles: a reference is prepared over the pair")
    p.add_argument("--reference-vertical", choices=("auto", "ellipsoidal", "egm96"),
                   default="auto", help="heights of --reference (auto: .hgt and SRTM-named "
                                        "files are EGM96, others ellipsoidal)")
    p.add_argument("--height-range", type=float, nargs=2, metavar=("MIN", "MAX"), default=None,
                   help="ellipsoidal height range of the scene when there is no reference "
                        "(default for RPCs: their own height offset +- scale)")
    p.add_argument("--corrections", choices=("offset", "linear"), default="linear",
                   help="linear (default): attitude biases and rates / an RPC affine; offset: "
                        "biases / an RPC shift only")
    p.add_argument("--cell-m", type=float, default=2000.0,
                   help="keep the best tie point per ground cell of this size (default 2000 m)")
    p.add_argument("--search-radius-m", type=float, default=None,
                   help="ground uncertainty of each image's metadata to search over (default: "
                        "30 pixels, between 10 and 300 m)")
    p.add_argument("--out", type=Path, required=True, help="output rel.json")


def run(args: argparse.Namespace) -> int:
    from core.errors import InputError
    from tasks.dem_io import check_reference
    from tasks.sensor_io import load_model

    for path in (args.left, args.right):
        if not Path(path).exists():
            raise InputError(f"{path} does not exist; give the two images of the pair")
    # check the models and the reference before Prefect starts: bad input is one clean line
    load_model(args.left, model=args.left_model, band=args.band)
    load_model(args.right, model=args.right_model, band=args.band)
    if args.reference is not None:
        check_reference(args.reference)
    if args.srtm_dir is not None and not Path(args.srtm_dir).is_dir():
        raise InputError(f"SRTM directory {args.srtm_dir} does not exist")
    from flows.relative import RelativeParams, relative_flow

    outcome = relative_flow(RelativeParams(
        left=args.left, right=args.right, out=args.out, left_model=args.left_model,
        right_model=args.right_model, band=args.band, reference=args.reference,
        reference_vertical=args.reference_vertical, srtm_dir=args.srtm_dir,
        height_range_m=tuple(args.height_range) if args.height_range else None,
        corrections=args.corrections, cell_m=args.cell_m,
        search_radius_m=args.search_radius_m))
    print("\n".join(outcome.lines))
    return 0
