"""Tasks of the relative orientation: the pair's models, the reference DEM, the adjustment and
its products (``rel.json`` and the tie points with their relative ground coordinates).

The maths is in :mod:`core.orientation.relative` and :mod:`core.intersection`; here the
models are found and checked, the reference is read or prepared, and the results written.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from prefect import task

from core.dem import GeoDEM
from core.errors import CoverageError, GeometryError, InsufficientDataError
from core.geodesy import BBox
from core.heights import DatumDecision
from core.intersection import triangulate
from core.matching.overlap import overlap_area_m2, overlap_cell_m
from core.matching.tiepoint_results import TiePointResult, TiePointStatus
from core.matching.tiepoints import HeightPrior, TiePointConfig
from core.orientation.multiview import (
    JointAlong,
    ViewPairFit,
    fix_along_joint,
    joint_relative_orientation,
    track_heights,
)
from core.orientation.relative import (
    AlongEpipolar,
    RelativeConfig,
    epipolar_fit,
    fix_along_epipolar,
    image_correction,
    relative_orientation,
)
from core.orientation.tracks import PairTies, Tracks, tracks_from_pairs
from core.sensors.base import SensorModel
from core.sensors.footprint import footprint_box
from core.sensors.viewing import footprint_mean_height_m, pair_geometry
from tasks.io.pair import PairInputs
from tasks.io.rasters import atomic_write_json
from tasks.io.sensors import LoadedModel

FORMAT = "gcpfree.relative"
DEFAULT_CONFIG = RelativeConfig()
#: of three images or more, a pair under this base-to-height ratio gives no tie points
MIN_B_OVER_H = 0.02
#: an overlap this fraction of the widest one or more sets the images' common tie-point cell
WIDE_OVERLAP = 0.25


@task(name="load-pair")
def load_pair(pair: PairInputs) -> tuple[LoadedModel, LoadedModel]:
    """The sensor models of both images (found beside them unless given)."""
    return pair.load()


def pair_box(left: LoadedModel, right: LoadedModel, h_range: tuple[float, float]) -> BBox:
    """The lon/lat box holding both images' footprints over the height range, with the
    metadata's margin (:func:`core.sensors.footprint.footprint_box`)."""
    return footprint_box([(m.model, (0, 0, *m.size)) for m in (left, right)], h_range)


def scene_height_m(left: LoadedModel, dem: GeoDEM | None, h_range: tuple[float, float]) -> float:
    """The mean terrain height under the left image: from the reference DEM, else mid-range."""
    if dem is None:
        return 0.5 * (h_range[0] + h_range[1])
    return footprint_mean_height_m(left.model, *left.size, dem,
                                   h0_m=0.5 * (h_range[0] + h_range[1])).mean_h_m


def check_overlap(left: LoadedModel, right: LoadedModel, h_m: float,
                  h_range: tuple[float, float] | None = None) -> float:
    """The overlap (% of the left footprint) at the terrain height ``h_m``; GeometryError when
    there is none (the images do not overlap, or a model does not belong to its image).

    ``h_range``: when the terrain height is only known to lie in a range (no reference DEM),
    the pair overlaps if it does at some height of the range: small crops of a wide-baseline
    pair (Pleiades) can miss each other at mid-range and overlap at the true height.
    """
    levels = [h_m]
    if h_range is not None:
        levels += [float(h) for h in np.linspace(h_range[0], h_range[1], 17)]
    best = None
    for h in levels:
        try:
            pct = float(pair_geometry(left.model, left.size, right.model, right.size,
                                      h).overlap_pct)
        except GeometryError:
            continue
        best = pct if best is None else max(best, pct)
        if h == h_m:
            return pct
    if best is None:
        where = (f"at any terrain height in {h_range[0]:.0f}..{h_range[1]:.0f} m"
                 if h_range is not None else f"at the terrain height ({h_m:.0f} m)")
        raise GeometryError(
            f"{left.image or left.source} and {right.image or right.source} do not overlap under "
            f"their sensor models {where}; check that each model belongs to its image")
    return best


@dataclass(frozen=True)
class ReferenceUsed:
    """The reference DEM a step used: its file, its vertical datum decision, and the SRTM
    folder it was prepared from (None when given as a file)."""

    path: Path
    datum: DatumDecision
    srtm_dir: Path | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"path": str(self.path), **self.datum.to_dict(),
                "srtm_dir": None if self.srtm_dir is None else str(self.srtm_dir)}



@dataclass(frozen=True, eq=False)
class Ground:
    """The heights a relative orientation searches its tie points over: the reference DEM
    (``path``, prepared from DEM tiles when those were given; ``dem`` read over the images)
    with ``used`` its datum decision, or none; ``h_range`` the reference's heights, else the
    scene's (:func:`core.sensors.footprint.scene_height_range_m`)."""

    path: Path | None
    used: ReferenceUsed | None
    dem: GeoDEM | None
    h_range: tuple[float, float]


def reference_ground(pair: PairInputs, views: list[LoadedModel], out: Path,
                     height_range_m: tuple[float, float] | None) -> Ground:
    """The reference of ``pair`` (given, or prepared from its DEM tiles over every image's
    footprint into ``<out>.reference.tif``) read over the images, or the scene's heights."""
    from core.sensors.footprint import ANY_TERRAIN_H_M, scene_height_range_m
    from tasks.io.dem import dem_datum, read_reference
    from tasks.io.reference import build_reference, locate_tiles

    out = Path(out)
    path, vertical = pair.reference, pair.reference_vertical
    box = views_box(views, height_range_m or ANY_TERRAIN_H_M)
    if path is None and pair.srtm_dir is not None:
        tiles = locate_tiles(pair.dem_source, box, True)
        path = Path(build_reference(tiles, box, out.with_name(out.stem + ".reference.tif")).path)
        vertical = "auto"  # its own tag says ellipsoidal
    if path is None:
        return Ground(None, None, None, scene_height_range_m([v.model for v in views],
                                                             height_range_m, any_terrain=False))
    used = ReferenceUsed(Path(path), dem_datum(path, vertical),
                         None if pair.reference is not None else pair.srtm_dir)
    dem = read_reference(used.path, box, used.datum.datum)
    return Ground(Path(path), used, dem, reference_box_heights(dem))


def search_radius_m(given: float | None, left: LoadedModel, h_range: tuple[float, float]
                    ) -> float:
    """The tie points' search radius: ``given``, else from the left image's GSD at its centre
    (:func:`core.matching.tiepoints.default_search_radius_m`)."""
    from core.matching.tiepoints import default_search_radius_m, ground_sampling_m

    if given is not None:
        return given
    c, r = 0.5 * (left.size[0] - 1), 0.5 * (left.size[1] - 1)
    return default_search_radius_m(ground_sampling_m(left.model, c, r,
                                                     0.5 * (h_range[0] + h_range[1])))


@dataclass(frozen=True, eq=False)
class RelativeProducts:
    """What :func:`orient_relative` wrote and the figures a user reads first."""

    rel_json: Path
    tie_points_json: Path
    right_model: SensorModel
    n_points: int
    n_rejected: int
    parallax_rms_before_px: float
    parallax_rms_after_px: float
    along_epipolar: AlongEpipolar
    cell_m: float | None = None  # the tie points' ground cell (smaller than asked on crops)
    reference: ReferenceUsed | None = None

    def lines(self) -> list[str]:
        ae = self.along_epipolar
        along = ("not observable: held at the metadata (no reference DEM)" if not ae.observable
                 else f"{ae.shift_px:+.3f} px +- {ae.sigma_px:.3f} from the reference DEM"
                 if ae.sigma_px is not None else "observable")
        return [
            f"relative orientation  {self.rel_json}",
            (f"tie points            {self.n_points} used, {self.n_rejected} rejected"
             + (f", one per {self.cell_m:.4g} m cell" if self.cell_m is not None else "")
             + f" ({self.tie_points_json.name})"),
            (f"y-parallax RMS        {self.parallax_rms_before_px:.3f} px before, "
             f"{self.parallax_rms_after_px:.3f} px after"),
            f"along epipolar        {along}",
        ]


def _model_dict(model: SensorModel) -> dict[str, Any]:
    return model.to_dict()  # type: ignore[attr-defined]


@task(name="relative-orientation")
def orient_relative(
    left: LoadedModel, right: LoadedModel, ties: TiePointResult, out: Path,
    reference: GeoDEM | None = None, h_range: tuple[float, float] | None = None,
    config: RelativeConfig = DEFAULT_CONFIG, reference_sigma_m: float = 5.0,
    reference_used: ReferenceUsed | None = None,
) -> RelativeProducts:
    """Adjust the right model to the left from the tie points, set the along-epipolar part
    from the reference DEM when there is one, intersect the tie points, write ``out``
    (rel.json) and ``<out>.tiepoints.json``."""
    tp = ties.tie_points
    ok = np.flatnonzero(tp.ok)
    lc, lr, rc, rr = (np.asarray(a)[ok] for a in (tp.left_col, tp.left_row, tp.right_col,
                                                  tp.right_row))
    h_mid = 0.5 * sum(h_range) if h_range is not None else 0.0
    h0 = np.where(np.isfinite(tp.h_m[ok]), tp.h_m[ok], h_mid) if tp.h_m.size else h_mid
    try:
        rel = relative_orientation(left.model, right.model, lc, lr, rc, rr, h0, config)
    except InsufficientDataError as exc:
        r = ties.report
        why = ", ".join(f"{k.lower().replace('_', ' ')} {v}" for k, v in r.rejected.items())
        raise InsufficientDataError(
            f"{exc}. The search tried {r.n_candidates} interest points in "
            f"{r.n_cells_textured} of {r.n_cells} ground cells with texture; rejected: "
            f"{why or 'none'} (clouds, change between the dates or no texture)") from None
    model = rel.right_model
    along = AlongEpipolar(observable=not rel.unobservable)
    if reference is not None and rel.unobservable:
        fit = epipolar_fit(left.model, model, lc, lr, rc, rr, h0)
        href = reference.height_m(fit.lon_deg, fit.lat_deg)
        model, along = fix_along_epipolar(left.model, rel, lc, lr, rc, rr, href, *right.size,
                                          reference_sigma_m=reference_sigma_m)
    h_ref = float(np.nanmedian(h0)) if np.isfinite(h0).any() else h_mid
    corr = image_correction(left.model, right.model, model, *right.size, h_ref)
    lo, hi = (float(np.nanmin(h0)) - 500.0, float(np.nanmax(h0)) + 500.0)
    ground = triangulate([left.model, model], [lc, rc], [lr, rr], (lo, hi))
    tie_json = Path(out).with_suffix(".tiepoints.json")
    tie_doc = {
        "report": ties.report.to_dict(),
        "tie_points": tp.with_status(ok[~rel.inlier],
                                     TiePointStatus.ORIENTATION_OUTLIER).to_dict(),
        "relative_ground": {
            "index": ok.tolist(), "lon_deg": ground.lon_deg.tolist(),
            "lat_deg": ground.lat_deg.tolist(), "h_m": ground.h_m.tolist(),
            "miss_m": ground.miss_m.tolist(), "parallax_px": rel.parallax_px.tolist(),
            "inlier": rel.inlier.tolist(),
            "heights": "WGS84 ellipsoidal, from the left and the relatively oriented right model",
        },
    }
    atomic_write_json(tie_json, tie_doc, indent=None)
    doc = {
        "format": FORMAT, "version": 1,
        "left": {"image": str(left.image), "model": str(left.source), "family": left.family},
        "right": {"image": str(right.image), "model": str(right.source),
                  "family": right.family},
        "tie_points": int(rel.inlier.sum()),
        "tie_points_rejected": int((~rel.inlier).sum()),
        "tie_points_file": tie_json.name,
        "tie_point_search": ties.report.to_dict(),
        "parallax_rms_before_px": rel.parallax_rms_before_px,
        "parallax_rms_after_px": rel.parallax_rms_after_px,
        "right_correction": {
            "col_shift_px": corr.col_shift_px, "row_shift_px": corr.row_shift_px,
            "across_epipolar_px": corr.across_epipolar_px,
            "along_epipolar_px": corr.along_epipolar_px,
            "affine": [list(r) for r in corr.affine], "affine_rms_px": corr.affine_rms_px,
            "at_height_m": h_ref, "corrections": config.corrections,
        },
        "epipolar_direction": list(corr.epipolar_direction),
        "along_epipolar_observable": along.observable,
        "along_epipolar": vars(along),
        "miss_distance_m": {"median": float(np.median(ground.miss_m[rel.inlier])),
                            "p95": float(np.percentile(ground.miss_m[rel.inlier], 95))},
        "adjustment": rel.to_dict(),
        "reference": None if reference_used is None else reference_used.to_dict(),
        "right_model": _model_dict(model),
    }
    atomic_write_json(out, doc)
    return RelativeProducts(Path(out), tie_json, model, int(rel.inlier.sum()),
                            int((~rel.inlier).sum()), rel.parallax_rms_before_px,
                            rel.parallax_rms_after_px, along, ties.report.cell_m,
                            reference_used)


def reference_box_heights(reference: GeoDEM) -> tuple[float, float]:
    """The reference's height range (ellipsoidal metres); CoverageError when it holds none."""
    lo, hi = reference.height_range_m()
    if not np.isfinite(lo):
        raise CoverageError("the reference DEM holds no height over the pair; give a DEM that "
                            "covers the images")
    return lo, hi


# ---------------------------------------------------------------------------- N images


@task(name="load-views")
def load_views(pair: PairInputs, images: tuple[Path, ...]) -> list[LoadedModel]:
    """The sensor models of every image (found beside them; the pair's band), the first one
    fixed in the orientation."""
    from tasks.io.sensors import load_model

    return [load_model(Path(im), band=pair.band) for im in images]


def views_box(views: list[LoadedModel], h_range: tuple[float, float]) -> BBox:
    """The lon/lat box holding every image's footprint over the height range."""
    return footprint_box([(m.model, (0, 0, *m.size)) for m in views], h_range)


def overlapping_pairs(views: list[LoadedModel], h_m: float,
                      h_range: tuple[float, float] | None) -> list[tuple[int, int]]:
    """The pairs (i < j) of images that overlap (:func:`check_overlap`) and, of three images
    or more, see their overlap with a base (B/H at least :data:`MIN_B_OVER_H`: consecutive
    scenes of one pass look along the same lines of sight, their tie points hold no height);
    GeometryError when an image is in none of them."""
    pairs = []
    for i in range(len(views)):
        for j in range(i + 1, len(views)):
            try:  # the geometry at h_m serves the overlap and the base (computed once)
                geom = pair_geometry(views[i].model, views[i].size, views[j].model,
                                     views[j].size, h_m)
                bh = float(geom.b_over_h) if len(views) > 2 else None
            except GeometryError:  # overlapping at another height of the range only, or not
                try:
                    check_overlap(views[i], views[j], h_m, h_range)
                except GeometryError:
                    continue
                bh = None
            if bh is not None and bh < MIN_B_OVER_H:
                print(f"tie points {i}-{j}       none: B/H {bh:.3f} (one pass's consecutive "
                      "scenes, or the same view twice)")
                continue
            pairs.append((i, j))
    return each_overlapped(views, pairs)


def each_overlapped(views: list[LoadedModel], pairs: list[tuple[int, int]]
                    ) -> list[tuple[int, int]]:
    """``pairs``, after a GeometryError when an image is in none of them."""
    alone = [v for k, v in enumerate(views) if not any(k in p for p in pairs)]
    if alone:
        raise GeometryError(
            f"{alone[0].image or alone[0].source} overlaps none of the other images under "
            "their sensor models; give images of one area, and check each model")
    return pairs


def common_cell_m(views: list[LoadedModel], pairs: list[tuple[int, int]], dem: GeoDEM | None,
                  h_range: tuple[float, float], cfg: TiePointConfig) -> float:
    """One tie-point ground cell for the pairs that overlap widely (a quarter of the widest
    overlap or more, :data:`WIDE_OVERLAP`): the smallest any of them needs
    (:func:`core.matching.overlap.overlap_cell_m`), so that the pairs sharing an image pick
    its points in the same cells and their points chain into tracks seen three times or
    more (on the Marseille triplet, 46 of 75 against 23 with each pair's own cell). A block's
    narrow overlaps (adjacent scenes' strips, diagonal neighbours' corners) do not shrink it:
    each takes the smaller cell its own overlap needs in
    :func:`tasks.relative.tiepoints.find_tie_points` (a 2 x 2 x 2 tiny block's corners of
    2.4 km had made every pair's cell 300 m, 44 times the stereo pairs' candidates)."""
    heights = (HeightPrior.from_dem(dem, cfg.search_radius_m, cfg.height_margin_m)
               if dem is not None else HeightPrior.from_range(*h_range))
    areas = [overlap_area_m2(views[i].model, views[j].model, views[i].size, views[j].size,
                             heights) for i, j in pairs]
    wide = max((a for a in areas if a > 0), default=0.0) * WIDE_OVERLAP
    return min((overlap_cell_m(views[i].model, views[j].model, views[i].size, views[j].size,
                               heights, cfg.cell_m, cfg.min_cells_per_side)
                for (i, j), a in zip(pairs, areas, strict=True) if a >= wide),
               default=float(cfg.cell_m))


@dataclass(frozen=True, eq=False)
class ViewsProducts:
    """What :func:`orient_views` wrote and the figures a user reads first: the models (the
    first as given, the others adjusted), the tracks and the joint adjustment."""

    rel_json: Path
    tracks_json: Path
    models: tuple[SensorModel, ...]
    n_tracks: int
    n_multi: int
    n_rejected: int
    rms_before_px: float
    rms_after_px: float
    along: JointAlong
    pairs: tuple[ViewPairFit, ...]
    h_range_m: tuple[float, float]  # the inlier tracks' heights

    def lines(self) -> list[str]:
        along = ("not observable: held at the metadata (no reference DEM)"
                 if not self.along.observable else
                 f"set from the reference DEM ({self.along.height_offset_m:+.2f} m, "
                 f"+- {self.along.sigma_m:.2f} m)" if self.along.sigma_m is not None
                 else "observable")
        out = [(f"relative orientation  {self.rel_json} ({len(self.models)} images, the first "
                "fixed)"),
               (f"tie points            {self.n_tracks} tracks, {self.n_multi} seen by three "
                f"images or more, {self.n_rejected} rejected ({self.tracks_json.name})"),
               (f"equations RMS         {self.rms_before_px:.3f} px before, "
                f"{self.rms_after_px:.3f} px after")]
        out += [f"  pair {i}-{j}            {p.n_points} points, y-parallax RMS "
                f"{p.parallax_rms_before_px:.3f} px before, {p.parallax_rms_after_px:.3f} after"
                for p in self.pairs for i, j in [p.images]]
        return [*out, f"common height         {along}"]


def _track_ground(models: tuple[SensorModel, ...], tracks: Tracks, source: np.ndarray,
                  h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each track's ground (lon, lat) on its source ray at its height."""
    lon, lat = np.full(tracks.n, np.nan), np.full(tracks.n, np.nan)
    for s in np.unique(source):
        sel = source == s
        lon[sel], lat[sel] = models[s].localize(tracks.col[sel, s], tracks.row[sel, s], h[sel])
    return lon, lat


@task(name="joint-relative-orientation")
def orient_views(
    views: list[LoadedModel], pairs: list[tuple[int, int]], ties: list[TiePointResult],
    out: Path, reference: GeoDEM | None = None, h_range: tuple[float, float] | None = None,
    config: RelativeConfig = DEFAULT_CONFIG, reference_sigma_m: float = 5.0,
    reference_used: ReferenceUsed | None = None,
) -> ViewsProducts:
    """Every image but the first adjusted at once to the tie points of every pair
    (:func:`core.orientation.multiview.joint_relative_orientation`), their common height set
    from the reference DEM when there is one; writes ``out`` (relative.json) and
    ``<out>.tracks.json``."""
    h_mid = 0.5 * sum(h_range) if h_range is not None else 0.0
    pair_ties = []
    for (i, j), t in zip(pairs, ties, strict=True):
        tp = t.tie_points
        ok = tp.ok
        h0 = tp.h_m[ok] if tp.h_m.size else np.nan
        pair_ties.append(PairTies(i, j, tp.left_col[ok], tp.left_row[ok], tp.right_col[ok],
                                  tp.right_row[ok], h0))
    tracks, which = tracks_from_pairs(len(views), pair_ties, h_mid)
    res = joint_relative_orientation([v.model for v in views], tracks, config)
    models, along = res.models, JointAlong(observable=not res.unobservable)
    if reference is not None and res.unobservable:
        href = reference.height_m(*_track_ground(models, tracks, res.source, res.h_m))
        dirs = np.array([[u.step[n] for n in res.param_names] for u in res.unobservable]).T
        models, along = fix_along_joint(models, 0, tracks, res.inlier, dirs, href,
                                        [v.size for v in views], reference_sigma_m)
    h_m = track_heights(models, tracks, res.h_m) if models is not res.models else res.h_m
    h_in = h_m[res.inlier]
    h_track = (float(np.min(h_in)), float(np.max(h_in)))
    h_ref = float(np.median(h_in))
    tracks_json = Path(out).with_suffix(".tracks.json")
    atomic_write_json(tracks_json, {
        "col": tracks.col.tolist(), "row": tracks.row.tolist(), "h_m": h_m.tolist(),
        "inlier": res.inlier.tolist(), "source": res.source.tolist(),
        "parallax_px": res.parallax_px.tolist(),
        "pairs": [{"images": [i, j], "track": w.tolist()}
                  for (i, j), w in zip(pairs, which, strict=True)],
        "heights": "WGS84 ellipsoidal, on each track's source ray under the adjusted models",
    }, indent=None)
    corrections = [None] + [vars(image_correction(models[0], v.model.with_corrections(
        config.corrections), m, *v.size, h_ref)) for v, m in zip(views[1:], models[1:],
                                                                  strict=True)]
    atomic_write_json(out, {
        "format": "gcpfree.relative-views", "version": 1, "fixed": 0,
        "images": [{"image": str(v.image), "model": str(v.source), "family": v.family}
                   for v in views],
        "tracks": tracks.n, "tracks_multi": int((tracks.seen.sum(axis=1) > 2).sum()),
        "tracks_rejected": int(res.rejected.size), "tracks_file": tracks_json.name,
        "pairs": [{"images": list(p.images),
                   "tie_points": None if t is None else int(t.tie_points.ok.sum()),
                   "tie_point_search": None if t is None else t.report.to_dict(),
                   "parallax_rms_before_px": p.parallax_rms_before_px,
                   "parallax_rms_after_px": p.parallax_rms_after_px}
                  for p, t in zip(res.pairs, _ties_of(res.pairs, pairs, ties), strict=True)],
        "rms_before_px": res.rms_before_px, "rms_after_px": res.rms_after_px,
        "sigma_px": res.sigma_px, "n_iterations": res.n_iterations,
        "converged": res.converged, "corrections": config.corrections,
        "param_names": list(res.param_names), "params_before": res.params_before.tolist(),
        "params_after": [float(v) for m in models[1:] for v in m.params],
        "unobservable": [vars(u) for u in res.unobservable], "common_height": vars(along),
        "image_correction": corrections, "tracks_height_m": list(h_track),
        "reference": None if reference_used is None else reference_used.to_dict(),
        "models": [_model_dict(m) for m in models],
    })
    return ViewsProducts(Path(out), tracks_json, tuple(models), tracks.n,
                         int((tracks.seen.sum(axis=1) > 2).sum()), int(res.rejected.size),
                         res.rms_before_px, res.rms_after_px, along, res.pairs, h_track)


def _ties_of(fits: tuple[ViewPairFit, ...], pairs: list[tuple[int, int]],
             ties: list[TiePointResult]) -> list[TiePointResult | None]:
    """The tie-point search of each pair the adjustment reports on (same order; None for two
    images tied only through tracks that a third one sees)."""
    by_pair = dict(zip(pairs, ties, strict=True))
    return [by_pair.get(f.images) for f in fits]
