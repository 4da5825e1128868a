"""Arguments and input checks shared by the commands that take a stereo pair."""

from __future__ import annotations

import argparse
from pathlib import Path

from core.choices import CORRECTIONS, TIE_MEASURES, VERTICAL_CHOICES

VERTICALS = VERTICAL_CHOICES
VERTICAL_HELP = ("heights of REF: auto (default) reads its vertical_datum tag, then its CRS's "
                 "vertical part, then a product's name (SRTM .hgt, N44E005.tif, NASADEM: "
                 "EGM96; Copernicus_DSM_*: EGM2008); a DEM none of these describe is refused: "
                 "say egm96 or ellipsoidal, or name its geoid with --geoid")
GEOID_HELP = ("the geoid grid the DEM's orthometric heights refer to when not EGM96, any grid "
              "GDAL reads (GTX, or a GeoTIFF such as PROJ's us_nga_egm08_25.tif for "
              "Copernicus DEM's EGM2008 heights: https://cdn.proj.org/us_nga_egm08_25.tif); "
              "given for SRTM tiles it replaces the bundled EGM96 grid. Without it EGM2008 "
              "heights go through PROJ's own grid when PROJ has it, else are refused")


def add_vertical_argument(p: argparse.ArgumentParser, flag: str, of: str = "REF", *,
                          help: str | None = None) -> None:
    """``flag`` (``--dem-vertical``, ``--reference-vertical``...): the heights of a DEM or
    point cloud, ``auto`` (default) deciding them by the one datum rule; the help says it of
    ``of`` (the file's metavar), or is ``help``."""
    p.add_argument(flag, choices=VERTICALS, default="auto",
                   help=VERTICAL_HELP.replace("REF", of) if help is None else help)


class OneLineParser(argparse.ArgumentParser):
    """An argument parser whose errors are one line on stderr and exit code 2, like every
    other gcpfree error (argparse prints its usage, then the error, on two or more)."""

    def error(self, message: str, prog: str | None = None):  # type: ignore[override]
        import sys

        prog = prog or self.prog
        sys.stderr.write(f"{prog}: error: {message}; see {prog} --help\n")
        raise SystemExit(2)

    def parse_args(self, args=None, namespace=None):  # type: ignore[override]
        """As argparse's, with an unknown option named against its subcommand."""
        ns, extras = self.parse_known_args(args, namespace)
        if extras:
            command = getattr(ns, "command", None)
            self.error(f"unrecognized arguments: {' '.join(extras)}",
                       f"{self.prog} {command}" if command else None)
        return ns


def add_pair_arguments(p: argparse.ArgumentParser, *, right_help: str = "right image") -> None:
    """``--left --right --left-model --right-model --band --tie-measure``."""
    p.add_argument("--left", type=Path, required=True, help="left image (its model stays fixed)")
    p.add_argument("--right", type=Path, required=True, help=right_help)
    p.add_argument("--left-model", type=Path, default=None,
                   help="model of the left image (.DIM, gcpfree .json, .geom, RPC .XML or a "
                        "GeoTIFF's RPC); default: found beside the image")
    p.add_argument("--right-model", type=Path, default=None, help="model of the right image")
    add_image_arguments(p)


def add_image_arguments(p: argparse.ArgumentParser) -> None:
    """``--band --tie-measure``: how the pair's images are read and matched."""
    p.add_argument("--band", type=int, default=None,
                   help="SPOT multispectral band whose look angles to use (default the first)")
    p.add_argument("--tie-measure", choices=TIE_MEASURES, default="auto",
                   help="correlation of the tie points: auto (default) takes orientation "
                        "correlation, robust to illumination, when the metadata's suns differ "
                        "by more than a degree (a two-date pair), else normalised "
                        "cross-correlation, the more precise on one date")


DEM_DIR_HELP = ("folder of DEM tiles (SRTM, NASADEM, Copernicus GLO-30/GLO-90 as named when "
                "distributed, or tagged lon/lat GeoTIFFs): a reference is prepared over the "
                "pair on their own lattice (--srtm-dir is the same option)")


def add_reference_arguments(p: argparse.ArgumentParser, *, use: str) -> None:
    """``--reference | --dem-dir`` (alias ``--srtm-dir``), ``--reference-vertical`` and
    ``--geoid``; ``use`` says what for."""
    ref = p.add_mutually_exclusive_group()
    ref.add_argument("--reference", type=Path, default=None, metavar="REF",
                     help="reference DEM in EPSG:4326 (prepare-reference output or SRTM .hgt)"
                          f": {use}; with --geoid, a reference is prepared from it over the "
                          "pair")
    ref.add_argument("--dem-dir", "--srtm-dir", dest="srtm_dir", type=Path, default=None,
                     metavar="DIR", help=DEM_DIR_HELP)
    add_vertical_argument(p, "--reference-vertical")
    p.add_argument("--geoid", type=Path, default=None, metavar="GRID", help=GEOID_HELP)


def add_orientation_arguments(p: argparse.ArgumentParser) -> None:
    """The GCP-free orientation's options (``orient``, ``pair``): the pair's own files (check
    points, SAR scene) and the settings (:func:`add_orientation_settings`)."""
    p.add_argument("--checkpoints", type=Path, default=None, metavar="FILE",
                   help="independent check points: the simulator's truth/checkpoints.json or a "
                        "CSV id,lon_deg,lat_deg,h_m,left_col,left_row,right_col,right_row "
                        "(ellipsoidal heights, 0-based pixels)")
    p.add_argument("--sar", type=Path, default=None, metavar="IMAGE",
                   help="a SAR scene of the same ground (e.g. a Sentinel-1 measurement TIFF, "
                        "or gcpfree simulate's sar.tif; its annotation found beside it): "
                        "SAR-optical GCPs (Goncalves 2002) join the SRTM ones, or orient the pair "
                        "alone where SRTM surface matching is refused (flat terrain); "
                        "OUT/sar_points.json")
    p.add_argument("--sar-model", type=Path, default=None, metavar="FILE",
                   help="the SAR scene's model when not beside it (Sentinel-1 annotation XML or "
                        "gcpfree SAR .json)")
    add_orientation_settings(p)


def add_orientation_settings(p: argparse.ArgumentParser) -> None:
    """The orientation's settings (``orient``, ``pair``, and ``archive``/``serve`` for every
    pair): lens self-calibration, along-track attitude, corrections, surface-matching windows,
    relief refusal, the SAR product's and the reference's sigmas. Each ``dest`` is the option's
    name (:mod:`flows.options`, pair.json's ``params``), which is how the commands read them."""
    p.add_argument("--self-calibrate", action="store_true",
                   help="estimate the cameras' calibration errors of pushbroom images (look-angle "
                        "scale k1, bow p1, cubic k3, across-track quadratic p2), kept only where "
                        "significant (GCPs, or the tie points' parallax)")
    p.add_argument("--no-along-track", dest="along_track", action="store_false",
                   help="do not estimate the attitude's along-track profile of pushbroom images "
                        "(harmonics in time, as many as the data choose: none included)")
    p.add_argument("--corrections", choices=CORRECTIONS, default="linear",
                   help="terms adjusted per image: linear (default, attitude biases and rates / "
                        "RPC affine) or offset (biases / RPC shift)")
    p.add_argument("--window-radius", dest="surface.radius_m", type=float, default=4000.0,
                   metavar="M", help="radius of the surface-matching windows, metres (default "
                                     "4000)")
    p.add_argument("--window-spacing", dest="spacing_m", type=float, default=None, metavar="M",
                   help="distance between window centres (default: the radius)")
    p.add_argument("--max-shift", dest="surface.shift_max_arcsec", type=float, default=20.0,
                   metavar="ARCSEC", help="largest horizontal shift searched, arcseconds "
                                          "(default 20)")
    p.add_argument("--min-windows", type=int, default=8,
                   help="windows with enough relief needed, else the terrain is refused as too "
                        "flat (default 8)")
    p.add_argument("--sar-sigma", dest="sar_sigma_m", type=float, default=None, metavar="M",
                   help="the SAR product's stated geolocation accuracy, 1 sigma, m (default "
                        "the mission's: Sentinel-1 3, ERS and others 10): the prior of the SAR "
                        "GCPs' frame, against which the reference's own shift is estimated")
    p.add_argument("--reference-sigma", dest="reference_sigma_m", nargs=3, type=float,
                   default=(5.0, 5.0, 5.0), metavar=("E", "N", "U"),
                   help="registration error of the reference DEM, east, north and up in "
                        "metres, 1 sigma (default 5 5 5): the GCP-free orientation cannot see "
                        "it, so the predicted check-point RMS in report.json adds it")


def add_lidar_vertical_argument(p: argparse.ArgumentParser) -> None:
    """``--lidar-vertical`` (``pair``, and ``archive``/``serve`` for every pair)."""
    add_vertical_argument(p, "--lidar-vertical", help="heights of the lidar (auto: from its CRS)")


def add_run_arguments(p: argparse.ArgumentParser) -> None:
    """``--workers --no-progress --out`` (an output folder)."""
    p.add_argument("--workers", type=int, default=None,
                   help="parallel tiles of the dense matching (default: one per core)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--out", type=Path, required=True, help="output folder")


def check_reference_sigma(args: argparse.Namespace) -> None:
    """``--reference-sigma`` checked at once, before the Prefect server is started: three
    finite metres, each >= 0 (InputError else)."""
    import math

    from core.errors import InputError

    values = tuple(float(v) for v in args.reference_sigma_m)
    if len(values) != 3 or not all(math.isfinite(v) and v >= 0 for v in values):
        raise InputError(f"--reference-sigma takes three finite sigmas in metres (east north "
                         f"up), each >= 0; got {' '.join(f'{v:g}' for v in values)}")


def check_sar_arguments(args: argparse.Namespace) -> None:
    """``--sar``/``--sar-model`` name files that exist, ``--sar-sigma`` comes with ``--sar``
    (InputError else)."""
    from core.errors import InputError

    if args.sar_model is not None and args.sar is None:
        raise InputError("--sar-model names the model of the --sar image: give --sar too")
    if args.sar_sigma_m is not None and args.sar is None:
        raise InputError(f"--sar-sigma {args.sar_sigma_m:g} is the --sar product's geolocation "
                         "sigma: give --sar too")
    for flag, path in (("--sar", args.sar), ("--sar-model", args.sar_model)):
        if path is not None and not Path(path).is_file():
            raise InputError(f"{flag} {path} does not exist; give the SAR image (and its "
                             "annotation)")


def orientation_params(args: argparse.Namespace, command: str, checked):  # -> OrientParams
    """The orientation's parameters (:class:`flows.orient.OrientParams`) from the options,
    checked before the flow starts: the reference, the check points, the SAR files and every
    setting (by :func:`flows.options.with_options`, through the dataclasses that hold them).
    ``checked`` (what :func:`check_pair` returned: the pair's inputs and its two models) also
    refuses here, in seconds rather than after its matching, a scene too small for one
    surface-matching window."""
    from core.errors import InputError
    from flows.options import OPTIONS, given_options, with_options
    from flows.orient import OrientParams
    from tasks.absolute.orientation import read_checkpoints

    if args.reference is None and args.srtm_dir is None:
        raise InputError(f"gcpfree {command} needs a reference DEM: give --dem-dir (or "
                         "--srtm-dir) or --reference")
    if args.checkpoints is not None:
        read_checkpoints(args.checkpoints)
    check_sar_arguments(args)
    params = with_options(
        OrientParams(pair=checked[0], out=args.out, checkpoints=args.checkpoints, sar=args.sar,
                     sar_model=args.sar_model, workers=args.workers,
                     progress=not args.no_progress),
        {k: v for k, v in given_options(args).items() if OPTIONS[k].is_orientation})
    _check_scene_size(params.surface, *checked)
    return params


def _check_scene_size(surface, pair, left, right) -> None:  # PairInputs, LoadedModel x 2
    """InsufficientDataError when the pair's overlap, at the height that makes it largest,
    cannot hold one surface-matching window (:func:`core.matching.relief.scene_size_verdict`)."""
    import numpy as np

    from core.errors import GeometryError, InsufficientDataError
    from core.geodesy import metres_per_degree
    from core.matching.relief import scene_size_verdict
    from core.sensors.footprint import ANY_TERRAIN_H_M
    from core.sensors.viewing import pair_geometry
    from tasks.relative.orientation import pair_box

    box = pair_box(left, right, ANY_TERRAIN_H_M)
    if pair.reference is not None:
        from tasks.io.dem import read_reference

        cell = read_reference(pair.reference, box, "ellipsoidal").cell_size_m()
    else:
        from tasks.io.dem_tiles import find_tiles

        tiles = find_tiles(pair.dem_source, box, allow_missing=True)
        m_lon, m_lat = metres_per_degree(0.5 * (box.lat_min + box.lat_max))
        cell = float(min(min(t.res_lon_deg for t in tiles) * m_lon,
                         min(t.res_lat_deg for t in tiles) * m_lat))
    areas = []
    for h in np.linspace(*ANY_TERRAIN_H_M, 20):
        try:
            areas.append(pair_geometry(left.model, left.size, right.model, right.size,
                                       float(h)).overlap_area_m2)
        except GeometryError:
            pass
    refusal = scene_size_verdict(max(areas, default=0.0), surface, cell)
    if refusal is not None:
        raise InsufficientDataError(refusal)


def check_pair(args: argparse.Namespace):  # -> tuple[PairInputs, LoadedModel, LoadedModel]
    """The pair's inputs from the options (:class:`tasks.io.pair.PairInputs`), both models
    loaded and the reference checked before the flow starts: bad input is one clean line
    (InputError). Returns the inputs, to be passed whole, and the two models."""
    from core.errors import InputError
    from tasks.io.dem import check_reference, dem_datum
    from tasks.io.pair import PairInputs

    pair = PairInputs.from_args(args)
    for path in (pair.left, pair.right):
        if not path.exists():
            raise InputError(f"{path} does not exist; give the two images of the pair")
    left, right = pair.load()
    if pair.reference is not None:
        check_reference(pair.reference)
        # refused here in one line, or said before the long run starts
        decision = dem_datum(pair.reference, pair.reference_vertical, geoid_option="--geoid")
        if decision.geoid is not None:  # EGM2008 through PROJ's grid: prepared through it
            from dataclasses import replace

            pair = replace(pair, reference=None, srtm_dir=pair.reference)
        else:
            print(f"reference      {pair.reference}: {decision.describe()}")
    if pair.srtm_dir is not None and not pair.srtm_dir.exists():
        raise InputError(f"DEM tile folder {pair.srtm_dir} does not exist; give --dem-dir (or "
                         "--srtm-dir) a folder of tiles")
    from core.sensors.footprint import ANY_TERRAIN_H_M
    from tasks.relative.orientation import pair_box

    h_range = getattr(args, "height_range", None) or ANY_TERRAIN_H_M
    _check_overlap(left, right, h_range)
    if pair.reference is not None:  # CoverageError when it misses the pair altogether
        from tasks.io.dem import read_reference

        read_reference(pair.reference, pair_box(left, right, h_range), "ellipsoidal")
    if pair.srtm_dir is not None:  # the tiles that would be used, their datum and geoid
        from tasks.io.geoid import read_geoid
        from tasks.io.reference import locate_tiles

        box = pair_box(left, right, h_range)
        tiles = locate_tiles.fn(pair.dem_source, box, True)
        if tiles.datum.geoid is not None:  # type: ignore[union-attr]
            read_geoid(tiles.datum.geoid, box)  # type: ignore[union-attr]
        print(f"reference      prepared from {pair.srtm_dir}: {tiles.describe()}")
    return pair, left, right


def _check_overlap(left, right, h_range: tuple[float, float]) -> None:  # LoadedModel x 2
    """GeometryError when the footprints meet at none of a few heights over ``h_range``: two
    images of different places (a reference or SRTM mosaic over both would be the size of a
    continent)."""
    import numpy as np

    from core.errors import GeometryError
    from tasks.relative.orientation import check_overlap

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
