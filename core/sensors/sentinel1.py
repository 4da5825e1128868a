"""Sentinel-1 product annotation XML (``annotation/s1?-*.xml`` of a ``.SAFE``) as text:
:func:`parse_annotation` reads it into a :class:`~core.sensors.sar.SarModel` and its
geolocation grid.

Parsing only; the geometry is :mod:`core.sensors.sar`, reading files and finding the
annotation of a measurement TIFF is :mod:`tasks.io.sentinel1`. Times become seconds since the
first orbit state vector (``SarModel.orbit.epoch_utc``, UTC). A document that is not a
Sentinel-1 product annotation, or a damaged one, stops with a one-line
:class:`~core.errors.InputError`.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from core.errors import InputError
from core.sensors._xmldoc import XmlDoc
from core.sensors.orbit import Orbit
from core.sensors.sar import SarModel

FloatArray = NDArray[np.float64]
_INFO = "imageAnnotation/imageInformation"
#: missionId values read: Sentinel-1, and ERS in the same form (``gcpfree simulate --sar ers``)
MISSION_PREFIXES = ("S1", "ERS")


def looks_like_annotation(head: str) -> bool:
    """Whether the start of an XML text is a Sentinel-1 product annotation (its root is
    ``<product>`` with an ``<adsHeader>``)."""
    return "<product" in head and "<adsHeader" in head


@dataclass(frozen=True, eq=False)
class GeolocationGrid:
    """The annotation's geolocation grid: one entry per point, times as the model's."""

    azimuth_time_s: FloatArray
    slant_range_time_s: FloatArray
    line: FloatArray
    pixel: FloatArray
    lon_deg: FloatArray
    lat_deg: FloatArray
    h_m: FloatArray


@dataclass(frozen=True, eq=False)
class Annotation:
    """A parsed annotation: the model, its grid, and what the header says."""

    model: SarModel
    grid: GeolocationGrid
    mission: str
    mode: str
    product_type: str
    polarisation: str
    swath: str
    first_line_utc: str


class _Doc(XmlDoc):
    """A Sentinel-1 annotation tree: :class:`XmlDoc` plus number lists and UTC times."""

    def __init__(self, root: ET.Element, name: str) -> None:
        super().__init__(root, name, "the Sentinel-1 annotation is damaged or truncated")

    def floats(self, path: str, el: ET.Element | None = None) -> FloatArray:
        txt = self.text(path, el)
        try:
            return np.array([float(x) for x in txt.split()])
        except ValueError:
            raise InputError(f"{self.name}: <{path}> holds non-numbers; the Sentinel-1 "
                             "annotation is damaged") from None

    def time(self, path: str, el: ET.Element | None = None) -> np.datetime64:
        txt = self.text(path, el)
        try:
            return np.datetime64(txt, "ns")
        except (ValueError, OverflowError):
            raise InputError(f"{self.name}: <{path}> holds {txt[:40]!r}, not an ISO 8601 UTC "
                             "time; the Sentinel-1 annotation is damaged") from None


def _seconds(t: np.datetime64 | NDArray, epoch: np.datetime64) -> FloatArray:
    return np.asarray((t - epoch) / np.timedelta64(1, "ns"), dtype=np.float64) * 1e-9


def parse_annotation(text: str, name: str = "annotation") -> Annotation:
    """A Sentinel-1 SLC (stripmap or TOPS) or GRD product annotation -> model and grid."""
    try:
        return _parse(text, name)
    except InputError as exc:
        if name in str(exc):
            raise
        raise InputError(f"{name}: {exc}") from None


def _parse(text: str, name: str) -> Annotation:
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise InputError(f"{name} is not well-formed XML ({exc}); the annotation is damaged or "
                         "truncated") from None
    if root.tag != "product" or root.find("adsHeader/missionId") is None:
        raise InputError(f"{name} is not a Sentinel-1 product annotation (root <{root.tag}>, "
                         "no <adsHeader>); give the annotation/*.xml of a Sentinel-1 .SAFE")
    doc = _Doc(root, name)
    mission = doc.text("adsHeader/missionId")
    if not mission.startswith(MISSION_PREFIXES):
        raise InputError(f"{name}: mission {mission!r} is not Sentinel-1; only Sentinel-1 "
                         "annotations (and the SAR simulator's ERS-like ones) are read")
    ptype, mode = doc.text("adsHeader/productType"), doc.text("adsHeader/mode")
    orbits = doc.find("generalAnnotation/orbitList").findall("orbit")
    if len(orbits) < 2:
        raise InputError(f"{name}: fewer than 2 orbit state vectors; the annotation is damaged")
    for o in orbits:
        frame = doc.text("frame", o)
        if frame != "Earth Fixed":
            raise InputError(f"{name}: orbit frame {frame!r} is not 'Earth Fixed'")
    times = np.array([doc.time("time", o) for o in orbits])
    epoch = times[0]
    pos = np.array([[doc.number(f"position/{c}", o) for c in "xyz"] for o in orbits])
    vel = np.array([[doc.number(f"velocity/{c}", o) for c in "xyz"] for o in orbits])
    orbit = Orbit(_seconds(times, epoch), pos, vel, epoch_utc=str(epoch) + "Z")

    t0 = _seconds(doc.time(f"{_INFO}/productFirstLineUtcTime"), epoch)
    common = dict(
        orbit=orbit, n_cols=int(doc.number(f"{_INFO}/numberOfSamples")),
        n_rows=int(doc.number(f"{_INFO}/numberOfLines")), first_line_time_s=float(t0),
        line_interval_s=doc.number(f"{_INFO}/azimuthTimeInterval"),
        slant_range_time_s=doc.number(f"{_INFO}/slantRangeTime"),
        range_sampling_rate_hz=doc.number("generalAnnotation/productInformation/"
                                         "rangeSamplingRate"),
        range_pixel_spacing_m=doc.number(f"{_INFO}/rangePixelSpacing"),
        mission=mission, mode=mode)
    bursts = doc.find("swathTiming/burstList").findall("burst")
    if ptype == "GRD":
        recs = doc.find("coordinateConversion/coordinateConversionList").findall(
            "coordinateConversion")
        if not recs:
            raise InputError(f"{name}: a GRD annotation without slant-to-ground-range records "
                             "(coordinateConversionList); the annotation is damaged")
        coeffs = [doc.floats("srgrCoefficients", r) for r in recs]
        if len({c.size for c in coeffs}) != 1 or coeffs[0].size < 2:
            raise InputError(f"{name}: srgrCoefficients of unequal or too small length")
        model = SarModel(kind="grd", **common,
                         srgr_times_s=_seconds(np.array([doc.time("azimuthTime", r)
                                                         for r in recs]), epoch),
                         srgr_sr0_m=np.array([doc.number("sr0", r) for r in recs]),
                         srgr_coeffs=np.array(coeffs))
    elif ptype == "SLC" and bursts:
        model = SarModel(kind="tops", **common,
                         burst_times_s=_seconds(np.array([doc.time("azimuthTime", b)
                                                          for b in bursts]), epoch),
                         lines_per_burst=int(doc.number("swathTiming/linesPerBurst")))
    elif ptype == "SLC":
        model = SarModel(kind="slc", **common)
    else:
        raise InputError(f"{name}: product type {ptype!r} has no geometry here; give an SLC "
                         "or GRD annotation")

    pts = doc.find("geolocationGrid/geolocationGridPointList").findall("geolocationGridPoint")
    vals = {k: np.array([doc.number(k, p) for p in pts]) for k in
            ("slantRangeTime", "line", "pixel", "longitude", "latitude", "height")}
    grid = GeolocationGrid(
        _seconds(np.array([doc.time("azimuthTime", p) for p in pts], dtype="datetime64[ns]"),
                 epoch),
        vals["slantRangeTime"], vals["line"], vals["pixel"], vals["longitude"],
        vals["latitude"], vals["height"])
    return Annotation(model, grid, mission, mode, ptype, doc.text("adsHeader/polarisation"),
                      doc.text("adsHeader/swath"),
                      doc.text(f"{_INFO}/productFirstLineUtcTime"))
