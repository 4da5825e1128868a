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
from core.matching.tiepoint_results import TiePointResult, TiePointStatus
from core.orientation.relative import (
    AlongEpipolar,
    RelativeConfig,
    epipolar_fit,
    fix_along_epipolar,
    image_correction,
    relative_orientation,
)
from core.sensors.base import SensorModel
from core.sensors.footprint import footprint_box
from core.sensors.viewing import footprint_mean_height_m, pair_geometry
from tasks.io.pair import PairInputs
from tasks.io.rasters import atomic_write_json
from tasks.io.sensors import LoadedModel

FORMAT = "gcpfree.relative"
DEFAULT_CONFIG = RelativeConfig()


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
