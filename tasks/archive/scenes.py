"""The scenes of an archive folder, each read from its own model: what ``gcpfree scenes`` finds
before it proposes pairs and blocks (:mod:`tasks.archive.stereo`).

- **Which files are scenes.** Every image (``.tif``, ``.tiff``, ``.jp2``) under the folder is
  one scene, whatever model files sit beside it: its model is the one
  :func:`tasks.io.sensors.load_model` finds (a SPOT ``METADATA.DIM`` or ``.DIM``, a gcpfree
  ``.json``, an RPC ``.geom``, a DIMAP v2 ``RPC_*.XML``, the GeoTIFF's RPC tags). Hidden
  folders, and the ``truth/`` and ``work/`` folders of a simulated scene (a folder holding
  ``truth/scene.json``), are not searched. A model file (``.DIM``, ``.geom``, ``RPC_*.XML``)
  that no image claims is reported as a scene without its image.
- **Bad scenes** are never dropped: an image that cannot be read, has no model, has a
  malformed one, is a SAR scene (not an optical stereo image) or that the reference does not
  cover is a :class:`Rejection` with its one-line reason.
- **Heights.** A footprint is the ground of the image's corner pixels at the scene's height:
  the mean terrain height under the image from the reference DEM (``--reference``, its datum
  by the one rule) or from the DEM tiles of ``--dem-dir``/``--srtm-dir`` (SRTM, NASADEM,
  Copernicus, tagged DEMs: their datum by the one rule, converted through ``--geoid`` or the
  grid the rule names),
  found by :func:`core.sensors.viewing.footprint_mean_height_m` over the box that
  :func:`core.sensors.footprint.footprint_box` gives for the heights the model may see;
  without either, the model's own mean height (an RPC's height offset; 0 for a SPOT
  ``.DIM``, whose corners are stated at h = 0, and for any other rigorous model).
- **Figures** at the image centre at that height (:func:`core.sensors.viewing.scene_geometry`):
  incidence, across-track incidence, the sensor's azimuth, ground sample distance, the
  along-track heading (:func:`core.sensors.viewing.along_track_heading_deg`); the acquisition
  (:func:`tasks.io.acquisition.acquisition_of`), the sun (the metadata's) and the band family.

Plain functions, no Prefect: reading the metadata of a folder of scenes takes seconds.
"""

from __future__ import annotations

import os
import re
import tempfile
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rasterio.errors import NotGeoreferencedWarning

from core.dem import GeoDEM
from core.errors import GcpFreeError, InputError
from core.heights import DatumDecision
from core.sensors.footprint import footprint_box, scene_height_range_m, stated_height_range_m
from core.sensors.viewing import (
    along_track_heading_deg,
    footprint_mean_height_m,
    scene_geometry,
)
from tasks.io.acquisition import Acquisition, acquisition_of
from tasks.io.dem import check_reference, dem_datum, read_reference, tile_datum
from tasks.io.dem_tiles import DemSource, build_vrt, find_tiles, mosaic_grid
from tasks.io.rasters import open_raster
from tasks.io.reference import reference_geoid
from tasks.io.sensors import LoadedModel, load_model, model_beside

IMAGE_SUFFIXES = (".tif", ".tiff", ".jp2")
#: model files that describe one scene on their own (a gcpfree .json may be any product)
_MODEL_ALONE = re.compile(r"(.+\.dim|.+\.geom|rpc_.+\.xml)", re.IGNORECASE)
#: the folders of a simulated scene (beside truth/scene.json) that hold no scene
SIMULATOR_FOLDERS = ("truth", "work")
_ID_CHARS = re.compile(r"[^A-Za-z0-9._-]+")
#: SPOT 1-5 SENSOR_CODE first letters: P (HRV/HRVIR panchromatic), M (HRVIR mono-band B2, the
#: 10 m band of SPOT 4), A and B (HRG 5 m), T (HRG supermode 2.5 m), H (HRS) are one-band
#: panchromatic-like images; X (HRV XS), I (HRVIR XI), J (HRG multispectral) are not
_SPOT_PAN, _SPOT_MS = "PMABTH", "XIJ"


@dataclass(frozen=True)
class Rejection:
    """A file of the folder that is not a usable scene, and why (one line)."""

    path: Path
    reason: str


@dataclass(frozen=True, eq=False)
class Scene:
    """One scene: its image and model, footprint and figures (degrees, metres, UTC).

    ``model`` is None when the model is the image's own RPC tags. ``footprint`` is the ground
    (lon, lat) of the corner pixels (0, 0), (cols-1, 0), (cols-1, rows-1), (0, rows-1) at
    ``h_m``, the height ``height_source`` names; ``incidence_deg`` ... ``gsd_m`` are taken at
    the centre pixel at ``h_m`` (``gsd_m`` the mean of the across and along GSD);
    ``heading_deg`` is the along-track heading there; ``sun_deg`` (azimuth, elevation) as the
    metadata state it.
    """

    id: str
    image: Path
    model: Path | None
    loaded: LoadedModel
    family: str
    band_family: str
    acquisition: Acquisition
    h_m: float
    height_source: str
    footprint: tuple[tuple[float, float], ...]
    area_km2: float
    centre_lon_deg: float
    centre_lat_deg: float
    incidence_deg: float
    across_track_incidence_deg: float
    sensor_azimuth_deg: float
    heading_deg: float
    gsd_m: float
    sun_deg: tuple[float, float] | None = None

    @property
    def size(self) -> tuple[int, int]:
        return self.loaded.size

    @property
    def bbox(self) -> tuple[float, float, float, float]:
        lons, lats = [p[0] for p in self.footprint], [p[1] for p in self.footprint]
        return min(lons), min(lats), max(lons), max(lats)

    def to_dict(self, rel: Any = str) -> dict[str, Any]:
        """JSON values; ``rel`` turns a path into the string written (e.g. relative)."""
        a = self.acquisition
        return {
            "id": self.id, "image": rel(self.image),
            "model": None if self.model is None else rel(self.model),
            "family": self.family, "band_family": self.band_family,
            "size": {"cols": self.size[0], "rows": self.size[1]},
            "satellite": a.satellite, "instrument": a.instrument, "acquired_utc": a.utc,
            "acquired_source": a.source,
            "h_m": self.h_m, "height_source": self.height_source,
            "footprint": [list(p) for p in self.footprint], "area_km2": self.area_km2,
            "centre": {"lon_deg": self.centre_lon_deg, "lat_deg": self.centre_lat_deg},
            "incidence_deg": self.incidence_deg,
            "across_track_incidence_deg": self.across_track_incidence_deg,
            "sensor_azimuth_deg": self.sensor_azimuth_deg, "heading_deg": self.heading_deg,
            "gsd_m": self.gsd_m,
            "sun": None if self.sun_deg is None else {"azimuth_deg": self.sun_deg[0],
                                                      "elevation_deg": self.sun_deg[1]},
        }


# ---------------------------------------------------------------------------- the files


@dataclass(frozen=True)
class SceneFiles:
    """The images under a folder (sorted) and the model files no image claims."""

    images: tuple[Path, ...]
    models_alone: tuple[Path, ...]


def _is_simulated(folder: Path) -> bool:
    return (folder / "truth" / "scene.json").is_file()


def find_scene_files(root: str | Path) -> SceneFiles:
    """Every image under ``root`` and every model file (``.DIM``, ``.geom``, ``RPC_*.XML``)
    that is neither the model :func:`tasks.io.sensors.model_beside` finds for an image of its
    folder nor of an image's name. See the module docstring for the folders not searched.

    Raises:
        InputError: ``root`` is not a folder.
    """
    root = Path(root)
    if not root.is_dir():
        raise InputError(f"{root} is not a folder; give the folder holding the scenes")
    images: list[Path] = []
    alone: list[Path] = []
    seen: set[str] = set()  # folders linked twice (or into themselves) are read once
    for here, dirs, files in os.walk(root, followlinks=True):
        folder = Path(here)
        real = os.path.realpath(folder)
        if real in seen:
            dirs[:] = []
            continue
        seen.add(real)
        skip = set(SIMULATOR_FOLDERS) if _is_simulated(folder) else set()
        dirs[:] = sorted(d for d in dirs if not d.startswith(".") and d not in skip)
        found = sorted(folder / f for f in files if not f.startswith("."))
        imgs = [f for f in found if f.suffix.lower() in IMAGE_SUFFIXES]
        claimed = {model_beside(i).name for i in imgs} | {i.stem.lower() for i in imgs}
        images += imgs
        alone += [f for f in found if _MODEL_ALONE.fullmatch(f.name)
                  and f.name not in claimed and f.stem.lower() not in claimed]
    return SceneFiles(tuple(images), tuple(alone))


def scene_ids(images: tuple[Path, ...], root: Path) -> dict[Path, str]:
    """A unique id per image (an output folder name): its name without suffix (its folder's
    name for a SPOT ``IMAGERY.TIF``), else its path under ``root`` joined by ``_``."""
    def clean(text: str) -> str:
        text = _ID_CHARS.sub("_", text).lstrip(".-")
        return text or "scene"

    def short(p: Path) -> str:
        return clean(p.parent.name if p.stem.upper() == "IMAGERY" and p.parent != root
                     else p.stem)

    counts: dict[str, int] = {}
    for p in images:
        counts[short(p)] = counts.get(short(p), 0) + 1
    ids: dict[Path, str] = {}
    used: set[str] = set()
    for p in images:
        name = short(p)
        if counts[name] > 1:
            name = clean("_".join(p.relative_to(root).with_suffix("").parts))
        base, n = name, 2
        while name in used:
            name, n = f"{base}-{n}", n + 1
        used.add(name)
        ids[p] = name
    return ids


# ---------------------------------------------------------------------------- heights


@dataclass
class GroundHeights:
    """Where the scenes' heights come from: a reference DEM (its datum decided once by the
    one rule), DEM tiles (``dem_dir``: a folder of SRTM, NASADEM or Copernicus tiles, or of
    tagged DEMs, as ``--dem-dir``/``--srtm-dir`` take it; a reference given with a ``geoid``
    is read the same way, as :class:`tasks.io.pair.PairInputs` does), or neither (each
    model's own mean height)."""

    reference: Path | None = None
    reference_vertical: str = "auto"
    dem_dir: Path | None = None
    geoid: Path | None = None
    _datum: DatumDecision | None = field(default=None, repr=False)
    _tiles: str | None = field(default=None, repr=False)
    product: str = field(default="DEM", repr=False)  # the last tiles' product name

    def __post_init__(self) -> None:
        if self.reference is not None and self.dem_dir is not None:
            raise InputError("give the reference DEM (--reference) or the DEM tiles "
                             "(--dem-dir, --srtm-dir), not both")
        if self.reference is not None and self.geoid is not None:
            self.dem_dir, self.reference = Path(self.reference), None  # through the geoid
        if self.reference is not None:
            self.reference = Path(self.reference)
            check_reference(self.reference)
            self._datum = dem_datum(self.reference, self.reference_vertical)
        if self.dem_dir is not None:
            self.dem_dir = Path(self.dem_dir)
            if not self.dem_dir.exists():
                raise InputError(f"DEM folder {self.dem_dir} does not exist; give --dem-dir a "
                                 "folder of tiles")

    @property
    def given(self) -> bool:
        return self.reference is not None or self.dem_dir is not None

    def describe(self) -> str:
        if self.reference is not None and self._datum is not None:
            return f"{self.reference}: {self._datum.describe()}"
        if self.dem_dir is not None:
            return f"the DEM tiles of {self.dem_dir}" + (f" ({self._tiles})" if self._tiles
                                                         else "")
        return ("none: each footprint at its model's own mean height (an RPC's height offset, "
                "else 0)")

    def dem(self, loaded: LoadedModel) -> GeoDEM | None:
        """The ellipsoidal heights under the scene's footprint (None without a source).

        Raises:
            CoverageError: the reference or the tiles do not reach the footprint.
            InputError: the tiles' datum cannot be told (the one rule).
        """
        box = footprint_box([(loaded.model, (0, 0, *loaded.size))],
                            scene_height_range_m([loaded.model]))
        if self.reference is not None and self._datum is not None:
            return read_reference(self.reference, box, self._datum.datum)
        if self.dem_dir is None:
            return None
        source = DemSource(self.dem_dir, self.reference_vertical, self.geoid)
        tiles = tile_datum(find_tiles(source, box, allow_missing=True))
        self._tiles, self.product = tiles.describe(), tiles.product.name
        with tempfile.TemporaryDirectory(prefix="gcpfree-scenes-") as tmp:
            vrt = Path(tmp) / "tiles.vrt"
            vrt.write_text(build_vrt(tiles, mosaic_grid(tiles, box)))
            stored = read_reference(vrt, box, "ellipsoidal")  # the tiles' heights as stored
        geoid = reference_geoid(tiles.datum, box)  # type: ignore[arg-type]
        if geoid is None:
            return stored
        lon, lat = stored.nodes()
        return stored.with_values(geoid.orthometric_to_ellipsoidal(lon, lat, stored.h_m))


def own_height_m(loaded: LoadedModel) -> tuple[float, str]:
    """The model's own mean height: the middle of the heights it states (an RPC's offset),
    else 0 (a rigorous model states none; a SPOT ``.DIM`` states its corners at h = 0)."""
    stated = stated_height_range_m(loaded.model)
    if stated is not None:
        return 0.5 * (stated[0] + stated[1]), "the RPC's height offset"
    return 0.0, "the ellipsoid (the model states no height)"


def scene_height_m(loaded: LoadedModel, ground: GroundHeights) -> tuple[float, str]:
    """The height of the scene's footprint and what gave it (see the module docstring)."""
    h0, why = own_height_m(loaded)
    dem = ground.dem(loaded)
    if dem is None:
        return h0, why
    terrain = footprint_mean_height_m(loaded.model, *loaded.size, dem, h0_m=h0)
    what = "the reference's" if ground.reference is not None else f"the {ground.product} tiles'"
    return terrain.mean_h_m, (f"{what} mean height under the footprint "
                              f"({terrain.covered_pct:.0f} % of it covered)")


# ---------------------------------------------------------------------------- one scene


def band_family(loaded: LoadedModel) -> str:
    """``panchromatic`` or ``multispectral``: from a SPOT product's SENSOR_CODE, else from
    its bands (one band: panchromatic)."""
    spot = loaded.spot
    if spot is not None and spot.sensor_code:
        code = spot.sensor_code.strip().upper()[:1]
        if code in _SPOT_PAN:
            return "panchromatic"
        if code in _SPOT_MS:
            return "multispectral"
    if loaded.image is None:
        n = 1 if spot is None else len(spot.bands)
    else:
        with open_raster(loaded.image, "image") as src:
            n = src.count
    return "panchromatic" if n == 1 else "multispectral"


def read_scene(image: Path, scene_id: str, ground: GroundHeights) -> Scene:
    """The scene of one image: its model found beside it, its height, footprint and figures.

    Raises:
        GcpFreeError: the image or its model cannot be read, the model is a SAR one, or the
            heights do not cover it.
    """
    with warnings.catch_warnings():  # raw sensor images have no CRS, by nature
        warnings.simplefilter("ignore", NotGeoreferencedWarning)
        loaded = load_model(image)
        if loaded.family == "sar":
            raise InputError("a SAR scene, not an optical stereo image; give it to gcpfree "
                             "orient or pair as --sar")
        h_m, why = scene_height_m(loaded, ground)
        g = scene_geometry(loaded.model, *loaded.size, h_m)
        heading = float(along_track_heading_deg(loaded.model, g.centre_col, g.centre_row, h_m))
        family = band_family(loaded)
    same = loaded.source.resolve() == Path(image).resolve()
    return Scene(
        id=scene_id, image=Path(image), model=None if same else loaded.source, loaded=loaded,
        family=loaded.family, band_family=family, acquisition=acquisition_of(loaded), h_m=h_m,
        height_source=why, footprint=tuple((c.lon_deg, c.lat_deg) for c in g.corners),
        area_km2=g.area_km2, centre_lon_deg=g.centre_lon_deg, centre_lat_deg=g.centre_lat_deg,
        incidence_deg=g.incidence_deg, across_track_incidence_deg=g.across_track_incidence_deg,
        sensor_azimuth_deg=g.azimuth_deg, heading_deg=heading,
        gsd_m=0.5 * (g.gsd_across_m + g.gsd_along_m), sun_deg=loaded.sun)


def _reason(exc: BaseException) -> str:
    text = next((s.strip() for s in str(exc).splitlines() if s.strip()), "")
    if isinstance(exc, GcpFreeError):
        return text or type(exc).__name__
    return f"unreadable ({type(exc).__name__}: {text})" if text else \
        f"unreadable ({type(exc).__name__})"


def read_scenes(root: str | Path, ground: GroundHeights
                ) -> tuple[tuple[Scene, ...], tuple[Rejection, ...]]:
    """Every scene under ``root`` (sorted by path), and the files that are not usable scenes
    with their reasons (model files without an image included).

    Raises:
        InputError: ``root`` is not a folder, or holds no image and no model file.
    """
    root = Path(root)
    files = find_scene_files(root)
    if not files.images and not files.models_alone:
        raise InputError(f"no scene image under {root} (.tif, .tiff or .jp2, each with its "
                         "model: .DIM, .json, .geom, RPC_*.XML beside it or RPC tags)")
    ids = scene_ids(files.images, root)
    scenes: list[Scene] = []
    rejected: list[Rejection] = []
    for image in files.images:
        try:
            scenes.append(read_scene(image, ids[image], ground))
        except Exception as exc:  # noqa: BLE001 - every bad scene is listed, never dropped
            rejected.append(Rejection(image, _reason(exc)))
    for model in files.models_alone:
        rejected.append(Rejection(model, "a sensor model without its image: put the image "
                                         "beside it (IMAGERY.TIF beside a SPOT METADATA.DIM, "
                                         "the image of the same name beside a .DIM or .geom)"))
    return tuple(scenes), tuple(rejected)
