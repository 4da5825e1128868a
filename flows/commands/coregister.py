"""``gcpfree coregister``: the 3-D translation between a DEM and a reference (Nuth & Kaab).

No flow, by design: one in-memory adjustment of two DEMs (:func:`tasks.evaluation.coregister.
coregister`), with no step to watch, retry or resume; Prefect's start would outlast it."""

from __future__ import annotations

import argparse
from pathlib import Path

from flows.commands._pair import add_vertical_argument


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "coregister",
        help="3-D shift of a DEM onto a reference DEM (Nuth & Kaab plus vertical bias)",
        description=(
            "Align a whole DEM with a reference: iterate Nuth & Kaab's fit of the height "
            "differences against slope and aspect until the horizontal shift settles, then the "
            "vertical bias. Geographic or projected grids (the DEM is reprojected onto the "
            "reference's CRS when they differ). result.json holds shift_east_m, "
            "shift_north_m, shift_up_m and shift_col_px, shift_row_px in the reference's "
            "pixels: the translation that, added to the DEM's coordinates, aligns it with the "
            "reference."),
    )
    p.add_argument("--reference", "--ref", dest="reference", type=Path, required=True,
                   metavar="REF", help="reference DEM (GeoTIFF or .hgt)")
    p.add_argument("--dem", type=Path, required=True, help="DEM to align")
    add_vertical_argument(p, "--reference-vertical")
    add_vertical_argument(p, "--dem-vertical", "DEM")
    p.add_argument("--out", type=Path, required=True, help="output result.json")


def run(args: argparse.Namespace) -> int:
    from core.errors import InputError
    from tasks.evaluation.coregister import coregister, datums

    for path in (args.reference, args.dem):
        if not Path(path).is_file():
            raise InputError(f"{path} does not exist; give two DEM rasters")
    ref_datum, dem_d = datums(args.reference, args.dem, args.reference_vertical,
                              args.dem_vertical)
    print(f"reference      {args.reference}: {ref_datum.describe()}")
    print(f"DEM            {args.dem}: {dem_d.describe()}")
    r = coregister(args.reference, args.dem, args.out,
                   reference_vertical=args.reference_vertical, dem_vertical=args.dem_vertical)
    print(f"shift          east {r.shift_east_m:+.3f} m, north {r.shift_north_m:+.3f} m, "
          f"up {r.shift_up_m:+.3f} m")
    print(f"in ref pixels  col {r.shift_col_px:+.4f}, row {r.shift_row_px:+.4f} "
          f"({r.n_iterations} iterations, {r.n_points} cells)")
    print(f"height NMAD    {r.nmad_before_m:.3f} m before, {r.nmad_after_m:.3f} m after")
    print(f"result         {args.out}")
    return 0
