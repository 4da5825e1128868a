"""``gcpfree project``: ground points (``lon,lat,h``) through a sensor model into image
coordinates (adds ``col,row``; for SAR also ``azimuth_time_utc`` and ``slant_range_time_s``).

No flow, by design (as ``info``): one model file and one CSV answer in about a second; plain
functions of :mod:`tasks.io.model_points`."""

from __future__ import annotations

import argparse
from pathlib import Path

MODEL_HELP = ("the sensor model: a model file (.DIM, gcpfree .json, .geom, DIMAP v2 RPC .XML, "
              "Sentinel-1 annotation .xml) or an image whose model is found beside it (then "
              "col,row are that raster's pixels)")


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "project",
        help="ground points lon,lat,h -> image col,row through a sensor model (CSV in, CSV out)",
        description=(
            "Read a CSV whose header has lon,lat,h (WGS84 degrees, ellipsoidal metres), project "
            "every point through the model and write the same rows with col,row added (0-based, "
            "pixel centres at integers); for a SAR model also azimuth_time_utc (ISO 8601) and "
            "slant_range_time_s (two-way). Other columns are kept."),
    )
    add_points_arguments(p, reads="lon,lat,h", adds="col,row")


def add_points_arguments(p: argparse.ArgumentParser, *, reads: str, adds: str) -> None:
    """``--model --points --out`` of ``project`` and ``localize``: a CSV holding the columns
    ``reads`` through the model into one with ``adds`` too."""
    p.add_argument("--model", type=Path, required=True, metavar="M", help=MODEL_HELP)
    p.add_argument("--points", type=Path, required=True, metavar="IN.csv",
                   help=f"CSV with a header holding {reads}")
    p.add_argument("--out", type=Path, required=True, metavar="OUT.csv",
                   help=f"the CSV to write (the input's columns plus {adds})")


def run(args: argparse.Namespace) -> int:
    from tasks.io.model_points import project_points

    out = project_points(args.model, args.points, args.out)
    print(f"{'points':<14} {out}")
    return 0
