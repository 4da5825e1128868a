"""``gcpfree ortho``: an image orthorectified on a DEM through its sensor model (flow
``ortho``, :mod:`flows.ortho`).

Importing this module is light (no Prefect, rasterio or pyproj): :func:`run` checks the inputs,
then runs the flow.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from core.choices import RESAMPLINGS
from flows.commands._pair import add_vertical_argument

if TYPE_CHECKING:
    from tasks.ortho.orthorectify import OrthoOptions


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "ortho",
        help="orthorectify an image on a DEM (SRTM reference or the final DSM)",
        description=(
            "Orthorectify IMG by inverse mapping: each cell of the output grid takes its "
            "height from the DEM (EGM96 heights converted with h = H + N), goes through the "
            "sensor model into the image and is resampled there. The model is evaluated on a "
            "sparse lattice per 1024-cell tile and interpolated, the lattice refined until "
            "the interpolation error found on check points is below 0.01 px. The grid is in "
            "the local UTM zone (or --crs), cells of the image's GSD (or --resolution) "
            "aligned on multiples of the cell size, so two orthos of a pair share a lattice "
            "(see ortho-compare). Writes OUT (COG in the image's type with nodata and "
            "overviews), OUT.json and, when asked, the occlusion mask (0 seen, 1 hidden by "
            "relief, 255 no data)."),
    )
    p.add_argument("--image", type=Path, required=True, metavar="IMG",
                   help="the image (GeoTIFF, SPOT IMAGERY.TIF...)")
    p.add_argument("--model", type=Path, default=None, metavar="M",
                   help="its sensor model: .DIM (SPOT), gcpfree .json (pushbroom or RPC, e.g. "
                        "OUT/left.json of gcpfree orient), .geom, RPC .XML, or a GeoTIFF's RPC "
                        "tags; default: found beside the image")
    p.add_argument("--band", type=int, default=None,
                   help="SPOT multispectral band whose look angles to use (default the first)")
    p.add_argument("--dem", type=Path, required=True, metavar="DEM",
                   help="heights: a lon/lat DEM (SRTM .hgt, prepare-reference output) or a "
                        "projected DSM (gcpfree dsm/orient output)")
    add_vertical_argument(p, "--dem-vertical", "DEM")
    p.add_argument("--resolution", type=float, default=None, metavar="M",
                   help="cell size in metres (default the image's GSD, 2 digits)")
    p.add_argument("--crs", type=int, default=None, metavar="EPSG",
                   help="projected output CRS as an EPSG code (default the local UTM zone)")
    p.add_argument("--resampling", choices=RESAMPLINGS, default="bilinear",
                   help="image resampling (default bilinear; cubic: cubic convolution)")
    p.add_argument("--occlusion-mask", type=Path, default=None, metavar="MASK",
                   help="also write the cells hidden from the sensor by relief here (COG)")
    p.add_argument("--workers", type=int, default=None,
                   help="parallel tiles (default: one per core)")
    p.add_argument("--out", type=Path, required=True, metavar="ORTHO",
                   help="output ortho (GeoTIFF, COG)")


def options_from(args: argparse.Namespace) -> OrthoOptions:
    from tasks.ortho.orthorectify import OrthoOptions

    return OrthoOptions(
        image=args.image, dem=args.dem, out=args.out, model=args.model, band=args.band,
        dem_vertical=args.dem_vertical, resolution_m=args.resolution, epsg=args.crs,
        resampling=args.resampling, occlusion_mask=args.occlusion_mask, workers=args.workers)


def run(args: argparse.Namespace) -> int:
    from flows._env import prefect_api

    with prefect_api() as api:  # a temporary Prefect server boots meanwhile
        from tasks.ortho.orthorectify import check_ortho_options

        options = options_from(args)
        check_ortho_options(options)  # bad input is one line, before the flow starts
        from flows.ortho import ortho_flow

        api.ready()
        summary = ortho_flow(options)
        print("\n".join(summary.lines()))
    return 0
