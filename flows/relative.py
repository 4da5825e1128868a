"""Flow ``relative-orientation`` (``gcpfree relative``, :mod:`flows.commands.relative`): tie
points and the relative orientation of a pair.

models of both images -> reference DEM (given, or prepared from SRTM tiles) -> tie points ->
right model adjusted to the left -> rel.json, <rel>.tiepoints.json. The tie points' correlation
measure is the pair's ``tie_measure`` (``auto``: chosen from the two suns).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from prefect import flow

from core.matching.tiepoints import TiePointConfig
from core.orientation.relative import RelativeConfig
from tasks.io.pair import PairInputs
from tasks.io.sensors import LoadedModel


@dataclass(frozen=True)
class RelativeParams:
    """Parameters of :func:`relative_flow` (see ``gcpfree relative --help``): the pair (its
    reference optional: without one, the heights come from ``height_range_m``), where to
    write ``rel.json``, and the settings."""

    pair: PairInputs
    out: Path
    height_range_m: tuple[float, float] | None = None
    corrections: str = "linear"
    cell_m: float = 2000.0
    search_radius_m: float | None = None  # default: from the GSD (default_search_radius_m)
    reference_sigma_m: float = 5.0
    tie_points: TiePointConfig = field(default_factory=TiePointConfig)  # measure: the pair's
    workers: int | None = None  # threads matching the tie-point cells (default one per core)


@dataclass(frozen=True, eq=False)
class RelativeOutcome:
    """The pair after relative orientation: ``right.model`` is adjusted to ``left.model``;
    ``reference`` an ellipsoidal reference DEM covering the pair when one was given or made."""

    left: LoadedModel
    right: LoadedModel
    reference: Path | None
    rel_json: Path
    lines: tuple[str, ...] = ()


@flow(name="relative-orientation", log_prints=True)
def relative_flow(params: RelativeParams) -> RelativeOutcome:
    """Models -> reference -> tie points -> relative orientation -> rel.json."""
    from dataclasses import replace

    from core.matching.tiepoints import default_search_radius_m, ground_sampling_m
    from core.sensors.footprint import ANY_TERRAIN_H_M
    from tasks.dense.dem import scene_height_range
    from tasks.io.dem import dem_datum, read_reference
    from tasks.io.reference import build_reference, locate_tiles
    from tasks.relative.orientation import (
        ReferenceUsed,
        check_overlap,
        load_pair,
        orient_relative,
        pair_box,
        reference_box_heights,
        scene_height_m,
    )
    from core.matching.peaks import MEASURE_NAMES
    from tasks.relative.tiepoints import find_tie_points, tie_measure

    out, pair = Path(params.out), params.pair
    left, right = load_pair(pair)
    reference_path, vertical = pair.reference, pair.reference_vertical
    first_range = params.height_range_m or ANY_TERRAIN_H_M
    if reference_path is None and pair.srtm_dir is not None:
        box = pair_box(left, right, first_range)
        tiles = locate_tiles(pair.dem_source, box, True)
        reference_path = Path(build_reference(tiles, box, out.with_name(out.stem +
                                                                        ".reference.tif")).path)
        vertical = "auto"  # its own tag says ellipsoidal
    dem, used = None, None
    if reference_path is not None:
        used = ReferenceUsed(Path(reference_path), dem_datum(reference_path, vertical),
                             None if pair.reference is not None else pair.srtm_dir)
        dem = read_reference(used.path, pair_box(left, right, first_range), used.datum.datum)
        h_range = reference_box_heights(dem)
    else:
        h_range = scene_height_range(left, right, params.height_range_m, None)
    check_overlap(left, right, scene_height_m(left, dem, h_range),
                  None if dem is not None else h_range)
    radius = params.search_radius_m
    if radius is None:
        c, r = 0.5 * (left.size[0] - 1), 0.5 * (left.size[1] - 1)
        radius = default_search_radius_m(ground_sampling_m(left.model, c, r, 0.5 * (h_range[0]
                                                                               + h_range[1])))
    measure, why = tie_measure(pair.tie_measure, left.sun, right.sun)
    measure_line = f"tie-point measure     {MEASURE_NAMES[measure]} ({why})"
    print(measure_line)
    cfg = replace(params.tie_points, cell_m=params.cell_m, search_radius_m=radius,
                  measure=measure)
    ties = find_tie_points(left.image or left.source, right.image or right.source, left.model,
                           right.model, dem, cfg, h_range_m=h_range,
                           num_workers=params.workers)
    products = orient_relative(left, right, ties, out, dem, h_range,
                               RelativeConfig(corrections=params.corrections),
                               params.reference_sigma_m, used)
    for line in products.lines():
        print(line)
    return RelativeOutcome(left, replace(right, model=products.right_model), reference_path,
                           products.rel_json, (measure_line, *products.lines()))


@flow(name="relative-models")
def relative_models(pair: PairInputs, out_dir: Path,
                    workers: int | None = None) -> RelativeOutcome:
    """The pair relatively oriented (for the steps that follow, e.g. ``gcpfree dsm``); writes
    ``out_dir/rel.json`` and its tie points. ``workers``: threads for the tie points."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    return relative_flow(RelativeParams(pair=pair, out=out_dir / "rel.json", workers=workers))
