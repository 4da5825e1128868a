"""``gcpfree pair``: the whole chain for one stereo pair (flow ``pair``, :mod:`flows.pair`),
resumable."""

from __future__ import annotations

import argparse
from pathlib import Path

from flows.commands._pair import add_lidar_vertical_argument, check_reference_sigma
from flows.commands.orient import add_orient_arguments, orient_params


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "pair",
        help="the whole chain for one pair: orient, orthos, lidar evaluation, report, STAC",
        description=(
            "Everything gcpfree does for one stereo pair, as the Prefect flow pair: "
            "orientation without GCP (as gcpfree orient), the orthos of both images and their "
            "discrepancy, the final DSM against lidar per class (with --lidar), the report "
            "(report.html, report.md), a STAC catalog of the rasters (OUT/stac/catalog.json) "
            "and OUT/pair.json, the manifest written last. A rerun keeps every step whose "
            "products read back and redoes the rest, so an interrupted pair resumes."),
    )
    add_orient_arguments(p, _add_evaluation_arguments)


def _add_evaluation_arguments(p: argparse.ArgumentParser) -> None:
    """``--lidar --landcover --lidar-vertical --id``: the evaluation and the STAC items."""
    p.add_argument("--lidar", type=Path, default=None, metavar="LAS",
                   help="lidar LAS/LAZ to evaluate the final DSM against (any CRS)")
    p.add_argument("--landcover", type=Path, default=None, metavar="TIF",
                   help="land-cover raster classifying the evaluation (needs --lidar)")
    add_lidar_vertical_argument(p)
    p.add_argument("--id", dest="pair_id", default=None,
                   help="name of the pair in the STAC items (default: OUT's folder name)")


def _check_evaluation(args: argparse.Namespace) -> None:
    """The lidar and land-cover files read and their options checked (InputError), before
    the orientation's minutes."""
    from core.errors import InputError

    for name in ("lidar", "landcover"):
        path = getattr(args, name)
        if path is not None and not path.is_file():
            raise InputError(f"--{name} {path} does not exist; give an existing file")
    if args.landcover is not None and args.lidar is None:
        raise InputError("--landcover classifies the lidar evaluation: give --lidar too")
    if args.lidar is not None:  # its header now, not after the orientation's minutes
        from tasks.io.lidar import inspect_lidar

        inspect_lidar(args.lidar, vertical=args.lidar_vertical)
    if args.landcover is not None:
        from tasks.io.rasters import open_raster

        with open_raster(args.landcover, "land cover"):
            pass


def run(args: argparse.Namespace) -> int:
    from flows._env import prefect_api

    check_reference_sigma(args)  # refused in a line, before the server boots
    with prefect_api() as api:  # a temporary Prefect server boots meanwhile
        orient = orient_params(args, "pair", _check_evaluation)
        from flows.pair import PairParams, pair_flow

        api.ready()
        outcome = pair_flow(PairParams(orient=orient, lidar=args.lidar, landcover=args.landcover,
                                       lidar_vertical=args.lidar_vertical,
                                       pair_id=args.pair_id))
        print("\n".join(outcome.lines()))
    return 0
