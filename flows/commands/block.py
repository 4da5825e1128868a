"""``gcpfree block``: a block of overlapping scenes (a ``gcpfree scenes`` catalog's) oriented
in one adjustment against the reference, with no GCP (flow :func:`flows.block.block_flow`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from flows.commands._pair import (
    add_orientation_settings,
    add_reference_arguments,
    add_run_arguments,
    check_reference_sigma,
)


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "block",
        help="orient every overlapping image of a block together (tie points, SRTM, one "
             "adjustment), fuse their DSMs",
        description=(
            "The block of CATALOG (written by gcpfree scenes; --block, default its first): "
            "tie points between every overlapping pair of its images chained into tracks and "
            "one joint relative orientation (the first image fixed); each stereo pair's "
            "relative DEM matched to the reference into GCPs (a pair too flat gives none: its "
            "images are held by their tie points to their neighbours); one adjustment of every "
            "image on all GCPs and tracks (core.orientation.adjust). Writes OUT/models/NAME.json "
            "(one model per image) with its RPC export (NAME.rpc.json, and NAME.vrt: the image "
            "with the RPC in GDAL's RPC metadata), OUT/pairs/ID/ (each pair's relative DEM, "
            "windows and DSM), OUT/dsm.tif (the fused multi-view DSM, OUT/dsm_views.tif: the "
            "images behind each cell), OUT/orthos/NAME.tif, OUT/gcps.json, OUT/relative/ and "
            "OUT/report.json (per image: held by GCPs or ties, check points and predicted RMS; "
            "the block's connectivity)."),
    )
    p.add_argument("--catalog", type=Path, required=True, metavar="CATALOG",
                   help="the catalog gcpfree scenes wrote (its scenes, pairs and blocks)")
    p.add_argument("--block", default=None, metavar="ID",
                   help="which of the catalog's blocks (default its first)")
    p.add_argument("--checkpoints", type=Path, default=None, metavar="FILE",
                   help="independent check points keyed by image name (the block simulator's "
                        "truth/checkpoints.json)")
    p.add_argument("--tie-measure", choices=("auto", "ncc", "orientation"), default="auto",
                   help="how the tie points are correlated (default auto: orientation "
                        "correlation where the suns differ)")
    add_reference_arguments(p, use="the ground the block is oriented to (required, or "
                                   "--dem-dir)")
    add_orientation_settings(p)
    add_run_arguments(p)


def run(args: argparse.Namespace) -> int:
    from core.errors import InputError
    from flows._env import prefect_api

    check_reference_sigma(args)  # refused in a line, before the server boots
    if args.reference is None and args.srtm_dir is None:
        raise InputError("gcpfree block needs a reference DEM: give --dem-dir (or --srtm-dir) "
                         "or --reference")
    if getattr(args, "sar_sigma_m", None) is not None:
        raise InputError("--sar-sigma: gcpfree block takes no SAR scene yet; orient its pairs "
                         "with gcpfree orient --sar")
    reference, srtm_dir = args.reference, args.srtm_dir
    if reference is not None:  # the one datum rule, decided before anything runs
        from tasks.io.dem import check_reference, dem_datum

        check_reference(reference)
        decision = dem_datum(reference, args.reference_vertical, geoid_option="--geoid")
        if decision.geoid is not None:  # EGM2008 through PROJ's grid: prepared as tiles are
            reference, srtm_dir = None, reference
        else:
            print(f"reference      {reference}: {decision.describe()}")
    if srtm_dir is not None and not Path(srtm_dir).exists():
        raise InputError(f"DEM tile folder {srtm_dir} does not exist; give --dem-dir (or "
                         "--srtm-dir) a folder of tiles")
    with prefect_api() as api:  # a temporary Prefect server boots meanwhile
        from flows.block import BlockParams, block_flow
        from flows.options import OPTIONS, given_options, with_options
        from flows.orient import OrientParams
        from tasks.absolute.orientation import read_checkpoints
        from tasks.block.control import select_block
        from tasks.io.pair import PairInputs

        block = select_block(args.catalog, args.block)
        if args.checkpoints is not None:
            read_checkpoints(args.checkpoints, block.names)
        ground = PairInputs(block.images[0], block.images[1], block.models[0],
                            block.models[1], reference=reference,
                            reference_vertical=args.reference_vertical,
                            srtm_dir=srtm_dir, geoid=args.geoid,
                            tie_measure=args.tie_measure)
        orient = with_options(
            OrientParams(pair=ground, out=args.out, checkpoints=args.checkpoints,
                         workers=args.workers, progress=not args.no_progress),
            {k: v for k, v in given_options(args).items() if OPTIONS[k].is_orientation})
        api.ready()
        outcome = block_flow(BlockParams(args.catalog, orient, args.block))
        print("\n".join(outcome.lines()))
    return 0
