"""``gcpfree dsm``: a stereo pair's DSM by dense matching (relative orientation first)."""

from __future__ import annotations

import argparse
from pathlib import Path

from core.choices import DATUMS
from flows.commands._pair import add_pair_arguments, add_reference_arguments, check_pair


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "dsm",
        help="DSM of a stereo pair by dense matching (relative orientation first)",
        description=(
            "Orient the pair (the right model adjusted to the left one), cut the left region "
            "of interest into tiles, rectify each (an affine per image), match it by "
            "semi-global matching with a left-right check, triangulate every match with the "
            "models and grid the points in the local UTM zone (median per cell, holes under 5 "
            "cells filled). Writes OUT (float32 heights, NaN nodata), OUT_mask.tif (0 valid, "
            "1 mismatch, 2 occluded/outside) and OUT.json (figures per tile)."),
    )
    add_pair_arguments(p)
    for action in p._actions:  # --images may replace them
        if action.dest in ("left", "right"):
            action.required = False
    p.add_argument("--images", type=Path, nargs="+", default=None, metavar="IMAGE",
                   help="N >= 2 views of one area instead of --left/--right (models found "
                        "beside them): one joint relative orientation (the first fixed), "
                        "every overlapping pair matched, their heights fused per cell; "
                        "OUT_views.tif counts the images behind each cell")
    p.add_argument("--fusion", choices=("weighted_median", "weighted_mean", "median"),
                   default="weighted_median",
                   help="with --images, a cell's height from its pairs' (each weighted by "
                        "(B/H)^2): weighted_median (default; on a one-pass triplet the widest "
                        "pair's, the others where it has none), weighted_mean (of the pairs "
                        "within 3 robust sigmas of the weighted median; best when the pairs' "
                        "errors are independent) or median")
    p.add_argument("--roi", type=int, nargs=4, default=None,
                   metavar=("COL", "ROW", "WIDTH", "HEIGHT"),
                   help="region of the left (first) image (pixels); default the whole image")
    p.add_argument("--resolution", type=float, default=None, metavar="M",
                   help="DSM cell size in metres (default 2 x the left image's GSD)")
    add_reference_arguments(p, use="sizes the disparity search")
    p.add_argument("--height-range", type=float, nargs=2, default=None, metavar=("MIN", "MAX"),
                   help="ellipsoidal height range of the scene when there is no reference "
                        "(default for RPCs: their height offset +- scale)")
    p.add_argument("--vertical", choices=DATUMS, default="ellipsoidal",
                   help="heights of the DSM: WGS84 ellipsoidal (default) or EGM96 orthometric")
    p.add_argument("--margin", type=float, default=50.0, metavar="M",
                   help="height uncertainty searched around the reference, metres (default 50)")
    p.add_argument("--tile-px", type=int, default=1000,
                   help="tile size in left-image pixels (default 1000)")
    p.add_argument("--min-match-rate", type=float, default=0.2, metavar="F",
                   help="refuse the pair when less than this fraction of the overlap matches "
                        "(default 0.2)")
    p.add_argument("--no-orient", action="store_true",
                   help="use the models as they are (skip the relative orientation)")
    p.add_argument("--no-pointing-correction", action="store_true",
                   help="do not correct each tile's residual y-parallax from patch matches")
    p.add_argument("--workers", type=int, default=None,
                   help="parallel tiles (default: one per core)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--out", type=Path, required=True, help="output DSM (GeoTIFF, COG)")


def run(args: argparse.Namespace) -> int:
    from flows._env import prefect_api

    with prefect_api() as api:  # a temporary Prefect server boots while the inputs are checked
        from core.errors import InputError
        from tasks.dense.blocks import check_roi

        images = _check_images(args)
        pair, left, _ = check_pair(args)
        check_roi(tuple(args.roi) if args.roi else None, left.size)
        if images:
            from tasks.io.sensors import load_model

            for image in images[2:]:
                load_model(image, band=pair.band)  # a missing model is one line too
        out_dir = Path(args.out).resolve().parent
        if not out_dir.is_dir():
            raise InputError(f"the folder of --out ({out_dir}) does not exist; create it first")
        from flows.dsm import DsmParams, dsm_flow

        params = DsmParams(
            pair=pair, out=args.out, roi=tuple(args.roi) if args.roi else None,
            resolution_m=args.resolution,
            height_range_m=tuple(args.height_range) if args.height_range else None,
            vertical=args.vertical, orient=not args.no_orient, margin_m=args.margin,
            tile_px=args.tile_px, min_match_rate=args.min_match_rate,
            pointing_correction=not args.no_pointing_correction, workers=args.workers,
            progress=not args.no_progress, images=images, fusion=args.fusion)
        params.config()  # a bad setting is one line too
        api.ready()
        summary = dsm_flow(params)
    print("\n".join(summary.lines()))
    return 0


def _check_images(args: argparse.Namespace) -> tuple[Path, ...]:
    """``--images`` checked (at least two that exist, not with --left/--right and their
    models); the first two become the pair whose reference and overlap are checked."""
    from core.errors import InputError

    if not args.images:
        if args.left is None or args.right is None:
            raise InputError("give the pair (--left and --right) or the views (--images A B "
                             "...)")
        return ()
    if any(getattr(args, k) is not None for k in ("left", "right", "left_model",
                                                  "right_model")):
        raise InputError("--images replaces --left/--right and their models (found beside "
                         "each image): give one or the other")
    images = tuple(Path(im) for im in args.images)
    if len(images) < 2 or len(set(images)) < len(images):
        raise InputError(f"--images needs two different images or more, got {len(images)}")
    for image in images:
        if not image.exists():
            raise InputError(f"{image} does not exist; give the views' images")
    args.left, args.right = images[0], images[1]
    return images
