"""Tasks of the multi-view DSM: N jointly oriented images, every overlapping pair matched with
the DEM tasks of :mod:`tasks.dense.dem`, their points fused cell by cell into one DEM.

1. :func:`pair_roi`: the region of interest, given in the first image, in each pair's left
   image (its ground at the tie points' heights); :func:`unify_plans` puts every pair's
   points in the first pair's UTM zone, origin and cells.
2. Each pair is matched (:func:`tasks.dense.dem.match_tiles`) and its matches triangulated
   again with the delivered models (:func:`tasks.dense.dem.retriangulate_tiles`): the pairs'
   heights before the joint orientation.
3. :func:`grid_views_cog`: one grid over the first image's region (the tiles of the pairs it
   belongs to), block by block from every pair's point files
   (:func:`tasks.dense.blocks.views_block`: per-pair median heights fused by
   :func:`core.matching.fusion.fuse_heights`, then the holes, islands and edge of
   :func:`core.matching.grid.grid_dem`), written in one streamed pass as ``OUT.tif``,
   ``OUT_mask.tif`` and ``OUT_views.tif`` (the count of images behind each cell's height,
   uint8, 0 without one), with ``OUT.json``: the DEM summary of a pair, plus the images,
   each pair's B/H and tiles, and the median height difference of every two pairs over the
   cells both have (``pairwise_median_m``), before and after the joint orientation.
"""

from __future__ import annotations

import contextlib
import shutil
from dataclasses import asdict, dataclass, replace
from itertools import combinations
from pathlib import Path
from typing import Any

import dask.array as darr
import numpy as np
from prefect import task
from prefect.cache_policies import NO_CACHE

from core.matching.dense_tile import TileStats
from core.matching.fusion import DIFF_EDGES_M, FusionConfig, histogram_median
from core.matching.grid import MASK_MISMATCH, MASK_VALID
from core.matching.rectify import box_in_image
from core.sensors.viewing import pair_geometry
from tasks.dense.blocks import PairPoints, check_roi, views_block
from tasks.dense.dem import (
    DemSummary,
    DenseConfig,
    DensePlan,
    dem_items,
    dem_summary,
    grid_georef,
    grid_spec,
)
from tasks.io.rasters import CHUNK, CogItem, CogOptions, atomic_write_json, write_arrays_cog
from tasks.io.sensors import LoadedModel
from tasks.scheduling import threads


def pair_roi(views: list[LoadedModel], i: int, roi: tuple[int, int, int, int] | None,
             h_range_m: tuple[float, float]) -> tuple[int, int, int, int] | None:
    """The ``--roi`` (COL ROW WIDTH HEIGHT of the first image; None: all of it) in image
    ``i``: the pixels that see its ground at the heights ``h_range_m``
    (:func:`core.matching.rectify.box_in_image`), as COL ROW WIDTH HEIGHT; None for the
    whole image. A pair that does not see it is dropped by the flow (GeometryError of its
    plan)."""
    if roi is None or i == 0:
        return roi
    box = box_in_image(views[0].model, check_roi(roi, views[0].size), views[i].model,
                       views[i].size, h_range_m)
    if box is None:
        return tuple(roi)  # outside image i: its plan says the pair does not overlap there
    return (box[0], box[1], box[2] - box[0], box[3] - box[1])


def b_over_h(left: LoadedModel, right: LoadedModel, h_m: float) -> float:
    """The pair's base-to-height ratio at the centroid of its overlap
    (:func:`core.sensors.viewing.pair_geometry`)."""
    return float(pair_geometry(left.model, left.size, right.model, right.size, h_m).b_over_h)


def unify_plans(plans: list[DensePlan]) -> list[DensePlan]:
    """Every pair's plan with the first one's UTM zone, point origin and cell size: the pairs'
    points land on one grid."""
    first = plans[0]
    return [replace(p, epsg=first.epsg, origin_m=first.origin_m,
                    resolution_m=first.resolution_m) for p in plans]


@dataclass(frozen=True, eq=False)
class MatchedViewPair:
    """A pair of the views matched: its images (indices), plan, tiles and the folder of its
    point files under the joint models; when triangulated again with the delivered models,
    those tiles and folder too; its B/H."""

    images: tuple[int, int]
    plan: DensePlan
    stats: tuple[TileStats, ...]
    work: Path
    b_over_h: float
    stats_before: tuple[TileStats, ...] | None = None
    work_before: Path | None = None

    def points(self, before: bool = False) -> PairPoints:
        if before and (self.work_before is None or self.stats_before is None):
            raise ValueError("this pair was not triangulated with the delivered models")
        work, stats = ((self.work_before, self.stats_before) if before
                       else (self.work, self.stats))
        return PairPoints(str(work), stats, self.b_over_h**2, self.images)


@dataclass(frozen=True)
class ViewsDemSummary:
    """What :func:`grid_views_cog` produced: the DEM summary (as a pair's; its tiles are every
    pair's, its overlap the cells a pair saw), the count-of-views raster, the images and pairs
    (each with the cells of the grid it has a height in), the fusion, how many cells have each
    count of views, and ``pairwise_median_m``: for every two pairs, the median of their height
    differences (m) over the cells both have, before and after the joint orientation."""

    dem: DemSummary
    views_path: str
    images: tuple[str, ...]
    pairs: tuple[dict[str, Any], ...]
    fusion: dict[str, Any]
    views_cells: dict[str, int]
    pairwise_median_m: dict[str, dict[str, Any]]

    def to_dict(self) -> dict[str, Any]:
        d = self.dem.to_dict()
        d.update(views_path=self.views_path, images=list(self.images), pairs=list(self.pairs),
                 fusion=self.fusion, views_cells=self.views_cells,
                 pairwise_median_m=self.pairwise_median_m)
        return d

    def lines(self) -> list[str]:
        cells = ", ".join(f"{v} with {k}" for k, v in self.views_cells.items())
        names = [Path(im).stem for im in self.images]
        out = [line.replace("cells seen by both images", "cells a pair saw")
               for line in self.dem.lines()]
        out.append(f"views          {self.views_path} (cells with a height: {cells} views)")
        out += [f"pair {names[i]}-{names[j]}: B/H {p['b_over_h']:.3f}, heights in {p['cells']} "
                f"cells alone" for p in self.pairs for i, j in [p["images"]]]
        for v in self.pairwise_median_m.values():
            (a, b), (c, d) = v["pairs"]
            said = (f"{v['after']:+.2f} m, the models as delivered (not oriented)"
                    if v["before"] is None else f"{v['before']:+.2f} m before the joint "
                    f"orientation, {v['after']:+.2f} m after")
            out.append(f"{names[a]}-{names[b]} minus {names[c]}-{names[d]}: median height "
                       f"difference {said} ({v['cells']} cells)")
        return out


def _pair_name(images: tuple[int, int]) -> str:
    return f"{images[0]}-{images[1]}"


def _histograms(z_pairs: darr.Array) -> list[Any]:
    """The dask histograms of every two pairs' height differences (in pair order)."""
    return [darr.histogram(z_pairs[p] - z_pairs[q], bins=DIFF_EDGES_M)[0]
            for p, q in combinations(range(z_pairs.shape[0]), 2)]


@task(name="grid-views-dem", cache_policy=NO_CACHE)
def grid_views_cog(pairs: list[MatchedViewPair], images: tuple[str, ...], out: Path,
                   cfg: DenseConfig, fusion: FusionConfig, keep_work: bool = False,
                   extent: str = "first") -> ViewsDemSummary:
    """Fuse the pairs' points into ``out``, ``<out>_mask.tif`` and ``<out>_views.tif``, write
    ``<out>.json`` (module docstring); remove the work folders unless ``keep_work``.
    ``extent``: the grid spans the first image's pairs (``first``) or every pair's (``all``,
    a block)."""
    out = Path(out)
    first = pairs[0].plan
    with_first = [s for p in pairs if 0 in p.images for s in p.stats] if extent == "first" \
        else []
    with_first = with_first or [s for p in pairs for s in p.stats]
    spec = grid_spec(first, tuple(with_first))
    n = len(pairs)
    base = darr.zeros(spec.shape, chunks=CHUNK, dtype=np.float32)
    common = {"spec": spec, "origin_m": first.origin_m, "halo": cfg.halo_cells,
              "max_hole_cells": cfg.max_hole_cells, "min_island_cells": cfg.min_island_cells,
              "fusion": fusion, "new_axis": 0, "dtype": np.float32}
    stack = darr.map_blocks(views_block, base, pairs=tuple(p.points() for p in pairs),
                            chunks=((4 + n,),) + base.chunks, **common)
    z, mask, overlap = stack[0], stack[1].astype(np.uint8), stack[2] > 0
    views = stack[3].astype(np.uint8)
    extra = [*((mask == v).sum() for v in (MASK_VALID, MASK_MISMATCH)), overlap.sum(),
             darr.nanmin(z), darr.nanmax(z), darr.bincount(views.ravel(), minlength=n + 2),
             darr.stack([darr.isfinite(stack[4 + k]).sum() for k in range(n)]),
             *_histograms(stack[4:])]
    has_before = all(p.work_before is not None for p in pairs)
    if has_before:
        before = darr.map_blocks(views_block, base, pairs=tuple(p.points(True) for p in pairs),
                                 heights_only=True, chunks=((n,),) + base.chunks, **common)
        extra += _histograms(before)
    mask_path = out.with_name(out.stem + "_mask.tif")
    views_path = out.with_name(out.stem + "_views.tif")
    georef = grid_georef(first.epsg, spec, cfg.vertical)
    items = [*dem_items(z, mask, out, mask_path, georef, cfg.vertical),
             CogItem(views, views_path, CogOptions(
                 resampling="nearest", tags={"values": "images behind the cell's height "
                                                       "(0: none)"}, **georef))]
    with threads(cfg.num_workers):
        n_ok, n_mis, n_overlap, zmin, zmax, view_counts, pair_cells, *hists = write_arrays_cog(
            items, extra=extra)
    stats = tuple(s for p in pairs for s in p.stats)
    dem = dem_summary(first, stats, spec, out, mask_path, cfg.vertical,
                      spec.n_rows * spec.n_cols, (int(n_ok), int(n_mis), int(n_overlap)),
                      (float(zmin), float(zmax)))
    summary = ViewsDemSummary(
        dem=dem, views_path=str(views_path), images=tuple(images),
        pairs=tuple({"images": list(p.images), "b_over_h": p.b_over_h,
                     "tiles": [s.index for s in p.stats], "cells": int(c),
                     "match_rate_pct": 100.0 * sum(s.n_valid for s in p.stats)
                     / max(sum(s.n_overlap for s in p.stats), 1)}
                    for p, c in zip(pairs, pair_cells, strict=True)),
        fusion=asdict(fusion),
        views_cells={str(k): int(c) for k, c in enumerate(view_counts) if k > 0 and c > 0},
        pairwise_median_m=_pairwise(pairs, hists, has_before))
    atomic_write_json(out.with_suffix(".json"), summary.to_dict())
    if not keep_work:
        for p in pairs:
            for w in (p.work, p.work_before):
                if w is not None:
                    shutil.rmtree(w, ignore_errors=True)
        with contextlib.suppress(OSError):  # the pairs' folder, when nothing else is in it
            pairs[0].work.parent.rmdir()
    return summary


def _pairwise(pairs: list[MatchedViewPair], hists: list[Any], has_before: bool
              ) -> dict[str, dict[str, Any]]:
    """Every two pairs' median height difference, keyed ``"i-j minus k-l"`` (image indices),
    before (None when not oriented) and after, with the cells both have."""
    two = list(combinations(range(len(pairs)), 2))
    after = hists[:len(two)]
    before = hists[len(two):] if has_before else [None] * len(two)
    return {f"{_pair_name(pairs[p].images)} minus {_pair_name(pairs[q].images)}": {
        "pairs": [list(pairs[p].images), list(pairs[q].images)],
        "before": None if b is None else histogram_median(b), "after": histogram_median(a),
        "cells": int(np.sum(a))} for (p, q), a, b in zip(two, after, before, strict=True)}

