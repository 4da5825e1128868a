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
    write ``rel.json``, and the settings; for :func:`views_relative_flow`, the ``images``
    too."""

    pair: PairInputs
    out: Path
    height_range_m: tuple[float, float] | None = None
    corrections: str = "linear"
    cell_m: float = 2000.0
    search_radius_m: float | None = None  # default: from the GSD (default_search_radius_m)
    reference_sigma_m: float = 5.0
    tie_points: TiePointConfig = field(default_factory=TiePointConfig)  # measure: the pair's
    workers: int | None = None  # threads matching the tie-point cells (default one per core)
    images: tuple[Path, ...] = ()  # views_relative_flow: the N images, the first fixed; the
    # pair carries their band, reference and tie measure


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

    from core.matching.peaks import MEASURE_NAMES
    from tasks.relative.orientation import (
        check_overlap,
        load_pair,
        orient_relative,
        reference_ground,
        scene_height_m,
        search_radius_m,
    )
    from tasks.relative.tiepoints import find_tie_points, tie_measure

    out, pair = Path(params.out), params.pair
    left, right = load_pair(pair)
    ground = reference_ground(pair, [left, right], out, params.height_range_m)
    dem, h_range = ground.dem, ground.h_range
    check_overlap(left, right, scene_height_m(left, dem, h_range),
                  None if dem is not None else h_range)
    radius = search_radius_m(params.search_radius_m, left, h_range)
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
                               params.reference_sigma_m, ground.used)
    for line in products.lines():
        print(line)
    return RelativeOutcome(left, replace(right, model=products.right_model), ground.path,
                           products.rel_json, (measure_line, *products.lines()))


@flow(name="relative-models")
def relative_models(pair: PairInputs, out_dir: Path,
                    workers: int | None = None) -> RelativeOutcome:
    """The pair relatively oriented (for the steps that follow, e.g. ``gcpfree dsm``); writes
    ``out_dir/rel.json`` and its tie points. ``workers``: threads for the tie points."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    return relative_flow(RelativeParams(pair=pair, out=out_dir / "rel.json", workers=workers))


@dataclass(frozen=True, eq=False)
class ViewsOutcome:
    """N images after one joint relative orientation: ``views[k].model`` adjusted (the first
    as given); ``h_range_m`` the tie points' heights; ``reference`` as in
    :class:`RelativeOutcome`; ``models_before`` the models as delivered."""

    views: tuple[LoadedModel, ...]
    models_before: tuple[LoadedModel, ...]
    reference: Path | None
    rel_json: Path
    h_range_m: tuple[float, float]
    lines: tuple[str, ...] = ()


@flow(name="relative-views", log_prints=True)
def views_relative_flow(params: RelativeParams) -> ViewsOutcome:
    """Models -> reference -> tie points of every overlapping pair -> one joint relative
    orientation of all images (the first fixed) -> relative.json."""
    from dataclasses import replace

    from core.errors import GeometryError
    from core.matching.peaks import MEASURE_NAMES
    from tasks.relative.orientation import (
        common_cell_m,
        each_overlapped,
        load_views,
        orient_views,
        overlapping_pairs,
        reference_ground,
        scene_height_m,
        search_radius_m,
    )
    from tasks.relative.tiepoints import resumed_tie_points, tie_measure

    out, pair = Path(params.out), params.pair
    views = load_views(pair, params.images)
    ground = reference_ground(pair, views, out, params.height_range_m)
    dem, h_range = ground.dem, ground.h_range
    pairs = overlapping_pairs(views, scene_height_m(views[0], dem, h_range),
                              None if dem is not None else h_range)
    cfg = replace(params.tie_points, cell_m=params.cell_m,
                  search_radius_m=search_radius_m(params.search_radius_m, views[0], h_range))
    cfg = replace(cfg, cell_m=common_cell_m(views, pairs, dem, h_range, cfg))
    ties, lines, matched = [], [], []
    for i, j in pairs:
        measure, why = tie_measure(pair.tie_measure, views[i].sun, views[j].sun)
        lines.append(f"tie points {i}-{j}       {MEASURE_NAMES[measure]} ({why})")
        print(lines[-1])
        try:
            result, resumed = resumed_tie_points(
                views[i], views[j], dem, replace(cfg, measure=measure),
                out.parent / f"ties_{i}_{_stem(views[i])}__{j}_{_stem(views[j])}.json",
                h_range_m=h_range, reference_path=ground.path, num_workers=params.workers)
            ties.append(result)
            if resumed:
                print(f"tie points {i}-{j}       read back (the same images and settings)")
        except GeometryError:  # of many images, two whose footprints touch at a corner
            if len(views) == 2:
                raise
            lines[-1] = f"tie points {i}-{j}       none (their footprints only touch)"
            print(lines[-1])
            continue
        matched.append((i, j))
    pairs = each_overlapped(views, matched)
    products = orient_views(views, pairs, ties, out, dem, h_range,
                            RelativeConfig(corrections=params.corrections),
                            params.reference_sigma_m, ground.used)
    for line in products.lines():
        print(line)
    return ViewsOutcome(tuple(replace(v, model=m) for v, m in zip(views, products.models,
                                                                   strict=True)),
                        tuple(views), ground.path, products.rel_json, products.h_range_m,
                        (*lines, *products.lines()))


def _stem(view: LoadedModel) -> str:
    return Path(view.image or view.source).stem


@flow(name="relative-views-models")
def views_models(pair: PairInputs, images: tuple[Path, ...], out_dir: Path,
                 workers: int | None = None) -> ViewsOutcome:
    """The images jointly oriented (for ``gcpfree dsm --images``); writes
    ``out_dir/relative.json`` and its tracks. ``workers``: threads for the tie points."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    return views_relative_flow(RelativeParams(pair=pair, out=out_dir / "relative.json",
                                              workers=workers, images=tuple(images)))
