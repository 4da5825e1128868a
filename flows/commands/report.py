"""``gcpfree report OUT_DIR``: the run report of an existing ``gcpfree orient`` output, made
again (after the run, with a lidar evaluation or the check points added, or for a run that
stopped on too flat a terrain).

Writes ``OUT_DIR/report.html``, ``OUT_DIR/report.md``, the figures in ``OUT_DIR/report_files/``
and the key ``report`` of ``OUT_DIR/report.json`` (:func:`tasks.report.build.make_report`). No flow:
the report reads a few small products and draws eight figures, in seconds, so it runs without
starting Prefect. Importing this module is light; :func:`run` checks the inputs first.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from flows.commands._pair import add_vertical_argument

# products of gcpfree orient, one of which a folder must hold to be reported on
ORIENT_PRODUCTS = ("report.json", "windows.json", "relative/rel.json")


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "report",
        help="the run report (HTML, Markdown, figures) of a gcpfree orient output folder",
        description=(
            "Make the run report of a gcpfree orient output folder again from its products "
            "(report.json, windows.json, gcps.json, the oriented models, the tie points, the "
            "relative DEM): tie points over the left image, the correlation surface of a "
            "surface-matching window, a profile of the relative DEM against the reference, "
            "the relief verdict, residual vectors at the GCPs and check points, residual "
            "histograms and, with --evaluation, LE68 per class. Writes OUT_DIR/report.html, "
            "OUT_DIR/report.md and OUT_DIR/report_files/*.png, and adds the report's numbers "
            "to OUT_DIR/report.json under the key 'report' (the orientation's keys are kept). "
            "What is not available is said in the report."),
    )
    p.add_argument("out_dir", type=Path, metavar="OUT_DIR",
                   help="the output folder of gcpfree orient (--out)")
    p.add_argument("--reference", type=Path, default=None, metavar="REF",
                   help="the reference DEM the orientation used (profile and correlation "
                        "surface); default: the one orient made from --srtm-dir in "
                        "OUT_DIR/relative/")
    add_vertical_argument(p, "--reference-vertical")
    p.add_argument("--checkpoints", type=Path, default=None, metavar="CP",
                   help="the check points given to orient (their residual vectors)")
    p.add_argument("--evaluation", type=Path, default=None, metavar="EVAL_JSON",
                   help="eval.json of gcpfree evaluate on the final DSM (LE68 per class)")
    p.add_argument("--window-radius", type=float, default=4000.0, metavar="M",
                   help="radius of the surface-matching windows orient used (default 4000)")
    p.add_argument("--max-shift", type=float, default=20.0, metavar="ARCSEC",
                   help="largest shift orient searched, arcseconds (default 20)")


def check_inputs(args: argparse.Namespace) -> None:
    """Bad input in one line (InputError) before anything is read or written."""
    from core.errors import InputError
    from tasks.io.rasters import read_json

    out = Path(args.out_dir)
    if not out.is_dir():
        raise InputError(f"{out} is not a folder; give the output folder of gcpfree orient "
                         "(its --out)")
    if not any((out / p).is_file() for p in ORIENT_PRODUCTS):
        raise InputError(f"{out} holds no gcpfree orient products (none of "
                         f"{', '.join(ORIENT_PRODUCTS)}); run gcpfree orient --out {out} first")
    if args.reference is not None:
        from tasks.io.dem import check_reference, dem_datum

        check_reference(args.reference)
        print(f"reference      {args.reference}: "
              f"{dem_datum(args.reference, args.reference_vertical).describe()}")
    if args.checkpoints is not None:
        from tasks.absolute.orientation import read_checkpoints

        read_checkpoints(args.checkpoints)
    if args.evaluation is not None:
        doc = read_json(args.evaluation, "the evaluation",
                        "give the eval.json gcpfree evaluate wrote")
        if not isinstance(doc, dict) or not isinstance(doc.get("classes"), dict):
            raise InputError(f"{args.evaluation} has no 'classes': not an eval.json of gcpfree "
                             "evaluate")
    if not (args.window_radius > 0 and args.max_shift > 0):
        raise InputError("--window-radius and --max-shift must be > 0")


def run(args: argparse.Namespace) -> int:
    check_inputs(args)
    from dataclasses import replace

    from core.matching.surface import SurfaceMatchConfig
    from tasks.report.build import make_report

    surface = replace(SurfaceMatchConfig(), radius_m=args.window_radius,
                      shift_max_arcsec=args.max_shift)
    outcome = make_report(args.out_dir, args.reference, args.checkpoints, args.evaluation,
                          reference_vertical=args.reference_vertical, surface=surface)
    print("\n".join(outcome.lines()))
    return 0
