"""Sentinel-1 annotation files: read one (:func:`read_annotation`), recognise one by content
(:func:`is_annotation_file`), find the annotation of a measurement TIFF inside a ``.SAFE``
(:func:`annotation_beside`: ``<safe>/measurement/x.tiff`` -> ``<safe>/annotation/x.xml``),
write one for a model and its grid (:func:`annotation_xml`, :func:`write_annotation`: the SAR
simulator's annotations, read back by the same reader).
The text -> model conversion is :mod:`core.sensors.sentinel1`, the geometry
:mod:`core.sensors.sar`.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from core.errors import InputError
from core.sensors.sar import SPEED_OF_LIGHT_M_S, SarModel
from core.sensors.sentinel1 import Annotation, looks_like_annotation, parse_annotation
from core.simulation.sar import GridPoints
from tasks.io.rasters import atomic_write_text

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


# ---------------------------------------------------------------------------- writing


@dataclass(frozen=True)
class AnnotationHeader:
    """What an annotation states besides the geometry (the simulator fills it)."""

    product_type: str  # "SLC" (slant range) or "GRD" (ground range)
    polarisation: str = "VV"
    swath: str = "S2"
    pass_direction: str = "Descending"
    radar_frequency_hz: float = 5.405e9
    terrain_height_m: float = 0.0
    azimuth_pixel_spacing_m: float = 0.0
    incidence_mid_deg: float = 0.0
    heading_deg: float = 0.0


def _num(v: float) -> str:
    return repr(float(v))


def _utc(model: SarModel, t_s: np.ndarray | float) -> list[str]:
    """ISO UTC strings with microseconds and no zone, as annotations write them."""
    return [u.rstrip("Z") for u in model.utc_of_times(t_s)]


def _timed_records(parent: ET.Element, list_tag: str, item_tag: str, times_utc: list[str]
                   ) -> Iterator[tuple[int, ET.Element]]:
    """``<list_tag count=n>`` under ``parent`` and in it one ``<item_tag>`` per time, each
    opened by its ``azimuthTime``: (index, item) to fill with the rest of the record."""
    records = ET.SubElement(parent, list_tag, count=str(len(times_utc)))
    for i, t in enumerate(times_utc):
        item = ET.SubElement(records, item_tag)
        ET.SubElement(item, "azimuthTime").text = t
        yield i, item


def annotation_xml(model: SarModel, grid: GridPoints, head: AnnotationHeader,
                   grsr: np.ndarray | None = None) -> str:
    """A Sentinel-1 product annotation (the subset :func:`core.sensors.sentinel1.parse_annotation`
    and other readers use) of a ``slc`` or ``grd`` model and its geolocation grid; numbers are
    written with Python's shortest repr so the model reads back bit for bit (times to the
    microsecond: give the model microsecond times)."""
    if model.kind not in ("slc", "grd") or model.col0_px or model.row0_px:
        raise InputError("only whole stripmap SLC or GRD models can be written as annotations")
    root = ET.Element("product")

    def sub(parent: ET.Element, tag: str, text: object = None, **attrib: str) -> ET.Element:
        el = ET.SubElement(parent, tag, attrib)
        if text is not None:
            el.text = text if isinstance(text, str) else _num(text)  # type: ignore[arg-type]
        return el

    t_first = model.first_line_time_s
    t_last = t_first + (model.n_rows - 1) * model.line_interval_s
    first, last = _utc(model, [t_first, t_last])
    ads = sub(root, "adsHeader")
    for tag, text in (("missionId", model.mission), ("productType", head.product_type),
                      ("polarisation", head.polarisation), ("mode", model.mode),
                      ("swath", head.swath), ("startTime", first), ("stopTime", last),
                      ("absoluteOrbitNumber", "0"), ("missionDataTakeId", "0"),
                      ("imageNumber", "001")):
        sub(ads, tag, text)
    gen = sub(root, "generalAnnotation")
    info = sub(gen, "productInformation")
    sub(info, "pass", head.pass_direction)
    sub(info, "timelinessCategory", "Simulated")
    sub(info, "platformHeading", head.heading_deg)
    sub(info, "projection", "Ground Range" if model.kind == "grd" else "Slant Range")
    sub(info, "rangeSamplingRate", model.range_sampling_rate_hz)
    sub(info, "radarFrequency", head.radar_frequency_hz)
    orbit = model.orbit
    ol = sub(gen, "orbitList", count=str(orbit.times_s.size))
    for t, p, v in zip(_utc(model, orbit.times_s), orbit.positions_m, orbit.velocities_m_s,
                       strict=True):
        o = sub(ol, "orbit")
        sub(o, "time", t)
        sub(o, "frame", "Earth Fixed")
        for name, vec in (("position", p), ("velocity", v)):
            e = sub(o, name)
            for c, x in zip("xyz", vec, strict=True):
                sub(e, c, x)
    th = sub(gen, "terrainHeightList", count="1")
    e = sub(th, "terrainHeight")
    sub(e, "azimuthTime", first)
    sub(e, "value", head.terrain_height_m)
    img = sub(sub(root, "imageAnnotation"), "imageInformation")
    for tag, text in (
            ("productFirstLineUtcTime", first), ("productLastLineUtcTime", last),
            ("slantRangeTime", model.slant_range_time_s), ("pixelValue", "Detected"),
            ("outputPixels", "16 bit Unsigned Integer"),
            ("rangePixelSpacing", model.range_pixel_spacing_m),
            ("azimuthPixelSpacing", head.azimuth_pixel_spacing_m),
            ("azimuthTimeInterval", model.line_interval_s),
            ("azimuthFrequency", 1.0 / model.line_interval_s),
            ("numberOfSamples", str(model.n_cols)), ("numberOfLines", str(model.n_rows)),
            ("incidenceAngleMidSwath", head.incidence_mid_deg)):
        sub(img, tag, text)
    st = sub(root, "swathTiming")
    sub(st, "linesPerBurst", "0")
    sub(st, "samplesPerBurst", "0")
    sub(st, "burstList", count="0")
    for i, p in _timed_records(sub(root, "geolocationGrid"), "geolocationGridPointList",
                               "geolocationGridPoint", _utc(model, grid.azimuth_time_s)):
        sub(p, "slantRangeTime", grid.slant_range_time_s[i])
        sub(p, "line", str(int(grid.line[i])))
        sub(p, "pixel", str(int(grid.pixel[i])))
        for tag, arr in (("latitude", grid.lat_deg), ("longitude", grid.lon_deg),
                         ("height", grid.h_m), ("incidenceAngle", grid.incidence_deg),
                         ("elevationAngle", grid.elevation_deg)):
            sub(p, tag, arr[i])
    if model.kind == "grd":
        for k, r in _timed_records(sub(root, "coordinateConversion"),
                                   "coordinateConversionList", "coordinateConversion",
                                   _utc(model, model.srgr_times_s)):
            sub(r, "slantRangeTime", 2.0 * model.srgr_sr0_m[k] / SPEED_OF_LIGHT_M_S)
            sub(r, "sr0", model.srgr_sr0_m[k])
            sub(r, "srgrCoefficients", " ".join(_num(c) for c in model.srgr_coeffs[k]),
                count=str(model.srgr_coeffs.shape[1]))
            sub(r, "gr0", 0.0)
            if grsr is not None:
                sub(r, "grsrCoefficients", " ".join(_num(c) for c in grsr[k]),
                    count=str(grsr.shape[1]))
    ET.indent(root, space="  ")
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") \
        + "\n"


def write_annotation(path: str | Path, model: SarModel, grid: GridPoints,
                     head: AnnotationHeader, grsr: np.ndarray | None = None) -> Path:
    """Write :func:`annotation_xml` to ``path`` atomically; returns the path."""
    path = Path(path)
    atomic_write_text(path, annotation_xml(model, grid, head, grsr))
    return path
