"""Sentinel-1 annotation files: read one (:func:`read_annotation`), recognise one by content
(:func:`is_annotation_file`), find the annotation of a measurement TIFF inside a ``.SAFE``
(:func:`annotation_beside`: ``<safe>/measurement/x.tiff`` -> ``<safe>/annotation/x.xml``).
The text -> model conversion is :mod:`core.sensors.sentinel1`, the geometry
:mod:`core.sensors.sar`.
"""

from __future__ import annotations

from pathlib import Path

from core.errors import InputError
from core.sensors.sentinel1 import Annotation, looks_like_annotation, parse_annotation

_HEAD_BYTES = 4096


def is_annotation_file(path: str | Path) -> bool:
    """Whether an XML file is a Sentinel-1 product annotation, from its first bytes."""
    try:
        with open(path, "rb") as f:
            head = f.read(_HEAD_BYTES).decode("utf-8", errors="replace")
    except OSError:
        return False
    return looks_like_annotation(head)


def read_annotation(path: str | Path) -> Annotation:
    """The SAR model and geolocation grid of a Sentinel-1 annotation file."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise InputError(f"cannot read Sentinel-1 annotation {path}: {exc.strerror}; check the "
                         "path") from exc
    return parse_annotation(text, str(path))


def annotation_beside(image: str | Path) -> Path | None:
    """The annotation of a measurement TIFF of a ``.SAFE`` product (same name, ``.xml``, in the
    sibling ``annotation/`` folder), or None when the image is not laid out so."""
    image = Path(image)
    if image.parent.name.lower() != "measurement":
        return None
    for suffix in (".xml", ".XML"):
        cand = image.parent.parent / "annotation" / (image.stem + suffix)
        if cand.is_file():
            return cand
    return None
