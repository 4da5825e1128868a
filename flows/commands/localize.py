"""``gcpfree localize``: image points at heights (``col,row,h``) through a sensor model back to
the ground (adds ``lon,lat``; for SAR also ``azimuth_time_utc`` and ``slant_range_time_s``).

No flow, by design (as ``info``): plain functions of :mod:`tasks.io.model_points`."""

from __future__ import annotations

import argparse

from flows.commands.project import add_points_arguments


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "localize",
        help="image points col,row at height h -> ground lon,lat through a sensor model (CSV)",
        description=(
            "Read a CSV whose header has col,row,h (0-based pixels with centres at integers, "
            "ellipsoidal metres), intersect each line of sight (for SAR: range sphere and "
            "zero-Doppler plane) with the ellipsoid raised by h and write the same rows with "
            "lon,lat added (WGS84 degrees); for a SAR model also azimuth_time_utc (ISO 8601) "
            "and slant_range_time_s (two-way). Other columns are kept."),
    )
    add_points_arguments(p, reads="col,row,h", adds="lon,lat")


def run(args: argparse.Namespace) -> int:
    from tasks.io.model_points import localize_points

    out = localize_points(args.model, args.points, args.out)
    print(f"{'points':<14} {out}")
    return 0
