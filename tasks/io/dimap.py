"""SPOT 1-5 Level 1A DIMAP metadata files (``METADATA.DIM``): read, written, found beside an
image. The text <-> :class:`~core.sensors.spot.SpotScene` conversion is
:mod:`core.sensors.dimap`; what the values mean is :mod:`core.sensors.spot`.
"""

from __future__ import annotations

from pathlib import Path

from core.errors import InputError
from core.sensors.dimap import dimap_xml, parse_dimap
from core.sensors.spot import SpotScene
from tasks.io.rasters import atomic_write_text


def read_dimap(path: str | Path) -> SpotScene:
    """The geometry stated by a ``METADATA.DIM`` file."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise InputError(f"cannot read DIMAP file {path}: {exc.strerror}; check the path") from exc
    return parse_dimap(text, str(path))


def write_dimap(scene: SpotScene, path: str | Path, image_name: str = "IMAGERY.TIF") -> Path:
    """Write ``scene`` as a ``METADATA.DIM`` (atomically) referring to ``image_name``."""
    return atomic_write_text(path, dimap_xml(scene, image_name))


# ------------------------------------------------------------------------------------ discovery

IMAGE_SUFFIXES = (".tif", ".tiff", ".bil", ".TIF", ".TIFF", ".BIL")


def dimap_beside(image: str | Path) -> Path | None:
    """The DIMAP metadata of an image, found as ASP finds it: ``METADATA.DIM`` in the folder of
    an ``IMAGERY.*`` file, else a ``.DIM``/``.dim`` file of the same name beside the image."""
    image = Path(image)
    candidates = []
    if image.stem.upper() == "IMAGERY":
        candidates += [image.with_name("METADATA.DIM"), image.with_name("metadata.dim")]
    candidates += [image.with_suffix(".DIM"), image.with_suffix(".dim")]
    return next((c for c in candidates if c.is_file()), None)
