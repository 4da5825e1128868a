"""Read sensor models from files: RPCs (OSSIM ``.geom``, GeoTIFF RPC tags, DIMAP v2 RPC XML),
SPOT Level 1A ``METADATA.DIM`` and gcpfree JSON; find the model of an image (:func:`load_model`).

Where each source's pixel coordinates start, and how :func:`read_rpc` brings them to the
raster's own pixels (0-based, pixel centres at integers):

- ``.geom`` and DIMAP files describe the *full* vendor image. A crop that stores its position
  as a pure pixel-offset geotransform (no CRS, unit pixel size, origin ``(c, f)``: what
  ``gdal_translate -srcwin c f ...`` or rasterio's ``window_transform`` write for a raster with
  no georeferencing) has its pixel ``(0, 0)`` at full-image pixel ``(c, f)``: the half-pixel
  shifts of the corner-based geotransform cancel, so the model is moved by exactly ``(c, f)``
  (:meth:`RPCModel.with_image_offset`). The Ventoux crops carry origins such as (5000, 5000).
- RPC tags inside the raster (GDAL RPC metadata domain) already describe that raster's pixels
  (GDAL's RPC transformer ignores the geotransform and GDAL updates the tags when it crops), so
  no offset is applied to them.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

import rasterio
from rasterio.errors import NotGeoreferencedWarning, RasterioIOError

from core.errors import InputError
from core.jsonio import parse_json
from core.sensors.base import SensorModel
from core.sensors.pushbroom import PushbroomModel
from core.sensors.rpc import RPCModel
from core.sensors.spot import SpotScene, spot_pushbroom
from tasks.dimap import dimap_beside, read_dimap


def _read_text(path: Path, what: str) -> str:
    try:
        return path.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise InputError(f"cannot read {what} {path}: {exc.strerror}; check the path") from exc


def rpc_from_geom_file(path: str | Path) -> RPCModel:
    """RPC from an OSSIM keyword-list file (``.geom``), in the full image's pixels."""
    path = Path(path)
    try:
        return RPCModel.from_geom(_read_text(path, "RPC .geom file"))
    except InputError as exc:
        raise InputError(f"{path}: {exc}") from exc


def rpc_from_dimap_file(path: str | Path) -> RPCModel:
    """RPC from a Pleiades / SPOT 6-7 DIMAP v2 RPC XML file, in the full image's 0-based pixels."""
    path = Path(path)
    try:
        return RPCModel.from_dimap_xml(_read_text(path, "DIMAP RPC file"))
    except InputError as exc:
        raise InputError(f"{path}: {exc}") from exc


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
        "offset; an RPC from a .geom/DIMAP file cannot be placed on it. Give the uncropped "
        "image or a crop written with a unit-pixel offset geotransform"
    )


def read_rpc_tags(image_path: str | Path) -> RPCModel:
    """The RPC in a raster's own GDAL RPC metadata domain (ignoring any .geom beside it)."""
    image_path = Path(image_path)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", NotGeoreferencedWarning)
            with rasterio.open(image_path) as src:
                tags = src.tags(ns="RPC")
    except RasterioIOError as exc:
        raise InputError(f"cannot open raster {image_path}: {exc}; check the path") from exc
    if not tags:
        raise InputError(f"{image_path} holds no RPC tags; give its model file instead")
    try:
        return RPCModel.from_gdal_tags(tags)
    except InputError as exc:
        raise InputError(f"{image_path} RPC tags: {exc}") from exc


def read_rpc(image_path: str | Path, dimap_xml: str | Path | None = None) -> RPCModel:
    """The RPC model of a raster, in that raster's pixels (0-based, centres at integers).

    Sources, first found wins:

    1. ``dimap_xml`` when given (explicit beats implicit);
    2. a ``.geom`` beside the image (same name, suffix ``.geom``);
    3. the raster's GDAL RPC metadata domain.

    For (1) and (2) a pure pixel-offset geotransform moves the model into the crop's pixels
    (see the module docstring); in-file RPC tags are taken as they are.

    Raises:
        InputError: the image cannot be opened, no RPC is found, or the RPC is malformed.
    """
    image_path = Path(image_path)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", NotGeoreferencedWarning)
            with rasterio.open(image_path) as src:
                tags = src.tags(ns="RPC")
                transform, has_crs = src.transform, src.crs is not None
    except RasterioIOError as exc:
        raise InputError(f"cannot open raster {image_path}: {exc}; check the path") from exc

    geom = image_path.with_suffix(".geom")
    if dimap_xml is not None:
        model = rpc_from_dimap_file(dimap_xml)
    elif geom.is_file():
        model = rpc_from_geom_file(geom)
    elif tags:
        try:
            return RPCModel.from_gdal_tags(tags)
        except InputError as exc:
            raise InputError(f"{image_path} RPC tags: {exc}") from exc
    else:
        raise InputError(
            f"no RPC found for {image_path}: no {geom.name} beside it and no RPC metadata in the "
            "raster; put the OSSIM .geom next to the image or pass the DIMAP RPC XML (dimap_xml=)"
        )
    col0, row0 = pixel_offset_of(transform, has_crs)
    if col0 or row0:
        model = model.with_image_offset(col0, row0)
    return model


# ---------------------------------------------------------------------------- any sensor model

MODEL_SUFFIXES = (".dim", ".json", ".geom", ".xml")


@dataclass(frozen=True, eq=False)
class LoadedModel:
    """A sensor model found for an image or read from a model file, and where it came from.

    ``family`` is ``"pushbroom"`` or ``"rpc"``; ``source`` the file the model was read from;
    ``image`` the raster when one was given or found; ``size`` (cols, rows) of the image the
    model describes; ``spot`` the SPOT metadata when the model came from a ``METADATA.DIM``;
    ``band`` the band whose look angles were used.
    """

    model: SensorModel
    family: str
    source: Path
    image: Path | None
    size: tuple[int, int]
    spot: SpotScene | None = None
    band: int | None = None


def _raster_size(path: Path) -> tuple[int, int]:
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", NotGeoreferencedWarning)
            with rasterio.open(path) as src:
                return src.width, src.height
    except RasterioIOError as exc:
        raise InputError(f"cannot open raster {path}: {exc}; check the path") from exc


def _from_dimap(path: Path, image: Path | None, band: int | None) -> LoadedModel:
    scene = read_dimap(path)
    model = spot_pushbroom(scene, band)
    if image is not None and _raster_size(image) != (scene.n_cols, scene.n_rows):
        raise InputError(f"{image} is {_raster_size(image)} px but {path} describes "
                         f"{scene.n_cols}x{scene.n_rows}: they are not the same scene")
    return LoadedModel(model, "pushbroom", path, image, (scene.n_cols, scene.n_rows), scene,
                       scene.look(band).band_index)


def _from_json(path: Path, image: Path | None) -> LoadedModel:
    d = parse_json(_read_text(path, "model JSON file"), str(path))
    rpc = isinstance(d, dict) and d.get("type") == "rpc"
    try:
        model = RPCModel.from_dict(d) if rpc else PushbroomModel.from_dict(d)
        size = ((_raster_size(image) if image else _rpc_size(model)) if rpc
                else (model.n_cols, model.n_rows))
    except InputError as exc:
        raise InputError(f"{path}: {exc}") from None
    except (KeyError, IndexError, TypeError, ValueError, AttributeError, OverflowError) as exc:
        # the model classes check the keys they expect, not every damaged value
        raise InputError(f"{path} is not a valid gcpfree {'RPC' if rpc else 'pushbroom'} model "
                         f"({type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''})"
                         "; give the model file gcpfree wrote") from None
    return LoadedModel(model, "rpc" if rpc else "pushbroom", path, image, size)


def _rpc_size(rpc: RPCModel) -> tuple[int, int]:
    """The image size an RPC's normalisation implies (its offsets are the image centre)."""
    return int(round(2 * rpc.col_off + 1)), int(round(2 * rpc.row_off + 1))


def load_model(path: str | Path, *, model: str | Path | None = None,
               band: int | None = None) -> LoadedModel:
    """The sensor model of an image, or of a model file given alone.

    ``path`` may be an image or a model file (``.DIM``, gcpfree ``.json``, ``.geom``, DIMAP v2
    ``RPC_*.XML``); ``model`` names the model file of an image explicitly (a GeoTIFF there
    means its own RPC tags, e.g. to use a simulated image's RPC rather than its .DIM). For an image the
    model is looked for beside it, first found wins: ``METADATA.DIM`` in the folder of an
    ``IMAGERY.*`` file or a ``.DIM`` of the same name (SPOT Level 1A, rigorous), a gcpfree
    pushbroom ``.json`` of the same name, then its RPC (:func:`read_rpc`). ``band`` chooses the
    look angles of a multispectral SPOT product (BAND_INDEX, 1-based; default the first).
    """
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path} does not exist; give an image or a sensor model file")
    if path.suffix.lower() in MODEL_SUFFIXES and model is None:
        model, image = path, None
    else:
        image = path
    if model is not None:
        model = Path(model)
        if not model.is_file():
            raise InputError(f"model file {model} does not exist")
        suffix = model.suffix.lower()
        if suffix == ".dim":
            return _from_dimap(model, image, band)
        if suffix == ".json":
            return _from_json(model, image)
        if suffix == ".geom" or suffix == ".xml":
            rpc = (rpc_from_geom_file(model) if suffix == ".geom"
                   else rpc_from_dimap_file(model))
            if image is not None:
                rpc = read_rpc(image, dimap_xml=model) if suffix == ".xml" else rpc
                return LoadedModel(rpc, "rpc", model, image, _raster_size(image))
            return LoadedModel(rpc, "rpc", model, None, _rpc_size(rpc))
        if suffix in (".tif", ".tiff"):  # a GeoTIFF's own RPC tags
            rpc = read_rpc_tags(model)
            return LoadedModel(rpc, "rpc", model, image,
                               _raster_size(image) if image is not None else _raster_size(model))
        raise InputError(f"{model}: unknown model format; give a .DIM (SPOT), a gcpfree .json, "
                         "an OSSIM .geom, a DIMAP v2 RPC .XML or a GeoTIFF with RPC tags")
    dim = dimap_beside(image)
    if dim is not None:
        return _from_dimap(dim, image, band)
    js = image.with_suffix(".json")
    if js.is_file():
        return _from_json(js, image)
    geom = image.with_suffix(".geom")
    return LoadedModel(read_rpc(image), "rpc", geom if geom.is_file() else image, image,
                       _raster_size(image))
