"""Read sensor models from files: RPCs (OSSIM ``.geom``, GeoTIFF RPC tags, DIMAP v2 RPC XML),
SPOT Level 1A ``METADATA.DIM``, Sentinel-1 annotation XML (a SAR model, recognised by content)
and gcpfree JSON; find the model of an image (:func:`load_model`).

Where each source's pixel coordinates start, and how :func:`load_model` brings them to the
raster's own pixels (0-based, pixel centres at integers), whichever way the model is named
(found beside the image, ``--left-model``/``--model``, a catalog's ``left_model`` column):

- ``.geom``, DIMAP v2 RPC XML, SPOT ``.DIM``, Sentinel-1 annotations and gcpfree pushbroom and
  SAR ``.json`` files describe the *whole* product image. A crop that stores its position as a pure pixel-offset geotransform
  (no CRS, unit pixel size, origin ``(c, f)``: what rasterio's ``window_transform`` writes for a
  raster with no georeferencing) has its pixel ``(0, 0)`` at product pixel ``(c, f)``: the
  half-pixel shifts of the corner-based geotransform cancel, so the model is moved by exactly
  ``(c, f)`` (:meth:`RPCModel.with_image_offset`, :meth:`PushbroomModel.with_image_window`,
  :meth:`SarModel.with_image_window`). The Ventoux crops carry origins such as (5000, 5000). A
  pushbroom or SAR model of the raster's own size is the raster's (a gcpfree model written for
  a crop).
- RPC tags inside a raster (GDAL RPC metadata domain) describe that raster's pixels (GDAL's RPC
  transformer ignores the geotransform, and GDAL rewrites the tags when it crops), so no offset
  is applied to an image's own tags; another GeoTIFF's tags named as the model are moved by the
  difference of the two rasters' pixel offsets. A gcpfree RPC ``.json`` is in the pixels of the
  raster it was written for.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from core.errors import InputError
from core.jsonio import parse_json
from core.sensors.base import SensorModel
from core.sensors.pushbroom import PushbroomModel
from core.sensors.rpc import RPCModel
from core.sensors.sar import SarModel
from core.sensors.sentinel1 import Annotation
from core.sensors.spot import SpotScene, spot_pushbroom
from tasks.io.dimap import dimap_beside, read_dimap
from tasks.io.model_files import SUN_KEY, family_of, read_model_document
from tasks.io.rasters import open_raster
from tasks.io.sentinel1 import annotation_beside, is_annotation_file, read_annotation


def _read_text(path: Path, what: str) -> str:
    try:
        return path.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise InputError(f"cannot read {what} {path}: {exc.strerror}; check the path") from exc


def _rpc_from_file(path: str | Path, what: str, parse: Callable[[str], RPCModel]) -> RPCModel:
    path = Path(path)
    try:
        return parse(_read_text(path, what))
    except InputError as exc:
        raise InputError(f"{path}: {exc}") from exc


def rpc_from_geom_file(path: str | Path) -> RPCModel:
    """RPC from an OSSIM keyword-list file (``.geom``), in the full image's pixels."""
    return _rpc_from_file(path, "RPC .geom file", RPCModel.from_geom)


def rpc_from_dimap_file(path: str | Path) -> RPCModel:
    """RPC from a Pleiades / SPOT 6-7 DIMAP v2 RPC XML file, in the full image's 0-based pixels."""
    return _rpc_from_file(path, "DIMAP RPC file", RPCModel.from_dimap_xml)


def pixel_offset_of(transform: tuple[float, ...] | object, has_crs: bool) -> tuple[float, float]:
    """Full-image pixel ``(col0, row0)`` of a crop's pixel (0, 0) read from its geotransform.

    ``transform`` is an ``affine.Affine`` (a, b, c, d, e, f). Returns (0, 0) for an identity
    transform; ``(c, f)`` for a pure pixel offset (a = e = 1, b = d = 0, no CRS). Raises
    InputError for any other transform without a CRS (the crop position cannot be told).
    A raster with a CRS is map-projected: its geotransform says nothing about sensor pixels,
    so (0, 0) is returned.
    """
    a, b, c, d, e, f = (float(v) for v in tuple(transform)[:6])  # type: ignore[arg-type]
    if has_crs:
        return 0.0, 0.0
    if (a, b, d, e) == (1.0, 0.0, 0.0, 1.0):
        return c, f
    raise InputError(
        f"the raster has no CRS and a geotransform {(a, b, c, d, e, f)} that is not a pure pixel "
        "offset; a model of the whole product (.geom, DIMAP, .DIM) cannot be placed on it. Give "
        "the uncropped image or a crop written with a unit-pixel offset geotransform"
    )


def _open_raster(path: Path) -> tuple[tuple[int, int], object, bool, dict[str, str]]:
    """(width, height), geotransform, whether it has a CRS, and the RPC tags of a raster."""
    with open_raster(path, "image") as src:
        return (src.width, src.height), src.transform, src.crs is not None, src.tags(ns="RPC")


def read_rpc_tags(image_path: str | Path) -> RPCModel:
    """The RPC in a raster's own GDAL RPC metadata domain (ignoring any .geom beside it)."""
    image_path = Path(image_path)
    tags = _open_raster(image_path)[3]
    if not tags:
        raise InputError(f"{image_path} holds no RPC tags; give its model file instead")
    try:
        return RPCModel.from_gdal_tags(tags)
    except InputError as exc:
        raise InputError(f"{image_path} RPC tags: {exc}") from exc


def read_rpc(image_path: str | Path, model_file: str | Path | None = None) -> RPCModel:
    """The RPC model of a raster, in that raster's pixels (0-based, centres at integers):
    :func:`load_model` for an RPC (``model_file`` an OSSIM ``.geom``, a DIMAP v2 RPC XML, a
    gcpfree RPC ``.json`` or a GeoTIFF with RPC tags; default: found beside the image).

    Raises:
        InputError: the image cannot be opened, no RPC is found, or the RPC is malformed.
    """
    loaded = load_model(image_path, model=model_file)
    if not isinstance(loaded.model, RPCModel):
        raise InputError(f"the model of {image_path} ({loaded.source}) is not an RPC")
    return loaded.model


# ---------------------------------------------------------------------------- any sensor model

MODEL_SUFFIXES = (".dim", ".json", ".geom", ".xml")
TIFF_SUFFIXES = (".tif", ".tiff")


@dataclass(frozen=True, eq=False)
class LoadedModel:
    """A sensor model found for an image or read from a model file, and where it came from.

    ``family`` is ``"pushbroom"``, ``"rpc"`` or ``"sar"``; ``source`` the file the model was
    read from;
    ``image`` the raster when one was given or found; ``size`` (cols, rows) of the image the
    model describes; ``spot`` the SPOT metadata when the model came from a ``METADATA.DIM``;
    ``band`` the band whose look angles were used; ``crop`` the pixel (col, row) of the model
    file's image at the raster's pixel (0, 0) (``(0, 0)`` when the file describes the raster
    itself); ``sar`` the Sentinel-1 annotation (model and geolocation grid) of a SAR model;
    ``sun_deg`` the sun (azimuth, elevation; degrees) a gcpfree model file carries from the
    metadata it was made from (``gcpfree orient``'s ``left.json``), see :attr:`sun`.
    """

    model: SensorModel
    family: str
    source: Path
    image: Path | None
    size: tuple[int, int]
    spot: SpotScene | None = None
    band: int | None = None
    crop: tuple[float, float] = (0.0, 0.0)
    sar: Annotation | None = None
    sun_deg: tuple[float, float] | None = None

    @property
    def sun(self) -> tuple[float, float] | None:
        """The sun at imaging (azimuth, elevation; degrees) the metadata state: a SPOT
        ``.DIM``'s, or the one a gcpfree model file carries; None for other models."""
        s = self.spot
        if s is not None and s.sun_azimuth_deg is not None and s.sun_elevation_deg is not None:
            return s.sun_azimuth_deg, s.sun_elevation_deg
        return self.sun_deg


@dataclass(frozen=True, eq=False)
class FileModel:
    """A model as its file gives it, before it is placed on a raster.

    ``frame`` says whose pixels the file's coordinates are: ``"product"`` (the whole vendor
    image: ``.geom``, DIMAP v2 RPC XML, SPOT ``.DIM``, a Sentinel-1 annotation, a pushbroom or
    SAR ``.json``, which knows its image's size) or ``"raster"`` (the raster the file was written for: GeoTIFF RPC tags, a
    gcpfree RPC ``.json``); ``size`` the image size the file states (None for an RPC file);
    ``raster_offset`` a GeoTIFF model's own crop offset; ``sun_deg`` a gcpfree model file's
    ``sun`` (:data:`SUN_KEY`).
    """

    model: SensorModel
    family: str
    path: Path
    frame: str
    size: tuple[int, int] | None = None
    spot: SpotScene | None = None
    band: int | None = None
    raster_offset: tuple[float, float] = (0.0, 0.0)
    sar: Annotation | None = None
    sun_deg: tuple[float, float] | None = None


def sun_to_dict(sun: tuple[float, float] | None) -> dict[str, dict[str, float]]:
    """``{SUN_KEY: ...}`` to add to a model file's dict (the sun of the metadata it was made
    from, which chooses the tie points' measure), or nothing when there is no sun; a model
    file with its sun is :func:`tasks.io.model_files.model_document`."""
    if sun is None:
        return {}
    return {SUN_KEY: {"azimuth_deg": float(sun[0]), "elevation_deg": float(sun[1])}}


def _from_dimap(path: Path, band: int | None) -> FileModel:
    scene = read_dimap(path)
    return FileModel(spot_pushbroom(scene, band), "pushbroom", path, "product",
                      (scene.n_cols, scene.n_rows), scene, scene.look(band).band_index)


def _from_json(path: Path) -> FileModel:
    """A gcpfree model file (:mod:`tasks.io.model_files`)."""
    d = parse_json(_read_text(path, "model JSON file"), str(path))
    family = family_of(d)
    model, sun = read_model_document(d, str(path))
    if family == "rpc":
        return FileModel(model, "rpc", path, "raster")
    size = (model.n_cols, model.n_rows)  # type: ignore[union-attr]
    return FileModel(model, family, path, "product", size, sun_deg=sun)


def _from_tiff(path: Path) -> FileModel:
    _, transform, has_crs, tags = _open_raster(path)
    if not tags:
        raise InputError(f"{path} holds no RPC tags; give its model file instead")
    try:
        model = RPCModel.from_gdal_tags(tags)
    except InputError as exc:
        raise InputError(f"{path} RPC tags: {exc}") from exc
    try:
        offset = pixel_offset_of(transform, has_crs)
    except InputError:  # its tags describe its pixels whatever its geotransform
        offset = (0.0, 0.0)
    return FileModel(model, "rpc", path, "raster", raster_offset=offset)


def read_model_file(path: str | Path, band: int | None = None) -> FileModel:
    """A model file read as it is, in its own pixels; the format from its suffix."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"model file {path} does not exist; check the path")
    suffix = path.suffix.lower()
    if suffix == ".dim":
        return _from_dimap(path, band)
    if suffix == ".json":
        return _from_json(path)
    if suffix == ".geom":
        return FileModel(rpc_from_geom_file(path), "rpc", path, "product")
    if suffix == ".xml":
        if is_annotation_file(path):  # recognised by content: a Sentinel-1 annotation
            ann = read_annotation(path)
            return FileModel(ann.model, "sar", path, "product",
                             (ann.model.n_cols, ann.model.n_rows), sar=ann)
        return FileModel(rpc_from_dimap_file(path), "rpc", path, "product")
    if suffix in TIFF_SUFFIXES:
        return _from_tiff(path)
    raise InputError(f"{path}: unknown model format; give a .DIM (SPOT), a gcpfree .json, "
                     "an OSSIM .geom, a DIMAP v2 RPC .XML, a Sentinel-1 annotation .xml or a "
                     "GeoTIFF with RPC tags")


#: a Pleiades / SPOT 6-7 DIMAP v2 image file: IMG_<product id>[_R1C1].<ext> (first tile only:
#: the other tiles start elsewhere in the product's pixels)
_DIMAP2_IMAGE = re.compile(r"IMG_(?P<id>.+?)(?:_R1C1)?", re.IGNORECASE)


def model_beside(image: str | Path) -> Path:
    """The model file of an image, first found wins: ``METADATA.DIM`` in the folder of an
    ``IMAGERY.*`` file or a ``.DIM`` of the same name (SPOT Level 1A, rigorous), a gcpfree
    ``.json`` of the same name, an OSSIM ``.geom`` of the same name, the DIMAP v2
    ``RPC_<id>.XML`` of an ``IMG_<id>[_R1C1].*`` image (Pleiades, SPOT 6-7 product layout),
    the Sentinel-1 ``annotation/<name>.xml`` of a ``measurement/<name>.tiff`` in a ``.SAFE``,
    else the image itself (its GDAL RPC tags)."""
    image = Path(image)
    dim = dimap_beside(image)
    if dim is not None:
        return dim
    ann = annotation_beside(image)
    if ann is not None:
        return ann
    for suffix in (".json", ".geom"):
        if image.with_suffix(suffix).is_file():
            return image.with_suffix(suffix)
    m = _DIMAP2_IMAGE.fullmatch(image.stem)
    if m:
        for name in (f"RPC_{m['id']}.XML", f"RPC_{m['id']}.xml"):
            if (image.parent / name).is_file():
                return image.parent / name
    return image


def _rpc_size(rpc: RPCModel) -> tuple[int, int]:
    """The image size an RPC's normalisation implies (its offsets are the image centre)."""
    return int(round(2 * rpc.col_off + 1)), int(round(2 * rpc.row_off + 1))


def _place(fm: FileModel, image: Path, size: tuple[int, int], transform: object,
           has_crs: bool) -> tuple[SensorModel, tuple[float, float]]:
    """The file's model in the raster's pixels, and the crop offset applied.

    One rule for every way a model is named (beside the image, ``--model``, a catalog column):
    a file in the ``raster`` frame describes the raster it was written for (a GeoTIFF's RPC
    tags: moved by the difference of the two rasters' pixel offsets, zero for the image's own
    tags); a ``product``-frame file describes the whole vendor image, and a raster that is a
    crop of it (a pure pixel-offset geotransform, see the module docstring) gets the model
    moved by that offset. A pushbroom or SAR model of the raster's own size is the raster's.
    """
    if fm.frame == "raster":
        if fm.path.suffix.lower() not in TIFF_SUFFIXES or _same_file(fm.path, image):
            return fm.model, (0.0, 0.0)
        col0, row0 = pixel_offset_of(transform, has_crs)
        crop = (col0 - fm.raster_offset[0], row0 - fm.raster_offset[1])
    elif fm.size is not None and tuple(fm.size) == tuple(size):
        return fm.model, (0.0, 0.0)
    else:
        crop = pixel_offset_of(transform, has_crs)
        if fm.size is not None and crop == (0.0, 0.0):
            raise InputError(
                f"{image} is {size[0]}x{size[1]} px but {fm.path} describes {fm.size[0]}x"
                f"{fm.size[1]}: they are not the same image (a crop must carry its pixel offset "
                "in its geotransform, as rasterio's window_transform writes it)")
    if crop == (0.0, 0.0):
        return fm.model, crop
    if isinstance(fm.model, RPCModel):
        return fm.model.with_image_offset(*crop), crop
    if isinstance(fm.model, (PushbroomModel, SarModel)):
        return fm.model.with_image_window(crop[0], crop[1], *size), crop
    raise InputError(f"{fm.path}: a {fm.family} model cannot be placed on a crop")


def _same_file(a: Path, b: Path) -> bool:
    try:
        return a.resolve() == b.resolve() or a.samefile(b)
    except OSError:
        return False


def load_model(path: str | Path, *, model: str | Path | None = None,
               band: int | None = None) -> LoadedModel:
    """The sensor model of an image, or of a model file given alone.

    ``path`` may be an image or a model file (``.DIM``, gcpfree ``.json``, ``.geom``, DIMAP v2
    ``RPC_*.XML``: given alone, the model of the whole image it describes); ``model`` names
    the model file of an image explicitly (a GeoTIFF there means its own RPC tags, e.g. to use
    a simulated image's RPC rather than its .DIM), else it is found beside the image
    (:func:`model_beside`). Whichever way it is named, a file reaches the same model for the
    same raster (:func:`_place`: a crop's pixel offset is applied to a model of the whole
    product). ``band`` chooses the look angles of a multispectral SPOT product (BAND_INDEX,
    1-based; default the first).
    """
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path} does not exist; give an image or a sensor model file")
    if path.suffix.lower() in MODEL_SUFFIXES and model is None:
        fm = read_model_file(path, band)
        size = fm.size or (_open_raster(path)[0] if fm.path.suffix.lower() in TIFF_SUFFIXES
                           else _rpc_size(fm.model))  # type: ignore[arg-type]
        return LoadedModel(fm.model, fm.family, path, None, size, fm.spot, fm.band, sar=fm.sar,
                           sun_deg=fm.sun_deg)
    image = path
    size, transform, has_crs, tags = _open_raster(image)
    source = Path(model) if model is not None else model_beside(image)
    if model is None and source == image and not tags:
        raise InputError(
            f"no sensor model found for {image}: no .DIM, .json or .geom of the same name beside "
            "it and no RPC metadata in the raster; put the model file next to the image or name "
            "it (--left-model/--right-model, --model)")
    fm = read_model_file(source, band)
    placed, crop = _place(fm, image, size, transform, has_crs)
    return LoadedModel(placed, fm.family, source, image, size, fm.spot, fm.band, crop,
                       sar=fm.sar if crop == (0.0, 0.0) else None, sun_deg=fm.sun_deg)
