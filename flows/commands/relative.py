"""``gcpfree relative``: tie points and the relative orientation of a stereo pair."""

from __future__ import annotations

import argparse
from pathlib import Path

from core.choices import CORRECTIONS
from flows.commands._pair import add_pair_arguments, add_reference_arguments, check_pair


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
    add_pair_arguments(p, right_help="right image (its model is adjusted)")
    add_reference_arguments(p, use="heights of the tie points' search and the along-epipolar "
                                   "correction")
    p.add_argument("--height-range", type=float, nargs=2, metavar=("MIN", "MAX"), default=None,
                   help="ellipsoidal height range of the scene when there is no reference "
                        "(default for RPCs: their own height offset +- scale)")
    p.add_argument("--corrections", choices=CORRECTIONS, default="linear",
                   help="linear (default): attitude biases and rates / an RPC affine; offset: "
                        "biases / an RPC shift only")
    p.add_argument("--cell-m", type=float, default=2000.0,
                   help="keep the best tie point per ground cell of this size (default 2000 m; "
                        "reduced so that the overlap holds at least 8 x 8 cells)")
    p.add_argument("--search-radius-m", type=float, default=None,
                   help="ground uncertainty of each image's metadata to search over (default: "
                        "30 pixels, between 10 and 300 m)")
    p.add_argument("--out", type=Path, required=True, help="output rel.json")


def run(args: argparse.Namespace) -> int:
    from flows._env import prefect_api

    with prefect_api() as api:  # a temporary Prefect server boots meanwhile
        pair, _, _ = check_pair(args)
        from flows.relative import RelativeParams, relative_flow

        api.ready()
        outcome = relative_flow(RelativeParams(
            pair=pair, out=args.out,
            height_range_m=tuple(args.height_range) if args.height_range else None,
            corrections=args.corrections, cell_m=args.cell_m,
            search_radius_m=args.search_radius_m))
        print("\n".join(outcome.lines))
    return 0
