"""``gcpfree orient``: a stereo pair oriented with no GCP, from SRTM alone (steps 1-4)."""

from __future__ import annotations

import argparse

from flows.commands._pair import (
    add_orientation_arguments,
    add_pair_arguments,
    add_reference_arguments,
    add_run_arguments,
    check_orientation_arguments,
    check_pair,
)


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "orient",
        help="orient a stereo pair without GCPs: relative, relative DEM, SRTM surface "
             "matching, absolute",
        description=(
            "Relative orientation of the pair, its relative DEM by dense matching, windows of "
            "that DEM around the tie points matched to the reference DEM (SRTM) into simulated "
            "GCPs, and the absolute orientation of both images on them (robust least squares, "
            "blunders rejected, optional lens self-calibration). Refuses terrain too flat to "
            "fix the position. The final DSM is the relative DEM's matches intersected again "
            "with the oriented models. Writes OUT/report.json, the oriented models OUT/left.json "
            "and OUT/right.json, OUT/gcps.json, OUT/windows.json, OUT/dsm.tif (ellipsoidal) "
            "and OUT/dsm_egm96.tif, OUT/relative_dem.tif and OUT/relative/."),
    )
    add_pair_arguments(p)
    add_reference_arguments(p, use="the ground the pair is oriented to (required, or "
                                   "--srtm-dir)")
    add_orientation_arguments(p)
    add_run_arguments(p)


def run(args: argparse.Namespace) -> int:
    from flows._env import prefect_api

    with prefect_api() as api:  # a temporary Prefect server boots meanwhile
        checked = check_pair(args)
        surface = check_orientation_arguments(args, "orient", checked)
        pair = checked[0]
        from flows.orient import OrientParams, orient_flow

        api.ready()
        outcome = orient_flow(OrientParams(
            pair=pair, out=args.out, checkpoints=args.checkpoints, self_calibrate=args.self_calibrate,
            along_track=args.along_track,
            corrections=args.corrections, spacing_m=args.window_spacing,
            min_windows=args.min_windows, workers=args.workers, progress=not args.no_progress,
            surface=surface))
        print("\n".join(outcome.lines()))
    return 0
