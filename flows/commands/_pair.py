"""Arguments and input checks shared by the commands that take a stereo pair."""

from __future__ import annotations

import argparse
from pathlib import Path

VERTICALS = ("auto", "ellipsoidal", "egm96")  # core.heights.VERTICAL_CHOICES (not imported:
# the parser is built without numpy, so --help answers at once)
VERTICAL_HELP = ("heights of REF: auto (default) reads its vertical_datum tag, then its CRS's "
                 "vertical part, then an SRTM name (.hgt, N44E005.tif: EGM96); a DEM none of "
                 "these describe is refused: say egm96 or ellipsoidal")


def add_pair_arguments(p: argparse.ArgumentParser, *, right_help: str = "right image") -> None:
    """``--left --right --left-model --right-model --band``."""
    p.add_argument("--left", type=Path, required=True, help="left image (its model stays fixed)")
    p.add_argument("--right", type=Path, required=True, help=right_help)
    p.add_argument("--left-model", type=Path, default=None,
                   help="model of the left image (.DIM, gcpfree .json, .geom, RPC .XML or a "
                        "GeoTIFF's RPC); default: found beside the image")
    p.add_argument("--right-model", type=Path, default=None, help="model of the right image")
    p.add_argument("--band", type=int, default=None,
                   help="SPOT multispectral band whose look angles to use (default the first)")


def add_reference_arguments(p: argparse.ArgumentParser, *, use: str) -> None:
    """``--reference | --srtm-dir`` and ``--reference-vertical``; ``use`` says what for."""
    ref = p.add_mutually_exclusive_group()
    ref.add_argument("--reference", type=Path, default=None, metavar="REF",
                     help="reference DEM in EPSG:4326 (prepare-reference output or SRTM .hgt)"
                          f": {use}")
    ref.add_argument("--srtm-dir", type=Path, default=None, metavar="DIR",
                     help="folder of SRTM tiles: a reference is prepared over the pair")
    p.add_argument("--reference-vertical", choices=VERTICALS,
                   default="auto", help=VERTICAL_HELP)


def add_orientation_arguments(p: argparse.ArgumentParser) -> None:
    """The GCP-free orientation's options (``orient``, ``pair``): check points, lens
    self-calibration, corrections, surface-matching windows, relief refusal."""
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


def add_run_arguments(p: argparse.ArgumentParser) -> None:
    """``--workers --no-progress --out`` (an output folder)."""
    p.add_argument("--workers", type=int, default=None,
                   help="parallel tiles of the dense matching (default: one per core)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--out", type=Path, required=True, help="output folder")


def check_orientation_arguments(args: argparse.Namespace, command: str):  # -> SurfaceMatchConfig
    """The reference, check points and window settings checked before Prefect starts;
    returns the surface-matching settings they make."""
    from dataclasses import replace

    from core.errors import InputError
    from core.surface_match import SurfaceMatchConfig
    from tasks.orient import read_checkpoints

    if args.reference is None and args.srtm_dir is None:
        raise InputError(f"gcpfree {command} needs a reference DEM: give --srtm-dir or "
                         "--reference")
    if args.checkpoints is not None:
        read_checkpoints(args.checkpoints)
    if args.min_windows < 1:
        raise InputError("--min-windows must be at least 1")
    return replace(SurfaceMatchConfig(), radius_m=args.window_radius,
                   shift_max_arcsec=args.max_shift)


def check_pair(args: argparse.Namespace):  # -> tuple[LoadedModel, LoadedModel]
    """Both models loaded and the reference checked before Prefect starts: bad input is one
    clean line (InputError)."""
    from core.errors import InputError
    from tasks.dem_io import check_reference, dem_datum
    from tasks.sensor_io import load_model

    for path in (args.left, args.right):
        if not Path(path).exists():
            raise InputError(f"{path} does not exist; give the two images of the pair")
    left = load_model(args.left, model=args.left_model, band=args.band)
    right = load_model(args.right, model=args.right_model, band=args.band)
    if args.reference is not None:
        check_reference(args.reference)
        # refused here in one line, or said before the long run starts
        print(f"reference      {args.reference}: "
              f"{dem_datum(args.reference, args.reference_vertical).describe()}")
    if args.srtm_dir is not None and not Path(args.srtm_dir).is_dir():
        raise InputError(f"SRTM directory {args.srtm_dir} does not exist")
    h_range = getattr(args, "height_range", None) or OVERLAP_HEIGHTS_M
    _check_overlap(left, right, h_range)
    if args.reference is not None:  # CoverageError when it misses the pair altogether
        from tasks.dem_io import read_reference
        from tasks.relative import pair_box

        read_reference(args.reference, pair_box(left, right, h_range), "ellipsoidal")
    if args.srtm_dir is not None:  # the tiles that would be used: EGM96 as SRTM is
        from tasks.dem_io import check_srtm_tiles
        from tasks.relative import pair_box
        from tasks.srtm import find_tiles

        check_srtm_tiles(find_tiles(args.srtm_dir, pair_box(left, right, h_range),
                                    allow_missing=True))
        print(f"reference      prepared from the SRTM tiles of {args.srtm_dir}: EGM96 "
              "orthometric heights, converted with h = H + N")
    return left, right


OVERLAP_HEIGHTS_M = (-500.0, 9000.0)  # any terrain on Earth


def _check_overlap(left, right, h_range: tuple[float, float]) -> None:  # LoadedModel x 2
    """GeometryError when the footprints meet at none of a few heights over ``h_range``: two
    images of different places (a reference or SRTM mosaic over both would be the size of a
    continent)."""
    import numpy as np

    from core.errors import GeometryError
    from tasks.relative import check_overlap

    lo, hi = sorted(map(float, h_range))
    for h in np.linspace(lo, hi, 8):
        try:
            check_overlap(left, right, float(h))
            return
        except GeometryError:
            pass
    raise GeometryError(
        f"{left.image or left.source} and {right.image or right.source} do not overlap under "
        f"their sensor models at any height in {lo:.0f}..{hi:.0f} m; give two images of the "
        "same area, and check that each model belongs to its image")
