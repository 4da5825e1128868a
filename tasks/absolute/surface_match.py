"""Tasks of step 3: windows of the relative DEM around tie points matched to the reference DEM,
turned into simulated GCPs. The maths, from the choice of the windows and their two-pass search
to the GCPs, is :mod:`core.matching.surface`; here the tie points are read, the relative DEM's
cells of each window read (rasterio windows, projected to lon/lat with pyproj), the windows run
on Dask threads and the result written."""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

import dask
import numpy as np
import rasterio
from prefect import task
from prefect.cache_policies import NO_CACHE
from rasterio.windows import Window

from core.dem import GeoDEM
from core.matching.relief import ReliefVerdict, relief_sufficiency
from core.matching.surface import (
    SurfaceMatchConfig,
    WindowMatch,
    choose_windows,
    first_pass_mask,
    gcps_from_windows,
    match_window,
    search_windows,
)
from core.matching.surface_file import WindowsFile
from core.points import ControlPoint
from core.sensors.base import SensorModel
from tasks.io.crs import Projection
from tasks.io.products import WINDOWS
from tasks.io.rasters import read_json
from tasks.scheduling import compute


@dataclass(frozen=True, eq=False)
class TieGround:
    """Tie points with their relative ground coordinates (the relative orientation's frame) and
    their positions in both images."""

    lon_deg: np.ndarray
    lat_deg: np.ndarray
    h_m: np.ndarray
    left_col: np.ndarray
    left_row: np.ndarray
    right_col: np.ndarray
    right_row: np.ndarray
    score: np.ndarray

    @classmethod
    def from_tiepoints_json(cls, path: str | Path) -> TieGround:
        """The inlier tie points of a ``rel.tiepoints.json``."""
        doc = read_json(path, "tie-point file")
        g, tp = doc["relative_ground"], doc["tie_points"]
        idx = np.asarray(g["index"], dtype=np.int64)
        inl = np.asarray(g["inlier"], dtype=bool)

        def col(name: str) -> np.ndarray:
            return np.array([np.nan if v is None else v for v in tp[name]], dtype=float)[idx][inl]

        return cls(np.asarray(g["lon_deg"])[inl], np.asarray(g["lat_deg"])[inl],
                   np.asarray(g["h_m"])[inl], col("left_col"), col("left_row"),
                   col("right_col"), col("right_row"), col("correlation"))


def read_window_cells(dem_path: str, lon: float, lat: float, radius_m: float
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The relative DEM's cells within ``radius_m`` of (lon, lat): their lon, lat and height
    (NaN where the DEM has none)."""
    with rasterio.open(dem_path) as src:
        proj = Projection(src.crs.to_epsg())
        x, y = proj.to_xy(np.array([lon]), np.array([lat]))
        t = src.transform
        c0 = int(np.floor((x[0] - radius_m - t.c) / t.a))
        c1 = int(np.ceil((x[0] + radius_m - t.c) / t.a))
        r0 = int(np.floor((t.f - y[0] - radius_m) / -t.e))
        r1 = int(np.ceil((t.f - y[0] + radius_m) / -t.e))
        z = src.read(1, window=Window(c0, r0, c1 - c0, r1 - r0), boundless=True,
                     fill_value=np.nan, masked=True).astype(np.float64).filled(np.nan)
    cols = t.c + (np.arange(c0, c1) + 0.5) * t.a
    rows = t.f + (np.arange(r0, r1) + 0.5) * t.e
    xx, yy = np.meshgrid(cols, rows)
    clon, clat = proj.to_lonlat(xx.ravel(), yy.ravel())
    return clon, clat, z.ravel()


def match_one(dem_path: str, lon: float, lat: float, reference: GeoDEM,
              cfg: SurfaceMatchConfig, prior: tuple[float, float, float] | None = None
              ) -> WindowMatch:
    """One window: read its cells, match them (per-window function of the Dask graph)."""
    clon, clat, h = read_window_cells(dem_path, lon, lat, cfg.radius_m)
    return match_window(clon, clat, h, (lon, lat), reference, cfg, prior)


def _match_all(dem_path: Path, ties: TieGround, idx: np.ndarray, reference: GeoDEM,
               cfg: SurfaceMatchConfig, priors: np.ndarray | None = None,
               progress: bool = False, workers: int | None = None) -> list[WindowMatch]:
    parts = [dask.delayed(match_one)(str(dem_path), float(ties.lon_deg[i]),
                                     float(ties.lat_deg[i]), reference, cfg,
                                     None if priors is None else tuple(map(float, priors[k])))
             for k, i in enumerate(idx)]
    return compute(parts, progress=progress, workers=workers)


@dataclass(frozen=True, eq=False)
class SurfaceMatchResult:
    """The windows tried (centre tie point index and match) and the GCPs made from the good
    ones."""

    centres: np.ndarray
    matches: tuple[WindowMatch, ...]
    gcps: tuple[ControlPoint, ...]

    def verdict(self, cfg: SurfaceMatchConfig, min_windows: int, cell_m: float
                ) -> ReliefVerdict:
        """Whether enough windows have the relief to match (``cell_m``: the reference's cell
        size), :func:`core.matching.relief.relief_sufficiency`."""
        return relief_sufficiency(self.matches, cfg, min_windows, cell_m)

    def counts(self) -> dict[str, int]:
        out: dict[str, int] = {}
        for m in self.matches:
            out[m.status.name] = out.get(m.status.name, 0) + 1
        return out

    def document(self) -> WindowsFile:
        """What windows.json holds (:data:`tasks.io.products.WINDOWS`)."""
        return WindowsFile.of(self.centres, self.matches, self.gcps)


@task(name="surface-match", cache_policy=NO_CACHE)
def match_surfaces(dem_path: Path, ties: TieGround, reference: GeoDEM,
                   cfg: SurfaceMatchConfig = SurfaceMatchConfig(), spacing_m: float | None = None,
                   names: tuple[str, str] = ("left", "right"),
                   out: Path | None = None, progress: bool = False,
                   workers: int | None = None,
                   models: tuple[SensorModel, SensorModel] | None = None) -> SurfaceMatchResult:
    """Match a window around each chosen tie point (``spacing_m`` apart, default the window
    radius) and make a GCP of each good one: the relative point its shift holds at moved by the
    window's 3-D shift, where ``models`` (the relative orientation's, the images ``names``)
    see that point, with the window's precision; without ``models``, the window's centre tie
    point where it was measured. ``progress``: a progress bar over the windows on stderr;
    ``workers``: the threads that match them (default one per core)."""
    centres = choose_windows(ties.lon_deg, ties.lat_deg, ties.h_m, ties.score,
                             spacing_m or cfg.radius_m)
    if progress:
        print(f"surface matching: {len(centres)} windows "
              f"({int(first_pass_mask(len(centres)).sum())} searched over the whole range "
              "first)", file=sys.stderr, flush=True)

    def match(k: np.ndarray, priors: np.ndarray | None) -> list[WindowMatch]:
        return _match_all(dem_path, ties, centres[k], reference, cfg, priors, progress, workers)

    matches = tuple(search_windows(ties.lon_deg[centres], ties.lat_deg[centres], match))

    def locate(lon: float, lat: float, h: float) -> dict[str, tuple[float, float]]:
        seen = [m.project(np.array([lon]), np.array([lat]), np.array([h])) for m in models]
        return {n: (float(c[0]), float(r[0])) for n, (c, r) in zip(names, seen, strict=True)}

    gcps = gcps_from_windows(centres, matches, ties.lon_deg, ties.lat_deg, ties.h_m,
                             {names[0]: (ties.left_col, ties.left_row),
                              names[1]: (ties.right_col, ties.right_row)},
                             None if models is None else locate)
    result = SurfaceMatchResult(centres, matches, gcps)
    if out is not None:
        WINDOWS.write(out, result.document())
    return result
