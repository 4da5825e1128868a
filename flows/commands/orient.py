"""``gcpfree orient``: a stereo pair oriented with no GCP, from SRTM alone (steps 1-4)."""

from __future__ import annotations

import argparse
from pathlib import Path

from flows.commands._pair import add_pair_arguments, add_reference_arguments, check_pair


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
    p.add_argument("--checkpoints", type=Path, default=None, metavar="FILE",
                   help="independent check points: the simulator's truth/checkpoints.json or a "
                        "CSV id,lon_deg,lat_deg,h_m,left_col,left_row,right_col,right_row "
                        "(ellipsoidal heights, 0-based pixels)")
    p.add_argument("--self-calibrate", action="store_true",
                   help="estimate lens distortion (k1, k3, p1, p2) of pushbroom images, kept "
                        "only where significant")
    p.add_argument("--corrections", choices=("offset", "linear"), default="linear",
                   help="terms adjusted per image: linear (default, attitude biases and rates / "
                        "RPC affine) or offset (biases / RPC shift)")
    p.add_argument("--window-radius", type=float, default=4000.0, metavar="M",
                   help="radius of the surface-matching windows, metres (default 4000)")
    p.add_argument("--window-spacing", type=float, default=None, metavar="M",
                   help="distance between window centres (default: the radius)")
    p.add_argument("--max-shift", type=float, default=20.0, metavar="ARCSEC",
                   help="largest horizontal shift searched, arcseconds (default 20)")
    p.add_argument("--min-windows", type=int, default=8,
                   help="windows with enough relief needed, else the terrain is refused as too "
                        "flat (default 8)")
    p.add_argument("--workers", type=int, default=None,
                   help="parallel tiles of the dense matching (default: one per core)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--out", type=Path, required=True, help="output folder")


def run(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from core.errors import InputError
    from core.surface_match import SurfaceMatchConfig
    from tasks.orient import read_checkpoints

    check_pair(args)
    if args.reference is None and args.srtm_dir is None:
        raise InputError("gcpfree orient needs a reference DEM: give --srtm-dir or --reference")
    if args.checkpoints is not None:
        read_checkpoints(args.checkpoints)
    if args.min_windows < 1:
        raise InputError("--min-windows must be at least 1")
    surface = replace(SurfaceMatchConfig(), radius_m=args.window_radius,
                      shift_max_arcsec=args.max_shift)
    from flows.orient import OrientParams, orient_flow

    outcome = orient_flow(OrientParams(
        left=args.left, right=args.right, out=args.out, left_model=args.left_model,
        right_model=args.right_model, band=args.band, reference=args.reference,
        reference_vertical=args.reference_vertical, srtm_dir=args.srtm_dir,
        checkpoints=args.checkpoints, self_calibrate=args.self_calibrate,
        corrections=args.corrections, spacing_m=args.window_spacing,
        min_windows=args.min_windows, workers=args.workers, progress=not args.no_progress,
        surface=surface))
    print("\n".join(outcome.lines()))
    return 0
