"""``gcpfree simulate``: a SPOT-like stereo pair rendered with known truth over a real DEM,
and with ``--sar ers|s1`` a SAR product of the same world (flow ``simulate-scene``), or with
``--block RxC --dates K`` a block of R x C scenes over K dates of one world (flow
``simulate-block``; both in :mod:`flows.simulate_scene`)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING, Any

from flows.commands._pair import add_vertical_argument

if TYPE_CHECKING:
    from core.simulation.block import BlockLayout


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "simulate",
        help="render a SPOT-like stereo pair with known truth over a real DEM",
        description=(
            "Simulate a SPOT-like stereo pair over a DEM: truth DSM/DTM/land cover (COG), two "
            "8- or 12-bit images with the fitted RPC of their delivered metadata inside and the "
            "delivered pushbroom model (JSON) beside them, truth models, check points and lidar "
            "(LAZ) under DIR/truth/. With --block RxC --dates K: a block of scenes instead "
            "(see --block). Same seed, same bytes; a rerun resumes."
        ),
    )
    p.add_argument("--dem", type=Path, default=None,
                   help="DEM in EPSG:4326 (GeoTIFF or .hgt); default: the bundled SRTM tile "
                        "N44E005")
    add_vertical_argument(p, "--dem-vertical", "DEM")
    p.add_argument("--out", type=Path, required=True, help="output folder DIR")
    p.add_argument("--preset", choices=("tiny", "spot", "hrs", "hrg"), default="tiny",
                   help="tiny: 600x600 px at 40 m (CI); spot: 6000x6000 px at 10 m, "
                        "across-track +25.5/-20 deg from two dates; hrs: along-track +-20 deg; "
                        "hrg: SPOT 5 HRG-like, 12000x12000 px at 5 m, the spot geometry")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--center", nargs=2, type=float, metavar=("LON", "LAT"), default=None,
                   help="scene centre in degrees (default: the DEM's centre)")
    p.add_argument("--lens", action="store_true",
                   help="truth camera has lens distortion the delivered metadata lack")
    p.add_argument("--jitter", action="store_true",
                   help="truth attitude has high-frequency jitter the metadata lack")
    p.add_argument("--errors", choices=("realistic", "simple"), default=None,
                   help="realistic: the errors real SPOT products and SRTM have (a measured "
                        "low-frequency attitude profile, ephemeris, time-tag and detector "
                        "calibration errors, a reference with partial canopy, radar voids and "
                        "a tilt); simple: attitude biases and drifts only. Default: realistic "
                        "for spot and hrs, simple for tiny")
    p.add_argument("--date-change", type=float, default=0.0, metavar="F",
                   help="fraction of the scene changed between the dates (vegetation, snow, "
                        "cloud); default 0")
    p.add_argument("--relief-factor", type=float, default=1.0, metavar="K",
                   help="scale the relief by K (0.05: nearly flat); default 1")
    p.add_argument("--bits", type=int, choices=(8, 12), default=8, help="image depth (default 8)")
    p.add_argument("--no-lidar", action="store_true", help="skip the truth lidar")
    p.add_argument("--block", metavar="RxC", default=None,
                   help="a block instead of a pair: R scenes along track (consecutive segments "
                        "of one pass: one orbit, a continuous attitude) by C across (adjacent "
                        "passes), about 10 %% overlap, over --dates dates of one world, into "
                        "DIR/images/r<row>c<col>d<date>.tif with their models beside; the "
                        "truth in DIR/truth/ (block.json, checkpoints.json keyed by image, "
                        "dsm.tif, dtm.tif), the reference in DIR/reference.tif. No lidar, no "
                        "SAR")
    p.add_argument("--dates", type=int, default=2, metavar="K",
                   help="with --block: dates, each its own across-track view and sun (the "
                        "same scene on two dates is a stereo pair; the preset's two views, "
                        "then +10 and -6 deg); default 2")
    p.add_argument("--flat-scene", metavar="rRcC", default=None,
                   help="with --block: make that scene's ground too flat to orient alone "
                        "(relief x 0.02, tapered over 2 km), e.g. r0c1")
    p.add_argument("--sar", choices=("ers", "s1"), default=None,
                   help="also a SAR product of the same world: DIR/sar.tif (amplitude, uint16, "
                        "sigma0 = (DN/1000)^2) with its Sentinel-1-form annotation DIR/sar.xml "
                        "and the truth in DIR/truth/sar*. ers: ERS-like slant-range product, "
                        "23 deg, ~20 m, 5 looks, ~10 m delivered geolocation; s1: Sentinel-1 "
                        "IW GRD-like, 10 m, 38 deg, a few metres. The tiny preset's pixels are "
                        "4 times coarser. Rerun the same command with --sar to add it to an "
                        "existing scene")


def run(args: argparse.Namespace) -> int:
    from tasks.simulate.io import check_dem

    layout = _block_layout(args)
    dem = args.dem
    if dem is None:
        from flows.simulate_scene import BUNDLED_DEM
        dem = BUNDLED_DEM
    check_dem(dem)
    from tasks.io.dem import dem_datum

    print(f"DEM              {dem}: "
          f"{dem_datum(dem, args.dem_vertical, what='DEM', option='--dem-vertical').describe()}")
    if layout is not None:
        return _run_block(args, dem, layout)
    from flows.simulate_scene import SimulationParams, simulate_scene

    summary = simulate_scene(SimulationParams(**_world(args, dem), lidar=not args.no_lidar,
                                              sar=args.sar))
    print("\n".join(summary.lines()))
    if args.sar:
        from tasks.simulate.sar import sar_summary

        print("\n".join(sar_summary(args.out).lines()))
    return 0


def _block_layout(args: argparse.Namespace) -> BlockLayout | None:
    """The block asked for (None for a pair), its options checked."""
    from core.errors import InputError

    if args.block is None:
        if args.flat_scene is not None:
            raise InputError("--flat-scene needs --block; add --block RxC")
        return None
    if args.sar:
        raise InputError("--sar makes a pair's SAR product, not a block's; drop --sar or --block")
    from core.simulation.block import BlockLayout

    layout = BlockLayout.parse(args.block, args.dates)
    if args.flat_scene is not None:
        layout.check_scene(args.flat_scene)
    return layout


def _world(args: argparse.Namespace, dem: Path) -> dict[str, Any]:
    """The fields of :class:`flows.simulate_scene.WorldParams` (a pair's and a block's)."""
    return {"out": args.out, "dem": dem, "preset": args.preset, "seed": args.seed,
            "lens": args.lens, "jitter": args.jitter, "date_change": args.date_change,
            "relief_factor": args.relief_factor, "bits": args.bits,
            "center": tuple(args.center) if args.center else None,
            "dem_vertical": args.dem_vertical, "errors": args.errors}


def _run_block(args: argparse.Namespace, dem: Path, layout: BlockLayout) -> int:
    from flows.simulate_scene import BlockParams, simulate_block

    summary = simulate_block(BlockParams(**_world(args, dem), layout=layout,
                                         flat_scene=args.flat_scene))
    print("\n".join(summary.lines()))
    return 0
