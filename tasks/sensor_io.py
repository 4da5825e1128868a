"""Read RPC sensor models from files: OSSIM ``.geom``, GeoTIFF RPC tags, DIMAP v2 RPC XML.

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
from pathlib import Path

import rasterio
from rasterio.errors import NotGeoreferencedWarning, RasterioIOError

from core.errors import InputError
from core.sensors.rpc import RPCModel


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
