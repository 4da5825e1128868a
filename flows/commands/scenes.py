"""``gcpfree scenes``: the stereo pairs and blocks of a folder of scenes, found from their own
models, written as the catalog ``gcpfree archive --catalog`` runs.

No flow, by design: it reads the metadata of the scenes (a model file and a window of the
reference per scene, seconds for a folder of them) and compares their footprints, with nothing
a dashboard would show or a rerun would resume; Prefect's own start would take longer than the
answer. Plain functions of :mod:`tasks.archive.scenes` and :mod:`tasks.archive.stereo`.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from flows.commands._pair import add_reference_arguments


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "scenes",
        help="find the stereo pairs and blocks of a folder of scenes (catalog for archive)",
        description=(
            "Read every scene image under DIR with the model found beside it (SPOT .DIM, "
            "gcpfree .json, RPC .geom or RPC_*.XML or RPC tags; a simulated scene's truth/ and "
            "work/ are skipped), compute its footprint at the mean terrain height under it "
            "(--reference, or the DEM tiles of --dem-dir/--srtm-dir; without them at the "
            "model's own mean height), and "
            "propose the stereo pairs (overlap, B/H from the two view vectors at the overlap's "
            "centre, incidence and heading differences, date gap, GSD ratio, band family) and "
            "the blocks (connected components of overlapping scenes). Writes CATALOG (JSON: "
            "scenes, pairs, overlaps, blocks, rejected; gcpfree archive --catalog CATALOG runs "
            "its pairs) and CATALOG's .stac.json beside it (a STAC ItemCollection of the "
            "scenes' footprints), and prints the table. Files that are not usable scenes "
            "(unreadable, no model, overlapping nothing) are listed with their reason."),
    )
    p.add_argument("directory", type=Path, metavar="DIR", help="folder of scenes (searched "
                   "recursively)")
    p.add_argument("--out", type=Path, required=True, metavar="CATALOG",
                   help="the catalog to write (.json); its STAC ItemCollection goes beside it "
                        "as CATALOG.stac.json")
    add_reference_arguments(p, use="mean terrain height under each footprint")
    c = p.add_argument_group("stereo-pair thresholds (inclusive; see the defaults' reasons "
                             "in tasks/archive/stereo.py)")
    c.add_argument("--min-overlap", type=float, default=30.0, metavar="PCT",
                   help="least overlap, %% of the smaller footprint (default 30)")
    c.add_argument("--bh", type=float, nargs=2, default=None, metavar=("MIN", "MAX"),
                   help="B/H range for every pair (default: 0.1-0.8 when the coarser GSD is "
                        "at most --vhr-gsd, else 0.3-1.2)")
    c.add_argument("--vhr-gsd", type=float, default=2.0, metavar="M",
                   help="coarser GSD up to which a pair takes the very-high-resolution B/H "
                        "range (default 2 m)")
    c.add_argument("--max-incidence-diff", type=float, default=30.0, metavar="DEG",
                   help="largest difference of the incidences at the overlap's centre "
                        "(default 30)")
    c.add_argument("--max-heading-diff", type=float, default=30.0, metavar="DEG",
                   help="largest difference of the along-track headings (default 30)")
    c.add_argument("--max-date-gap", type=float, default=365.0, metavar="DAYS",
                   help="largest time between the acquisitions, days (default 365; a product "
                        "that states no date is not held to it)")
    c.add_argument("--max-gsd-ratio", type=float, default=2.0, metavar="R",
                   help="largest coarser-over-finer GSD ratio (default 2)")
    c.add_argument("--any-band-family", action="store_true",
                   help="pair panchromatic with multispectral scenes too")
    c.add_argument("--min-link-overlap", type=float, default=1.0, metavar="PCT",
                   help="least overlap (%% of the smaller footprint) that ties two scenes into "
                        "one block (default 1)")


def criteria_of(args: argparse.Namespace):  # -> StereoCriteria
    """The thresholds from the options (InputError on a bad value)."""
    from tasks.archive.stereo import StereoCriteria

    d = StereoCriteria()
    bh = tuple(args.bh) if args.bh is not None else None
    return StereoCriteria(
        min_overlap_pct=args.min_overlap, b_over_h_vhr=bh or d.b_over_h_vhr,
        b_over_h_spot=bh or d.b_over_h_spot, vhr_gsd_m=args.vhr_gsd,
        max_incidence_diff_deg=args.max_incidence_diff,
        max_heading_diff_deg=args.max_heading_diff, max_date_gap_days=args.max_date_gap,
        max_gsd_ratio=args.max_gsd_ratio, same_band_family=not args.any_band_family,
        min_link_overlap_pct=args.min_link_overlap)


def run(args: argparse.Namespace) -> int:
    # plain functions, no Prefect: a quick read of metadata, as info
    from core.errors import InputError
    from tasks.archive.scenes import GroundHeights, read_scenes
    from tasks.archive.stereo import catalog_lines, propose, write_scene_catalog

    if args.out.suffix.lower() != ".json" or args.out.is_dir():
        raise InputError(f"--out {args.out}: the catalog is a .json file (e.g. scenes.json)")
    criteria = criteria_of(args)
    ground = GroundHeights(args.reference, args.reference_vertical, args.srtm_dir, args.geoid)
    scenes, rejected = read_scenes(args.directory, ground)
    catalog = propose(args.directory, scenes, rejected, criteria, ground)
    out, items = write_scene_catalog(catalog, args.out)
    print("\n".join(catalog_lines(catalog)))
    print(f"catalog        {out} (gcpfree archive --catalog {out})")
    print(f"stac           {items}")
    return 0
