"""Task of SAR-optical ground control (issue 20; the maths is
:mod:`core.orientation.sar_gcps`): the SAR scene and its model read, each optical image read
and matched against it on Dask threads, the GCPs made and ``sar_points.json`` written."""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import dask
import numpy as np
import rasterio
from prefect import task
from prefect.cache_policies import NO_CACHE
from rasterio.errors import NotGeoreferencedWarning

from core.dem import GeoDEM, SurfaceGrid
from core.errors import GeometryError, InputError
from core.orientation.frames import FrameEstimate, shifted_ground
from core.orientation.sar_gcps import (
    SarImageResult,
    geolocation_sigma_m,
    sar_gcps_of_image,
)
from core.orientation.sar_matching import SarGcpConfig
from core.points import ControlPoint
from core.sensors.troposphere import with_standard_troposphere
from tasks.io.crs import Projection
from tasks.io.rasters import atomic_write_json, open_raster, read_surface_window
from tasks.io.sensors import LoadedModel, load_model
from tasks.scheduling import compute

FILE = "sar_points.json"


def load_sar(image: Path, model: Path | None = None) -> LoadedModel:
    """The SAR scene's model (its annotation or gcpfree ``.json`` beside it, or ``model``);
    InputError when what was given is not a SAR scene."""
    loaded = load_model(image, model=model)
    if loaded.family != "sar":
        raise InputError(f"{image} has a {loaded.family} model ({loaded.source}), not a SAR "
                         "one: give a SAR image with its Sentinel-1 annotation beside it or "
                         "named with --sar-model")
    if loaded.image is None:
        raise InputError(f"{image} is a SAR model without its image: give the measurement "
                         "TIFF as --sar and the annotation as --sar-model")
    return loaded


def _read(path: Path) -> np.ndarray:
    with warnings.catch_warnings():  # radar geometry: no georeferencing
        warnings.simplefilter("ignore", NotGeoreferencedWarning)
        with rasterio.open(path) as f:
            return f.read(1)


def _corners(model: LoadedModel, h_m: float) -> tuple[np.ndarray, np.ndarray]:
    n_cols, n_rows = model.size
    c = np.array([0.0, n_cols - 1, 0.0, n_cols - 1])
    r = np.array([0.0, 0.0, n_rows - 1, n_rows - 1])
    return model.model.localize(c, r, np.full(4, h_m))


def _overlap(a: tuple[np.ndarray, np.ndarray], b: tuple[np.ndarray, np.ndarray]) -> float:
    """Share of box ``a`` (lon/lat) that box ``b`` covers."""
    w = min(a[0].max(), b[0].max()) - max(a[0].min(), b[0].min())
    h = min(a[1].max(), b[1].max()) - max(a[1].min(), b[1].min())
    area = (a[0].max() - a[0].min()) * (a[1].max() - a[1].min())
    return max(w, 0.0) * max(h, 0.0) / area if area > 0 else 0.0


def check_overlap(sar: LoadedModel, images: Mapping[str, LoadedModel], h_m: float) -> None:
    """InputError unless the SAR scene covers at least 20 % of each image at height ``h_m``
    (a coarse check: bounding boxes)."""
    try:
        sar_box = _corners(sar, h_m)
    except GeometryError as exc:
        raise InputError(f"the SAR scene {sar.image} does not overlap the pair: its corners "
                         f"do not reach the ground at {h_m:.0f} m ({exc})") from exc
    for name, m in images.items():
        share = _overlap(_corners(m, h_m), sar_box)
        if share < 0.2:
            raise InputError(f"the SAR scene {sar.image} covers {100 * share:.0f} % of the "
                             f"{name} image (20 % needed): it does not overlap the pair")


@dataclass(frozen=True, eq=False)
class ProjectedSurface:
    """A DEM in a projected CRS (the relative DEM, ellipsoidal heights) read at lon/lat
    points through that CRS: :class:`core.orientation.sar_matching.Surface`."""

    grid: SurfaceGrid
    projection: Projection

    def height_m(self, lon_deg: np.ndarray, lat_deg: np.ndarray) -> np.ndarray:
        return self.grid.sample(*self.projection.to_xy(lon_deg, lat_deg))

    def cell_size_m(self) -> float:
        return float(abs(self.grid.dx_m))


def read_surface(path: Path) -> ProjectedSurface:
    """The relative DEM written by the dense step (a north-up projected COG): the optical
    pair's own surface, crowns and roofs included, in the frame of its relative models."""
    with open_raster(path, "relative DEM", "run the relative DEM step first") as src:
        epsg, b = src.crs.to_epsg() if src.crs is not None else None, src.bounds
    if epsg is None:
        raise InputError(f"relative DEM {path} has no EPSG CRS; give the DEM gcpfree wrote")
    grid = read_surface_window(path, (b.left, b.bottom, b.right, b.top), 0,
                               what="relative DEM")
    return ProjectedSurface(grid, Projection(int(epsg)))


def mission_of(sar: LoadedModel) -> str:
    """The SAR model's mission id (``S1A``, ``ERS2``; empty when it does not say)."""
    return str(getattr(sar.model, "mission", ""))


def _image_head(r: SarImageResult) -> dict[str, Any]:
    """What both records say of one image: templates, counts by status, GCPs, and why there
    are none when refused."""
    head: dict[str, Any] = {"templates": int(r.matches.matches.status.size),
                            "counts": r.counts(), "gcps": len(r.gcps)}
    if r.looks != (1, 1):
        head["looks"] = list(r.looks)
    if r.heights is None:
        head["refused"] = r.refused
    return head


@dataclass(frozen=True, eq=False)
class SarControl:
    """The SAR GCPs of both images and the record written (``to_dict``)."""

    sar: LoadedModel
    results: tuple[SarImageResult, ...]
    config: SarGcpConfig
    troposphere_m: float = 0.0

    @property
    def gcps(self) -> tuple[ControlPoint, ...]:
        return tuple(p for r in self.results for p in r.gcps)

    @property
    def mission(self) -> str:
        return mission_of(self.sar)

    def to_dict(self) -> dict[str, Any]:
        images = {}
        for r in self.results:
            m, h = r.matches, r.heights
            ok = np.flatnonzero(m.matches.ok)
            head = {**_image_head(r), "scene_offset_m": [m.offset_cells[1] * m.cell_m,
                                                         -m.offset_cells[0] * m.cell_m]}
            if h is None:
                images[r.name] = head
                continue
            images[r.name] = {
                **head,
                "prediction": None if r.prediction is None else r.prediction.to_dict(),
                "sigma_match_m": h.sigma_match_m, "control_points": int(h.control.sum()),
                "parallax_m_per_m": float(np.median(h.m_per_m)),
                "heights_from_parallax_only": int((~h.from_reference & h.inlier).sum()),
                "points": [{"optical_col": float(m.optical_col[i]),
                            "optical_row": float(m.optical_row[i]),
                            "sar_col": float(m.sar_col[i]), "sar_row": float(m.sar_row[i]),
                            "score": float(m.matches.score[i]),
                            "h_reference_m": float(m.h_ref_m[i]),
                            "h_parallax_m": float(h.h_parallax_m[k]), "h_m": float(h.h_m[k]),
                            "inlier": bool(h.inlier[k]), "control": bool(h.control[k])}
                           for k, i in enumerate(ok)]}
        return {"format": "gcpfree.sar_points", "version": 1,
                "sar_image": str(self.sar.image), "sar_model": str(self.sar.source),
                "mission": self.mission,
                "method": "oriented-gradient (CFOG) matching on a common ground grid, of the "
                          "SAR image and the SAR image predicted from the pair's relative "
                          "DEM (or, without it, the optical image on the reference's "
                          "heights); heights from the SAR-optical parallax calibrated on the "
                          "reference (Goncalves 2002); planimetry from the SAR model",
                "cell_m": self.results[0].matches.cell_m if self.results else None,
                "geolocation_sigma_m": self.config.geolocation_sigma_m,
                "troposphere_m": self.troposphere_m, "images": images}

    def summary(self, srtm_used: bool, models: Mapping[str, Any] | None = None,
                frame: FrameEstimate | None = None,
                used: tuple[ControlPoint, ...] | None = None) -> dict[str, Any]:
        """report.json's ``sar`` section: the scene, the GCPs' role (``with SRTM``, or
        ``alone`` where SRTM surface matching was refused), their ``frame`` as the adjustment
        estimated it (its prior, the shift of the SAR GCPs onto the truth and its sigma:
        :class:`core.orientation.frames.FrameEstimate`), and per image the counts, the
        matching's noise and, given the oriented ``models`` (name -> sensor model) and the SAR
        GCPs ``used`` (default as made), their residuals (measured - projected, px; their
        ground moved by ``frame``'s shift, as the adjustment moved it)."""
        by_image = {r.name: [p for p in (used if used is not None else r.gcps)
                             if r.name in p.image_points] for r in self.results}
        images = {}
        for r in self.results:
            d = _image_head(r)
            if r.heights is not None:
                d["sigma_match_m"] = r.heights.sigma_match_m
            pts = by_image[r.name]
            if models is not None and pts:
                lon, lat, h = (np.array([getattr(p, k) for p in pts])
                               for k in ("lon_deg", "lat_deg", "h_m"))
                if frame is not None:
                    lon, lat, h = shifted_ground(lon, lat, h, frame.shift_m)
                col, row = models[r.name].project(lon, lat, h)
                dc = np.array([p.image_points[r.name].col for p in pts]) - col
                dr = np.array([p.image_points[r.name].row for p in pts]) - row
                d.update(residual_rms_col_px=float(np.sqrt(np.mean(dc**2))),
                         residual_rms_row_px=float(np.sqrt(np.mean(dr**2))),
                         residual_mean_col_px=float(np.mean(dc)),
                         residual_mean_row_px=float(np.mean(dr)))
            images[r.name] = d
        return {"file": FILE, "sar_image": str(self.sar.image),
                "mission": self.mission,
                "geolocation_sigma_m": self.config.geolocation_sigma_m,
                "troposphere_m": self.troposphere_m,
                "role": "with SRTM" if srtm_used else
                        "alone: SRTM surface matching refused (relief verdict or no window)",
                "frame": None if frame is None else frame.to_dict(),
                "images": images}

    def lines(self) -> list[str]:
        return [f"GCPs from SAR {r.name:<6} {len(r.gcps)} of {int(r.matches.matches.status.size)} "
                f"templates ({r.counts()}), " + (
                    f"matching {r.heights.sigma_match_m:.1f} m" if r.heights is not None
                    else f"none: {r.refused}") for r in self.results]


@task(name="sar-ground-control", cache_policy=NO_CACHE)
def sar_ground_control(sar: LoadedModel, images: Mapping[str, LoadedModel], reference: GeoDEM,
                       out: Path | None = None, config: SarGcpConfig | None = None,
                       workers: int | None = None, first_id: int = 1,
                       surface: Path | None = None, troposphere: bool = True) -> SarControl:
    """GCPs of every optical image in ``images`` (name -> model, their images read) from the
    SAR scene ``sar`` (:func:`load_sar`), numbered from ``first_id``; ``surface``: the
    pair's relative DEM (in the frame of ``images``' models), whence the SAR image is
    predicted; ``out``: ``sar_points.json`` written there; ``troposphere``: the standard
    atmosphere's hydrostatic delay taken out of the SAR's range first
    (:mod:`core.sensors.troposphere`)."""
    cfg = config or SarGcpConfig(geolocation_sigma_m=geolocation_sigma_m(mission_of(sar)))
    h_mid = float(np.nanmedian(reference.h_m))
    check_overlap(sar, images, h_mid)
    delay_m = 0.0
    if troposphere:  # the hydrostatic delay a standard atmosphere predicts, out of its timing
        lon, lat = (float(np.mean(v)) for v in _corners(next(iter(images.values())), h_mid))
        model, delay_m = with_standard_troposphere(sar.model, lon, lat, h_mid)
        sar = replace(sar, model=model)
    sar_pixels = _read(sar.image)
    dsm = read_surface(surface) if surface is not None else None
    parts = [dask.delayed(sar_gcps_of_image)(name, m.model, _read(m.image or m.source),
                                             sar.model, sar_pixels, reference,
                                             _corners(m, h_mid), cfg, surface=dsm)
             for name, m in images.items()]
    results, next_id = [], first_id
    for r in compute(parts, workers=workers):  # ids unique across images
        results.append(replace(r, gcps=tuple(replace(p, id=next_id + k)
                                             for k, p in enumerate(r.gcps))))
        next_id += len(r.gcps)
    results = tuple(results)
    result = SarControl(sar, results, cfg, delay_m)
    if out is not None:
        atomic_write_json(out, result.to_dict())
    return result
