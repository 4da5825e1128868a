"""What ``gcpfree info`` reports: an image's sensor model, footprint, viewing angles, GSD and
acquisition time, the self-check of SPOT metadata, the mean terrain height from a reference
DEM, and for two images their convergence, B/H and overlap.

Reads through :func:`tasks.io.sensors.load_model` and a window of the reference DEM; every
figure comes from :mod:`core.sensors.viewing` (and :func:`core.sensors.spot.frame_errors_m`).
Plain functions, no Prefect: the command is meant to answer in about a second.

Heights: corners are always given at h = 0 (WGS84 ellipsoid, where SPOT states its corners).
The view (centre, angles, GSD) and the pair are evaluated at the reference's mean terrain height
when ``--reference`` is given, else at the RPC's mean height (its HEIGHT_OFF: the height the
vendor fitted it around) for an RPC, else at h = 0.
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rasterio.errors import NotGeoreferencedWarning

from core.errors import GeometryError, InputError
from core.geodesy import BBox
from core.heights import DatumDecision
from core.jsonio import to_json
from core.sensors.footprint import ANY_TERRAIN_H_M, footprint_box, scene_height_range_m
from core.sensors.rpc import RPCModel
from core.sensors.sar import GridCheck, grid_check
from core.sensors.spot import frame_errors_m
from core.sensors.viewing import (
    GroundCorner,
    PairGeometry,
    SceneGeometry,
    TerrainHeight,
    centre_rays_height_m,
    footprint_mean_height_m,
    pair_geometry,
    scene_geometry,
)
from tasks.io.dem import VERTICALS, check_reference, dem_datum, read_reference
from tasks.io.rasters import atomic_write_text
from tasks.io.sensors import LoadedModel, load_model

FORMAT = "gcpfree.info"
LABEL = 15  # width of the printed labels


# ---------------------------------------------------------------------------- results


@dataclass(frozen=True)
class ReferenceHeight:
    """The reference DEM under one image: its file, vertical datum, mean terrain height and
    the image geometry at that height."""

    path: str
    vertical: str
    vertical_source: str
    terrain: TerrainHeight
    geometry: SceneGeometry


@dataclass(frozen=True)
class ImageInfo:
    """Everything ``info`` says about one image (or model file)."""

    input: Path
    loaded: LoadedModel
    at_zero: SceneGeometry  # corners at h = 0
    view: SceneGeometry  # centre view (angles, GSD) at the evaluation height
    view_height: str  # why that height
    corner_check_m: tuple[tuple[float, float, float], ...] | None  # (col, row, error_m)
    reference: ReferenceHeight | None
    sar_check: GridCheck | None = None  # a SAR model against its annotation's grid

    def to_dict(self) -> dict[str, Any]:
        lm, v, spot = self.loaded, self.view, self.loaded.spot
        d: dict[str, Any] = {
            "input": str(self.input),
            "image": None if lm.image is None else str(lm.image),
            "source": str(lm.source),
            "family": lm.family,
            "size": {"cols": lm.size[0], "rows": lm.size[1]},
            "crop_offset_px": {"col": lm.crop[0], "row": lm.crop[1]},
            "band": lm.band,
            "mission": None if spot is None else f"SPOT {spot.mission_index}",
            "instrument": None if spot is None else f"{spot.instrument} {spot.instrument_index}",
            "sensor_code": None if spot is None else spot.sensor_code,
            "dataset_name": None if spot is None else spot.dataset_name,
            "acquisition_utc": self.at_zero.acquisition_utc,
            "corners": _corners(self.at_zero.corners),
            "footprint_km2": self.at_zero.area_km2,
            "view_h_m": v.h_m,
            "view_height": self.view_height,
            "centre": {"col": v.centre_col, "row": v.centre_row, "lon_deg": v.centre_lon_deg,
                       "lat_deg": v.centre_lat_deg, "h_m": v.h_m},
            "incidence_deg": v.incidence_deg,
            "across_track_incidence_deg": v.across_track_incidence_deg,
            "azimuth_deg": v.azimuth_deg,
            "gsd_m": {"across": v.gsd_across_m, "along": v.gsd_along_m},
            "stated": None if spot is None else {
                "incidence_deg": spot.incidence_deg, "viewing_angle_deg": spot.viewing_angle_deg,
                "sun_azimuth_deg": spot.sun_azimuth_deg,
                "sun_elevation_deg": spot.sun_elevation_deg},
            "metadata_corner_check_m": None,
            "reference": None,
            "sar": None,
        }
        if lm.sar is not None:
            a = lm.sar
            d["sar"] = {"mission": a.mission, "mode": a.mode, "product_type": a.product_type,
                        "polarisation": a.polarisation, "swath": a.swath,
                        "kind": a.model.kind,
                        "grid_check": None if self.sar_check is None
                        else self.sar_check.to_dict()}
        if self.corner_check_m is not None:
            d["metadata_corner_check_m"] = {
                "max": max(e for _, _, e in self.corner_check_m),
                "points": [{"col": _px(c), "row": _px(r), "error_m": e}
                           for c, r, e in self.corner_check_m],
            }
        if self.reference is not None:
            ref = self.reference
            d["reference"] = {
                "path": ref.path, "vertical": ref.vertical,
                "vertical_source": ref.vertical_source, "mean_h_m": ref.terrain.mean_h_m,
                "covered_pct": ref.terrain.covered_pct,
                "corners": _corners(ref.geometry.corners),
            }
        return d

    def lines(self) -> list[str]:
        lm, v, spot = self.loaded, self.view, self.loaded.spot
        out = [_line("input", str(self.input)),
               _line("model", f"{lm.family}, from {lm.source}"
                     + (f", moved to the crop at pixel ({lm.crop[0]:g}, {lm.crop[1]:g}) of the "
                        "product" if lm.crop != (0.0, 0.0) else "")),
               _line("size", f"{lm.size[0]} x {lm.size[1]} px (cols x rows)")]
        if spot is not None:
            out.append(_line("mission", (
                f"SPOT {spot.mission_index} {spot.instrument} {spot.instrument_index}, sensor "
                f"{spot.sensor_code}, band {lm.band}"
                + (f" ({spot.dataset_name})" if spot.dataset_name else ""))))
        if lm.sar is not None:
            a = lm.sar
            out.append(_line("mission", f"{a.mission} {a.mode} {a.product_type} "
                             f"{a.polarisation} (SAR {a.model.kind}, zero-Doppler geometry)"))
        if self.at_zero.acquisition_utc:
            out.append(_line("acquired", f"{self.at_zero.acquisition_utc} (centre row)"))
        out += _corner_lines(self.at_zero)
        out.append(_line("footprint", f"{self.at_zero.area_km2:.4g} km2 at h = 0 m"))
        out.append(_line("centre", (
            f"lon {v.centre_lon_deg:.6f} lat {v.centre_lat_deg:.6f} at h = {v.h_m:.1f} m "
            f"({self.view_height})")))
        side = "west" if v.across_track_incidence_deg >= 0 else "east"
        out.append(_line("incidence", (
            f"{v.incidence_deg:.3f} deg, across track {v.across_track_incidence_deg:+.3f} deg "
            f"(sensor {side}), sensor azimuth {v.azimuth_deg:.2f} deg")))
        if spot is not None and spot.incidence_deg is not None:
            out.append(_line("", f"stated: incidence {spot.incidence_deg:+.3f} deg"))
        out.append(_line("GSD", f"{v.gsd_across_m:.3f} m across (cols), "
                                f"{v.gsd_along_m:.3f} m along (rows)"))
        if self.corner_check_m is not None:
            errs = [e for _, _, e in self.corner_check_m]
            out.append(_line("corner check", (
                f"max {max(errs):.3f} m, stated corners and centre vs the model "
                "(as the producer computes them)")))
        if self.sar_check is not None:
            g = self.sar_check
            out.append(_line("grid check", (
                f"{g.n_points} points of the annotation's geolocation grid against the model: "
                f"line max {g.line_max_px:.3f} rms {g.line_rms_px:.3f} px, pixel max "
                f"{g.pixel_max_px:.4f} rms {g.pixel_rms_px:.4f} px")))
            out.append(_line("", (
                f"azimuth time max {g.azimuth_max_m * 100:.2f} cm along track, slant range max "
                f"{g.range_max_mm:.3f} mm, localisation max {g.ground_max_m:.2f} m")))
        if self.reference is not None:
            ref = self.reference
            out.append(_line("reference", f"{ref.path}: " + DatumDecision(
                ref.vertical, ref.vertical_source).describe()))
            out.append(_line("", (
                f"mean h {ref.terrain.mean_h_m:.1f} m (ellipsoidal) under the footprint "
                f"({ref.terrain.covered_pct:.0f} % of samples)")))
            out += _corner_lines(ref.geometry)
        return out


@dataclass(frozen=True)
class InfoReport:
    """One or two images and, for two, their pair geometry (None when they do not overlap)."""

    images: tuple[ImageInfo, ...]
    pair: PairGeometry | None = None
    pair_h_m: float | None = None
    pair_height: str = ""  # why that height

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {"format": FORMAT, "version": 1, **self.images[0].to_dict()}
        if len(self.images) > 1:
            d["image2"] = self.images[1].to_dict()
            d["pair"] = {**_pair_dict(self.pair, self.pair_h_m), "height": self.pair_height}
        return d

    def to_json(self) -> str:
        return to_json(self.to_dict(), indent=2)

    def lines(self) -> list[str]:
        out = list(self.images[0].lines())
        if len(self.images) > 1:
            out += ["", *self.images[1].lines(), ""]
            p = self.pair
            if p is None:
                out.append(_line("pair", f"the footprints do not overlap at h = "
                                         f"{self.pair_h_m:.1f} m ({self.pair_height})"))
            else:
                out.append(_line("pair", (
                    f"B/H {p.b_over_h:.3f}, convergence {p.convergence_deg:.2f} deg, overlap "
                    f"{p.overlap_pct:.1f} % of image 1, at h = {p.h_m:.1f} m "
                    f"({self.pair_height})")))
                out.append(_line("", (
                    f"at lon {p.lon_deg:.6f} lat {p.lat_deg:.6f}: image 1 ({p.col1:.1f}, "
                    f"{p.row1:.1f}) incidence {p.incidence1_deg:.2f} deg azimuth "
                    f"{p.azimuth1_deg:.1f}; image 2 ({p.col2:.1f}, {p.row2:.1f}) incidence "
                    f"{p.incidence2_deg:.2f} deg azimuth {p.azimuth2_deg:.1f}")))
        return out


def _line(label: str, text: str) -> str:
    return f"{label:<{LABEL - 1}} {text}"


def _px(v: float) -> int | float:
    """Whole pixel coordinates as integers in the JSON."""
    return int(v) if float(v).is_integer() else float(v)


def _corners(corners: tuple[GroundCorner, ...]) -> list[dict[str, float]]:
    return [{"col": _px(c.col), "row": _px(c.row), "lon_deg": c.lon_deg, "lat_deg": c.lat_deg}
            for c in corners]


def _corner_lines(g: SceneGeometry) -> list[str]:
    out = [_line("corners", f"at h = {g.h_m:.1f} m (WGS84 ellipsoid)")]
    for c in g.corners:
        px = f"({c.col:g}, {c.row:g})"
        out.append(_line(f"  {px}", f"lon {c.lon_deg:11.6f} lat {c.lat_deg:10.6f}"))
    return out


def _pair_dict(p: PairGeometry | None, h_m: float | None) -> dict[str, Any]:
    if p is None:
        return {"h_m": h_m, "overlap_pct": 0.0, "convergence_deg": None, "b_over_h": None}
    return {
        "h_m": p.h_m, "b_over_h": p.b_over_h, "convergence_deg": p.convergence_deg,
        "overlap_pct": p.overlap_pct, "point": {"lon_deg": p.lon_deg, "lat_deg": p.lat_deg},
        "image1": {"col": p.col1, "row": p.row1, "incidence_deg": p.incidence1_deg,
                   "azimuth_deg": p.azimuth1_deg},
        "image2": {"col": p.col2, "row": p.row2, "incidence_deg": p.incidence2_deg,
                   "azimuth_deg": p.azimuth2_deg},
    }


# ---------------------------------------------------------------------------- gathering


def _default_height(lm: LoadedModel) -> tuple[float, str]:
    if isinstance(lm.model, RPCModel):
        return float(lm.model.alt_off), "the RPC's mean height"
    return 0.0, "the ellipsoid"


def _reference_box(lm: LoadedModel) -> BBox:
    """Lon/lat box of the footprint over the heights the scene may have (the one rule of
    :mod:`core.sensors.footprint`), plus the metadata's margin."""
    return footprint_box([(lm.model, (0, 0, *lm.size))], scene_height_range_m([lm.model]))


def describe_image(path: str | Path, *, model: str | Path | None = None, band: int | None = None,
                   reference: str | Path | None = None, vertical: str = "auto") -> ImageInfo:
    """Load the model of ``path`` (an image or a model file) and describe it; see the module
    docstring for the heights used."""
    path = Path(path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", NotGeoreferencedWarning)
        lm = load_model(path, model=model, band=band)
    n_cols, n_rows = lm.size
    at_zero = scene_geometry(lm.model, n_cols, n_rows, 0.0)
    h_view, why = _default_height(lm)
    ref = None
    if reference is not None:
        reference = Path(reference)
        decision = dem_datum(reference, vertical)
        dem = read_reference(reference, _reference_box(lm), decision.datum)
        terrain = footprint_mean_height_m(lm.model, n_cols, n_rows, dem, h0_m=h_view)
        h_view, why = terrain.mean_h_m, "the reference's mean height"
        ref = ReferenceHeight(str(reference), decision.datum, decision.source, terrain,
                              scene_geometry(lm.model, n_cols, n_rows, h_view))
    view = at_zero if h_view == 0.0 else (
        ref.geometry if ref is not None else scene_geometry(lm.model, n_cols, n_rows, h_view))
    check = None
    if lm.spot is not None and lm.spot.frame:
        errs = frame_errors_m(lm.spot, lm.band)
        check = tuple((p.col - 1.0, p.row - 1.0, float(e))
                      for p, e in zip(lm.spot.frame, errs, strict=True))
    sar = None
    if lm.sar is not None:
        g = lm.sar.grid
        sar = grid_check(lm.sar.model, g.lon_deg, g.lat_deg, g.h_m, g.pixel, g.line,
                         g.azimuth_time_s, g.slant_range_time_s)
    return ImageInfo(path, lm, at_zero, view, why, check, ref, sar)


def gather_info(path: str | Path, path2: str | Path | None = None, *,
                model: str | Path | None = None, model2: str | Path | None = None,
                band: int | None = None, reference: str | Path | None = None,
                vertical: str = "auto") -> InfoReport:
    """Describe one image, or two and their pair geometry (at the first image's view height).

    ``band`` applies to both images. Raises InputError on unreadable inputs, CoverageError when
    the reference does not cover an image.
    """
    if vertical not in VERTICALS:
        raise InputError(f"reference vertical {vertical!r} unknown; use one of {VERTICALS}")
    if model2 is not None and path2 is None:
        raise InputError("--model2 names the model of a second image; give IMAGE2 too")
    if band is not None and band < 1:
        raise InputError(f"band {band}: BAND_INDEX starts at 1")
    if reference is not None:
        check_reference(reference)
        dem_datum(reference, vertical)  # refused in one line before any model is read
    first = describe_image(path, model=model, band=band, reference=reference, vertical=vertical)
    if path2 is None:
        return InfoReport((first,))
    second = describe_image(path2, model=model2, band=band, reference=reference,
                            vertical=vertical)
    m1, s1, m2, s2 = first.loaded.model, first.loaded.size, second.loaded.model, second.loaded.size
    h, why = first.view.h_m, first.view_height
    try:
        return InfoReport((first, second), pair_geometry(m1, s1, m2, s2, h), h, why)
    except GeometryError:
        if reference is not None:  # the terrain height is known: report what it gives
            return InfoReport((first, second), None, h, why)
    # crops cut around a point at another height may overlap only there: try where the
    # central lines of sight meet
    try:
        h_meet, _ = centre_rays_height_m(m1, s1, m2, s2, h)
        if ANY_TERRAIN_H_M[0] <= h_meet <= ANY_TERRAIN_H_M[1]:
            return InfoReport((first, second), pair_geometry(m1, s1, m2, s2, h_meet), h_meet,
                              f"where the centre lines of sight meet; no overlap at {h:.1f} m")
    except GeometryError:
        pass
    return InfoReport((first, second), None, h, why)


def check_json_target(path: str | Path) -> None:
    """Fail early when the JSON cannot be written: its nearest existing parent must be a
    writable folder."""
    path = Path(path)
    parent = path.absolute().parent
    while not parent.exists():
        parent = parent.parent
    if path.is_dir() or not parent.is_dir() or not os.access(parent, os.W_OK | os.X_OK):
        raise InputError(f"cannot write the JSON to {path}: {parent} is not a writable folder "
                         "(or the path is a folder); choose another --json path")


def write_info_json(report: InfoReport, path: str | Path) -> Path:
    """Write the report's dictionary as JSON, atomically."""
    try:
        return atomic_write_text(path, report.to_json() + "\n")
    except OSError as exc:
        raise InputError(f"cannot write the JSON to {path}: {exc.strerror}; choose another "
                         "--json path") from exc
