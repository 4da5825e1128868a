"""``gcpfree evaluate``: accuracy of a DEM against lidar, per class (flow ``evaluate``,
:mod:`flows.evaluate`).

Importing this module is light (no Prefect, rasterio or laspy): the ``gcpfree`` parser includes
:func:`add_parser` at no cost; :func:`run` checks every input, then runs the flow.
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from flows.commands._pair import add_vertical_argument

if TYPE_CHECKING:
    from core.evaluation.evaluation_report import EvaluationReport

Z_UNITS = ("auto", "m", "ft", "us-ft")  # "auto" and the keys of core.heights.Z_UNITS


def report_lines(report: EvaluationReport) -> list[str]:
    """The summary the command prints: inputs as read, where the points went, one line per
    class and ``all``, then the mask and GCP checks when asked."""
    d, li, p = report.dem, report.lidar, report.points
    xy = f"x/y {li.xy_unit}" + (f" ({li.xy_factor_m} m)" if li.xy_factor_m else "")
    out = [
        (f"{'dem':<14} {d.path}: {d.crs.authority or d.crs.name}, {d.width}x{d.height}, "
         f"{d.vertical} heights ({d.vertical_source}), z {d.z_unit}"),
        (f"{'lidar':<14} {li.path}: {li.point_count} points, {li.crs.authority or li.crs.name} "
         f"({li.crs_source}), {xy}, z {li.z_unit} ({li.z_factor_m} m; {li.z_unit_source}), "
         f"{li.vertical} heights ({li.vertical_source})"),
        f"{'compared':<14} dz = DEM - lidar, metres, in {report.heights_compared} heights",
        f"{'lidar -> DEM':<14} {report.transformation}",
        (f"{'points':<14} read {p.read}, refused {p.refused} (outside the file's box "
         f"{p.refused_bounds}, reserved class {p.refused_class}), withheld {p.withheld}, class "
         f"excluded {p.excluded_class}, outside the DEM {p.outside_dem}, on DEM voids "
         f"{p.on_void}, evaluated {p.evaluated}"),
    ]
    if report.landcover is not None:
        out.append(f"{'classes':<14} land cover {report.landcover.path} "
                   f"({report.landcover.names_source})")
    ci = f"le68 {100 * report.stats_config.ci_level:g}% CI"
    out.append(f"{'class':<20} {'count':>9} {'bias':>8} {'std':>8} {'rmse':>8} {'nmad':>8} "
               f"{'le68':>8} {ci:>20} {'le90':>8}")
    for name, s in [*report.classes.items(), ("all", report.all)]:
        label = f"{name} {report.class_labels.get(name, '')}".strip()[:20]
        interval = f"[{s.le68_ci_m[0]:.3f}, {s.le68_ci_m[1]:.3f}]"
        out.append(f"{label:<20} {s.count:>9} {s.mean_m:>8.3f} {s.std_m:>8.3f} "
                   f"{s.rmse_m:>8.3f} {s.nmad_m:>8.3f} {s.le68_m:>8.3f} {interval:>20} "
                   f"{s.le90_m:>8.3f}")
    if report.mask is not None:
        out.append(f"{'mask':<14} {report.mask.mismatched_pct:.2f} % mismatched, "
                   f"{report.mask.occluded_pct:.2f} % occluded or outside")
    if report.gcps is not None:
        g = report.gcps
        out.append(f"{'gcps':<14} {g.stats.count} of {g.points} on the DEM: dz mean "
                   f"{g.stats.mean_m:.3f} m, RMS {g.stats.rmse_m:.3f} m")
    return out


def _classes(text: str) -> tuple[int, ...]:
    try:
        codes = tuple(int(c) for c in text.split(",") if c.strip())
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"{text!r} is not a list of LAS codes like 2,5,6") \
            from exc
    if not codes:
        raise argparse.ArgumentTypeError("give at least one LAS code, e.g. 2")
    return codes


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "evaluate",
        help="accuracy of a DEM against lidar: bias, NMAD, LE68/LE90 per class",
        description=(
            "Interpolate the DEM bilinearly at every lidar point (the lidar is never "
            "interpolated), in any CRS and unit (pyproj; feet handled), heights brought to the "
            "DEM's vertical datum (EGM96 converted with h = H + N), and report dz = DEM - lidar "
            "per class (LAS classification, or a land-cover raster's classes) and overall: "
            "count, mean (bias), std, RMSE, NMAD, LE68 with a bootstrap interval, LE90. The "
            "points stream in chunks: memory stays flat whatever the file size."
        ),
    )
    p.add_argument("--dem", type=Path, required=True, help="the DEM/DSM (GeoTIFF, any CRS)")
    p.add_argument("--lidar", type=Path, required=True, help="the lidar points (LAS or LAZ)")
    p.add_argument("--out", type=Path, required=True, help="output eval.json")
    p.add_argument("--landcover", type=Path, default=None, metavar="LC.tif",
                   help="classes from this raster (nearest cell at each point) instead of the "
                        "LAS classification")
    p.add_argument("--landcover-names", default=None, metavar="JSON_OR_SPEC",
                   help="names of the land-cover codes: JSON {\"1\": \"bare_soil\"} or "
                        "1=bare_soil,2=forest (default: the raster's NAME=code tags)")
    add_vertical_argument(p, "--lidar-vertical",
                          help="lidar heights: auto (default) takes the compound CRS's "
                               "vertical part (EGM96 height -> egm96) and assumes ellipsoidal "
                               "without one")
    add_vertical_argument(p, "--dem-vertical", "DEM")
    p.add_argument("--lidar-crs", default=None, metavar="CRS",
                   help="CRS of the lidar when the file has none or a wrong one (e.g. "
                        "EPSG:32631+5773: UTM 31N with EGM96 heights)")
    p.add_argument("--lidar-z-unit", choices=Z_UNITS, default="auto",
                   help="unit of the lidar heights: auto (default) from the vertical CRS, else "
                        "the horizontal unit")
    p.add_argument("--classes", type=_classes, default=None, metavar="2,5,6",
                   help="evaluate only these LAS classes (default: all but noise, 7 and 18)")
    p.add_argument("--mask", type=Path, default=None, metavar="dem_mask.tif",
                   help="the DSM's mask (0 valid, 1 mismatch, 2 occluded/outside): reports the "
                        "%% mismatched")
    p.add_argument("--gcps", type=Path, default=None, metavar="gcps.json",
                   help="ground points [[lon, lat, h_ellipsoidal], ...]: reports the DEM's RMS "
                        "at them")
    p.add_argument("--chunk-points", type=int, default=1_000_000, metavar="N",
                   help="points read per chunk (default 1000000)")
    p.add_argument("--ci-level", type=float, default=0.95,
                   help="level of the LE68 bootstrap interval (default 0.95)")
    p.add_argument("--seed", type=int, default=0, help="bootstrap seed (default 0)")


def run(args: argparse.Namespace) -> int:
    from flows._env import prefect_api

    with prefect_api() as api:  # a temporary Prefect server boots meanwhile
        from core.evaluation.evaluation import StatsConfig
        from tasks.evaluation.lidar import EvaluationOptions, plan_evaluation
        from tasks.io.sensor_info import check_json_target

        options = EvaluationOptions(
            dem=args.dem, lidar=args.lidar, out=args.out, landcover=args.landcover,
            landcover_names=args.landcover_names, lidar_vertical=args.lidar_vertical,
            dem_vertical=args.dem_vertical, lidar_crs=args.lidar_crs,
            lidar_z_unit=args.lidar_z_unit, classes=args.classes, mask=args.mask, gcps=args.gcps,
            chunk_points=args.chunk_points,
            stats=StatsConfig(ci_level=args.ci_level, seed=args.seed),
        )
        # every header read and checked before the flow starts: bad input is one clean line
        plan_evaluation(options)
        check_json_target(args.out)
        from flows.evaluate import evaluate_flow

        api.ready()
        report = evaluate_flow(options)
        print("\n".join(report_lines(report)))
        print(f"{'json':<14} {args.out}")
    return 0
