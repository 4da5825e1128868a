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
    check_sar_arguments,
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
            "and OUT/dsm_egm96.tif, OUT/relative_dem.tif and OUT/relative/. With --sar, "
            "SAR-optical GCPs too (OUT/sar_points.json), which also orient flat terrain."),
    )
    add_pair_arguments(p)
    add_reference_arguments(p, use="the ground the pair is oriented to (required, or "
                                   "--dem-dir)")
    add_orientation_arguments(p)
    add_reference_sigma_argument(p)
    add_run_arguments(p)


def add_reference_sigma_argument(p: argparse.ArgumentParser) -> None:
    """``--reference-sigma E N U``, shared by ``orient`` and ``pair``."""
    p.add_argument("--reference-sigma", nargs=3, type=float, default=(5.0, 5.0, 5.0),
                   metavar=("E", "N", "U"),
                   help="registration error of the reference DEM, east, north and up in "
                        "metres, 1 sigma (default 5 5 5): the GCP-free orientation cannot see "
                        "it, so the predicted check-point RMS in report.json adds it")


def reference_sigma_m(args: argparse.Namespace) -> tuple[float, float, float]:
    """``--reference-sigma`` checked: three finite metres, each >= 0 (InputError else)."""
    import math

    from core.errors import InputError

    values = tuple(float(v) for v in args.reference_sigma)
    if len(values) != 3 or not all(math.isfinite(v) and v >= 0 for v in values):
        raise InputError(f"--reference-sigma takes three finite sigmas in metres (east north "
                         f"up), each >= 0; got {' '.join(f'{v:g}' for v in values)}")
    return values  # type: ignore[return-value]


def run(args: argparse.Namespace) -> int:
    from flows._env import prefect_api

    sigma = reference_sigma_m(args)  # refused in a line, before the server boots
    with prefect_api() as api:  # a temporary Prefect server boots meanwhile
        checked = check_pair(args)
        surface = check_orientation_arguments(args, "orient", checked)
        check_sar_arguments(args)
        pair = checked[0]
        from core.orientation.absolute import AbsoluteConfig
        from flows.orient import OrientParams, orient_flow

        api.ready()
        outcome = orient_flow(OrientParams(
            pair=pair, out=args.out, checkpoints=args.checkpoints, self_calibrate=args.self_calibrate,
            along_track=args.along_track,
            corrections=args.corrections, spacing_m=args.window_spacing,
            min_windows=args.min_windows, workers=args.workers, progress=not args.no_progress,
            surface=surface, absolute=AbsoluteConfig(reference_sigma_m=sigma), sar=args.sar,
            sar_model=args.sar_model, sar_sigma_m=args.sar_sigma))
        print("\n".join(outcome.lines()))
    return 0
