"""``gcpfree archive``: every pair of a catalog oriented, in parallel on Dask, resumable."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from flows.commands._pair import (
    DEM_DIR_HELP,
    GEOID_HELP,
    add_image_arguments,
    add_lidar_vertical_argument,
    add_orientation_settings,
    add_vertical_argument,
)

if TYPE_CHECKING:
    from tasks.archive.catalog import Catalog

CATALOG_HELP = ("a folder of pair folders (each with left.tif + right.tif and their models, or "
                "left/ and right/ folders with IMAGERY.TIF + METADATA.DIM; optional lidar.laz, "
                "landcover.tif, checkpoints.json, sar.tif), or a CSV/JSON list with the columns "
                "id,left,right[,left_model,right_model,lidar,landcover,checkpoints,sar,"
                "sar_model] and any of the pair's options, named as in its pair.json's params "
                "(self_calibrate, along_track, corrections, spacing_m, min_windows, "
                "reference_sigma_m, sar_sigma_m, band, tie_measure, lidar_vertical, "
                "surface.radius_m and the other surface.* and absolute.* settings; text in a "
                "CSV, e.g. true, linear, \"5 5 5\"): a pair's own option wins over the command "
                "line's, which apply to every pair")


def add_archive_arguments(p: argparse.ArgumentParser) -> None:
    """The arguments ``archive`` and ``serve`` share."""
    p.add_argument("--catalog", type=Path, required=True, metavar="CATALOG", help=CATALOG_HELP)
    p.add_argument("--out", type=Path, required=True, metavar="ROOT",
                   help="output folder: ROOT/<pair id>/ per pair, ROOT/summary.csv and "
                        "ROOT/summary.json")
    ref = p.add_mutually_exclusive_group(required=True)
    ref.add_argument("--dem-dir", "--srtm-dir", dest="srtm_dir", type=Path, default=None,
                     metavar="DIR", help=DEM_DIR_HELP.replace("the pair", "each pair"))
    ref.add_argument("--reference", type=Path, default=None, metavar="REF",
                     help="one reference DEM in EPSG:4326 for every pair (prepare-reference "
                          "output or SRTM .hgt)")
    add_vertical_argument(p, "--reference-vertical")
    p.add_argument("--geoid", type=Path, default=None, metavar="GRID", help=GEOID_HELP)
    p.add_argument("--dask-address", default=None, metavar="tcp://HOST:PORT",
                   help="scheduler of an existing Dask cluster (its workers must see the same "
                        "paths and have gcpfree installed); default: a LocalCluster")
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help="LocalCluster workers, one pair each at a time (default: one per core, "
                        "at most one per pair to do)")
    p.add_argument("--threads", action="store_true",
                   help="LocalCluster workers as threads of this process instead of processes "
                        "(lighter for small pairs)")
    p.add_argument("--dashboard-address", default=":8787", metavar="[HOST]:PORT",
                   help="where the LocalCluster serves its Dask dashboard (default :8787; :0 "
                        "for any free port)")
    settings = p.add_argument_group(
        "the options of every pair (as gcpfree orient's and gcpfree pair's; a pair's own in "
        "the catalog wins)")
    add_orientation_settings(settings)
    add_image_arguments(settings)
    add_lidar_vertical_argument(settings)


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "archive",
        help="orient every stereo pair of a catalog on Dask (resumable, summary.csv)",
        description=(
            "Run the whole chain (orientation without GCP, DSM, orthos, evaluation when lidar is "
            "given, report) on every pair of CATALOG, pairs in parallel on a Dask cluster (a "
            "LocalCluster, or an existing one with --dask-address; the dashboard link is "
            "printed). A pair that the method refuses (terrain too flat, too small, too few "
            "points) or that fails is recorded with its reason and never stops the others. "
            "ROOT/summary.csv and ROOT/summary.json list every pair: status (done, skipped, "
            "refused, failed), reason, GCP count, check-point and GCP residual RMS per image, "
            "LE68; ROOT/map.html beside them (and the run's archive-map artifact) shows the "
            "pairs' footprints over an SRTM hillshade coloured by status and by stated "
            "accuracy, the counts, the throughput and the slowest steps, refreshed as pairs "
            "end. A rerun processes only the pairs missing, refused or failed, and a pair "
            "interrupted (Ctrl-C, a worker process killed) resumes after its last finished "
            "step. Exit code 1 when a pair was refused or failed, 130 when interrupted."),
    )
    add_archive_arguments(p)
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def check_archive_args(args: argparse.Namespace) -> Catalog:
    """Bad arguments refused in one line before Prefect starts; the catalog read."""
    from core.errors import InputError
    from flows.options import OPTIONS, check_options, given_options
    from tasks.archive.catalog import read_catalog
    from tasks.io.dem import check_reference, dem_datum

    check_options(given_options(args))
    catalog = read_catalog(args.catalog, tuple(OPTIONS))
    if args.reference is not None:
        check_reference(args.reference)
        decision = dem_datum(args.reference, args.reference_vertical, geoid=args.geoid,
                             geoid_option="--geoid")
        print(f"reference      {args.reference}: {decision.describe()}")
        if decision.geoid is not None and args.geoid is None:  # through PROJ's grid: every
            args.srtm_dir, args.reference = args.reference, None  # pair's is prepared from it
    if args.srtm_dir is not None and not Path(args.srtm_dir).is_dir():
        raise InputError(f"DEM tile folder {args.srtm_dir} does not exist; give --dem-dir (or "
                         "--srtm-dir) a folder of tiles")
    if args.geoid is not None:
        from tasks.io.geoid import check_geoid

        check_geoid(args.geoid)
    if args.workers is not None and args.workers < 1:
        raise InputError(f"--workers must be at least 1 (got {args.workers})")
    if args.dask_address is not None and "://" not in args.dask_address:
        raise InputError(f"--dask-address {args.dask_address}: give the scheduler as "
                         "tcp://HOST:PORT")
    return catalog


def flow_parameters(args: argparse.Namespace) -> dict:
    """The flow's parameters from the command line (absolute paths, JSON values; the options
    of every pair by name, those at their defaults left out)."""
    from flows.options import given_options

    def path(p: Path | None) -> str | None:
        return None if p is None else str(Path(p).expanduser().resolve())

    return {"catalog": path(args.catalog), "out": path(args.out),
            "srtm_dir": path(args.srtm_dir), "reference": path(args.reference),
            "reference_vertical": args.reference_vertical, "geoid": path(args.geoid),
            "dask_address": args.dask_address, "workers": args.workers,
            "processes": not args.threads, "dashboard_address": args.dashboard_address,
            "options": given_options(args)}


def interrupted_line(catalog: Catalog, root: Path) -> str:
    """What an interrupted run leaves: how many pairs are complete, how to finish the rest."""
    from tasks.archive.pair import pair_complete

    done = sum(pair_complete(Path(root) / i) for i in catalog.ids)
    return (f"gcpfree archive: interrupted with {done} of {len(catalog.pairs)} pairs complete "
            f"in {root}; run the same command again to process the "
            f"{len(catalog.pairs) - done} others (complete pairs are kept, the others resume "
            "after their last finished step)")


def run(args: argparse.Namespace) -> int:
    catalog = check_archive_args(args)
    from flows.reprocess_archive import reprocess_archive

    try:
        outcome = reprocess_archive(**flow_parameters(args), progress=not args.no_progress)
    except KeyboardInterrupt:  # Ctrl-C: every finished product stays, the rerun resumes
        print(interrupted_line(catalog, args.out), file=sys.stderr, flush=True)
        raise
    print("\n".join(outcome.lines()))
    return 1 if outcome.count("failed") or outcome.count("refused") else 0
