"""The scene simulator's folder layout and the DEM its world stands on.

:class:`ScenePaths` says where every product of a simulated scene lives; :func:`check_dem` and
:func:`read_dem_window` read the real DEM (voids filled); :func:`load_surface_spec` builds the
truth-surface definition of a scene once per process. Used by the tasks of
:mod:`tasks.simulate.scene`.
"""

from __future__ import annotations

import threading
import warnings
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np
import rasterio
from rasterio.errors import NotGeoreferencedWarning, WindowError
from rasterio.fill import fillnodata
from rasterio.windows import Window, from_bounds

from core.dem import GeoDEM
from core.errors import CoverageError, InputError
from core.geodesy import BBox
from core.simulation.landcover import LandCoverConfig
from core.simulation.scene import SceneDef, scale_relief
from core.simulation.surface import SurfaceSpec
from tasks.io.geoid import load_geoid
from tasks.io.rasters import open_raster


@dataclass(frozen=True)
class ScenePaths:
    """Where the products of a simulated scene live."""

    root: Path

    @property
    def truth(self) -> Path:
        return self.root / "truth"

    @property
    def work(self) -> Path:
        return self.root / "work"

    @property
    def scene_json(self) -> Path:
        return self.truth / "scene.json"

    @property
    def images(self) -> Path:
        """The folder of the images and their delivered models (a pair's: DIR itself)."""
        return self.root

    def image(self, name: str) -> Path:
        return self.images / f"{name}.tif"

    def delivered(self, name: str) -> Path:
        return self.images / f"{name}.json"

    def dimap(self, name: str) -> Path:
        return self.images / f"{name}.DIM"

    def truth_model(self, name: str) -> Path:
        return self.truth / f"{name}_truth.json"

    def radiance(self, name: str) -> Path:
        return self.work / f"radiance_{name}.tif"

    @property
    def dsm(self) -> Path:
        return self.truth / "dsm.tif"

    @property
    def dtm(self) -> Path:
        return self.truth / "dtm.tif"

    @property
    def landcover(self) -> Path:
        return self.truth / "landcover.tif"

    @property
    def checkpoints(self) -> Path:
        return self.truth / "checkpoints.json"

    @property
    def lidar(self) -> Path:
        return self.truth / "lidar.laz"


# ---------------------------------------------------------------------------- the DEM


def check_dem(path: Path) -> None:
    """Fail early, in one line, on a DEM that cannot serve the simulator."""
    with open_raster(path, "DEM", "give a GeoTIFF (EPSG:4326) or .hgt file") as src:
        crs = src.crs
    if crs is None or not crs.is_geographic:
        raise InputError(
            f"DEM {path} is not in geographic coordinates (CRS {crs}); reproject it to "
            "EPSG:4326 (e.g. gdalwarp -t_srs EPSG:4326)"
        )


def read_dem_window(path: Path, window: BBox | None, datum: str = "egm96"
                    ) -> tuple[np.ndarray, tuple, BBox]:
    """(H float64, geotransform, the box read) of a geographic DEM, voids filled; heights
    orthometric (EGM96), those of an ``ellipsoidal`` DEM converted with ``H = h - N``.

    The simulated world has no holes: SRTM voids (-32768, or the declared nodata) are filled
    by GDAL's inverse-distance fill.
    """
    check_dem(path)
    with rasterio.open(path) as src:
        win = None
        if window is not None:
            win = from_bounds(*window.as_tuple(), transform=src.transform)
            try:
                win = win.round_offsets().round_lengths().intersection(
                    Window(0, 0, src.width, src.height))
            except WindowError:
                b = src.bounds
                raise CoverageError(
                    f"DEM {path} (lon {b.left:.3f}..{b.right:.3f}, lat {b.bottom:.3f}.."
                    f"{b.top:.3f}) does not cover the scene (lon {window.lon_min:.3f}.."
                    f"{window.lon_max:.3f}, lat {window.lat_min:.3f}..{window.lat_max:.3f}); "
                    "give a --center inside the DEM or a DEM around it") from None
        try:
            H = src.read(1, window=win, masked=True).astype(np.float64).filled(np.nan)
        except rasterio.errors.RasterioIOError as exc:
            raise InputError(f"cannot read the heights of DEM {path}: {exc}; the file is "
                             "damaged, give a whole GeoTIFF or .hgt") from None
        tr = src.window_transform(win) if win is not None else src.transform
    H[H <= -1000] = np.nan  # SRTM voids (-32768) when no nodata is declared
    if datum == "ellipsoidal":
        rows, cols = np.mgrid[0:H.shape[0], 0:H.shape[1]]
        H = load_geoid().ellipsoidal_to_orthometric(tr.c + (cols + 0.5) * tr.a,
                                                    tr.f + (rows + 0.5) * tr.e, H)
    voids = np.isnan(H)
    if voids.any() and not voids.all():
        with warnings.catch_warnings():  # GDAL's fill works on an in-memory, unreferenced copy
            warnings.simplefilter("ignore", NotGeoreferencedWarning)
            H = fillnodata(H, mask=(~voids).astype(np.uint8), max_search_distance=max(H.shape),
                           smoothing_iterations=0)
    box = BBox(tr.c, tr.f + tr.e * H.shape[0], tr.c + tr.a * H.shape[1], tr.f)
    return H, tuple(tr)[:6], box


def products_exist(*paths: Path) -> bool:
    """Products of an earlier run of the same scene (written atomically, so complete)."""
    return all(p.exists() for p in paths)


def surface_spec(scene: SceneDef) -> SurfaceSpec:
    """The truth-surface definition of ``scene`` (:func:`load_surface_spec`)."""
    return load_surface_spec(scene.to_json())


_SPEC_LOCK = threading.Lock()


def load_surface_spec(scene_json: str) -> SurfaceSpec:
    """The truth-surface definition of a scene, read once per process even when many Dask
    threads ask for it at once (the DEM fill silences a GDAL warning, which is not thread-safe)."""
    with _SPEC_LOCK:
        return _load_surface_spec(scene_json)


@lru_cache(maxsize=4)
def _load_surface_spec(scene_json: str) -> SurfaceSpec:
    scene = SceneDef.from_json(scene_json)
    H, tr, _ = read_dem_window(Path(scene.dem_path), scene.dem_window, scene.dem_vertical)
    return SurfaceSpec(
        dem_H=GeoDEM.from_transform(scale_relief(H, scene.H_ref_m, scene.relief_factor), tr),
        geoid=load_geoid(),
        seed=scene.seed,
        landcover=LandCoverConfig(water_level_m=scene.water_level_m),
        detail_amplitude_m=3.0 * scene.relief_factor,
        detail_min_wavelength_m=2.0 * scene.preset_spec.truth_res_m,
    )
