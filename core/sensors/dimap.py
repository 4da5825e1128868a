"""SPOT 1-5 Level 1A DIMAP metadata (``METADATA.DIM``, profile ``SPOTSCENE_1A``) as text:
:func:`parse_dimap` reads the XML into a :class:`~core.sensors.spot.SpotScene`,
:func:`dimap_xml` writes one, as :mod:`core.sensors.rpc00b` reads and writes the RPC formats.

Parsing and writing the XML only; what the values mean and how they become a sensor model is
in :mod:`core.sensors.spot`. Every time is UTC, in seconds since the first ephemeris point.
A document of another profile (ortho or 1B products, SPOT 6/7 and Pleiades DIMAP v2) or a
truncated one stops with a one-line :class:`~core.errors.InputError`. Reading and writing the
files is :mod:`tasks.io.dimap`.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from datetime import datetime, timedelta

import numpy as np

from core.errors import InputError
from core.sensors._xmldoc import XmlDoc
from core.sensors.orbit import Orbit
from core.sensors.spot import FramePoint, SpotAngles, SpotLookAngles, SpotScene

PROFILE = "SPOTSCENE_1A"
_ATTITUDE = "Data_Strip/Satellite_Attitudes"
_LOOK = "Data_Strip/Sensor_Configuration/Instrument_Look_Angles_List/Instrument_Look_Angles"
_TIME = "Data_Strip/Sensor_Configuration/Time_Stamp"
_SOURCE = "Dataset_Sources/Source_Information/Scene_Source"


class _Doc(XmlDoc):
    """A DIMAP tree: :class:`XmlDoc` whose text look-ups may fall back to a default."""

    def __init__(self, root: ET.Element, name: str) -> None:
        super().__init__(root, name, "the DIMAP file is truncated or not a complete SPOT "
                                     "Level 1A metadata file")

    def text(self, path: str, el: ET.Element | None = None, default: str | None = None) -> str:
        found = (self.root if el is None else el).find(path)
        if found is None or not (found.text or "").strip():
            if default is not None:
                return default
            self.find(path, el)  # raises
            raise InputError(f"{self.name}: <{path}> is empty")
        return found.text.strip()

    def optional(self, path: str) -> float | None:
        found = self.root.find(path)
        return None if found is None or not (found.text or "").strip() else self.number(path)


def _parse_time(text: str, name: str) -> datetime:
    try:
        return datetime.fromisoformat(text.strip().rstrip("Z"))
    except ValueError:
        raise InputError(f"{name}: time {text!r} is not an ISO date-time") from None


def _check_profile(root: ET.Element, name: str) -> None:
    if root.tag != "Dimap_Document":
        raise InputError(f"{name} is not a DIMAP document (root <{root.tag}>); give the "
                         "METADATA.DIM of a SPOT 1-5 Level 1A scene")
    if root.find("Metadata_Identification") is not None:
        raise InputError(
            f"{name} is DIMAP v2 (SPOT 6/7 or Pleiades): those products carry their geometry as "
            "an RPC; give the RPC_*.XML (or the image with its RPC) instead")
    profile = (root.findtext("Metadata_Id/METADATA_PROFILE") or "").strip()
    if profile != PROFILE:
        raise InputError(
            f"{name} has METADATA_PROFILE {profile or 'none'!r}: only raw-geometry Level 1A "
            f"scenes ({PROFILE}) have a rigorous model here; resampled or orthorectified "
            "products (1B, 2A, SPOTView) cannot be oriented")


def parse_dimap(text: str, name: str = "METADATA.DIM") -> SpotScene:
    """The geometry of a SPOT 1-5 Level 1A DIMAP document (the text of ``METADATA.DIM``)."""
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise InputError(f"{name} is not well-formed XML ({exc}); the file is truncated or "
                         "damaged: download it again") from None
    _check_profile(root, name)
    doc = _Doc(root, name)
    points = root.findall("Data_Strip/Ephemeris/Points/Point")
    if len(points) < 2:
        raise InputError(f"{name}: the Ephemeris holds {len(points)} point(s); at least 2 "
                         "(normally 8 or more) are needed")
    epoch = _parse_time(doc.text("TIME", points[0]), name)

    def seconds(el: ET.Element, path: str = "TIME") -> float:
        return (_parse_time(doc.text(path, el), name) - epoch).total_seconds()

    mission = int(doc.number(f"{_SOURCE}/MISSION_INDEX"))
    times = np.array([seconds(p) for p in points])
    if np.any(np.diff(times) <= 0):
        raise InputError(f"{name}: the ephemeris times are not increasing; the file is corrupt")
    xyz = ("X", "Y", "Z")
    orbit = Orbit(
        times,
        np.array([[doc.number(f"Location/{k}", p) for k in xyz] for p in points]),
        np.array([[doc.number(f"Velocity/{k}", p) for k in xyz] for p in points]),
        epoch_utc=epoch.isoformat() + "Z",
        velocity_frame="ecef" if mission == 5 else "inertial",
    )

    def angles(path: str) -> SpotAngles | None:
        nodes = root.findall(path)
        if not nodes:
            return None
        return SpotAngles(
            np.array([seconds(n) for n in nodes]),
            *(np.array([doc.number(k, n) for n in nodes]) for k in ("ROLL", "PITCH", "YAW")),
            np.array([doc.text("OUT_OF_RANGE", n, "N") == "Y" for n in nodes]),
        )

    look = []
    for block in root.findall(_LOOK):
        rows = block.findall("Look_Angles_List/Look_Angles")
        look.append(SpotLookAngles(
            int(doc.number("BAND_INDEX", block)),
            np.array([int(doc.number("DETECTOR_ID", r)) for r in rows]),
            np.array([doc.number("PSI_X", r) for r in rows]),
            np.array([doc.number("PSI_Y", r) for r in rows]),
        ))

    def frame_point(v: ET.Element) -> FramePoint:
        return FramePoint(doc.number("FRAME_ROW", v), doc.number("FRAME_COL", v),
                          doc.number("FRAME_LON", v), doc.number("FRAME_LAT", v))

    frame = [frame_point(v) for v in root.findall("Dataset_Frame/Vertex")]
    centre = root.find("Dataset_Frame/Scene_Center")
    if centre is not None:
        frame.append(frame_point(centre))
    return SpotScene(
        mission_index=mission,
        instrument=doc.text(f"{_SOURCE}/INSTRUMENT"),
        instrument_index=int(doc.number(f"{_SOURCE}/INSTRUMENT_INDEX")),
        sensor_code=doc.text(f"{_SOURCE}/SENSOR_CODE", default=""),
        n_cols=int(doc.number("Raster_Dimensions/NCOLS")),
        n_rows=int(doc.number("Raster_Dimensions/NROWS")),
        epoch_utc=epoch.isoformat() + "Z",
        line_period_s=doc.number(f"{_TIME}/LINE_PERIOD"),
        centre_time_s=seconds(doc.find(_TIME), "SCENE_CENTER_TIME"),
        centre_line=doc.number(f"{_TIME}/SCENE_CENTER_LINE"),
        orbit=orbit,
        look_angles=tuple(look),
        aocs_angles=angles(f"{_ATTITUDE}/Raw_Attitudes/Aocs_Attitude/Angles_List/Angles"),
        aocs_speeds=angles(
            f"{_ATTITUDE}/Raw_Attitudes/Aocs_Attitude/Angular_Speeds_List/Angular_Speeds"),
        corrected_attitude=angles(f"{_ATTITUDE}/Corrected_Attitudes/Corrected_Attitude/Angles"),
        frame=tuple(frame),
        incidence_deg=doc.optional(f"{_SOURCE}/INCIDENCE_ANGLE"),
        viewing_angle_deg=doc.optional(f"{_SOURCE}/VIEWING_ANGLE"),
        sun_azimuth_deg=doc.optional(f"{_SOURCE}/SUN_AZIMUTH"),
        sun_elevation_deg=doc.optional(f"{_SOURCE}/SUN_ELEVATION"),
        dataset_name=doc.text("Dataset_Id/DATASET_NAME", default=""),
    )


# ------------------------------------------------------------------------------------- writing


def _num(v: float) -> str:
    return f"{float(v):+.16e}"  # 17 significant digits: the float read back is the one written


def _sub(parent: ET.Element, tag: str, text: object | None = None, **attrib: str) -> ET.Element:
    el = ET.SubElement(parent, tag, attrib)
    if text is not None:
        el.text = str(text)
    return el


def dimap_xml(scene: SpotScene, image_name: str = "IMAGERY.TIF",
              producer: str = "gcpfree simulate") -> str:
    """A SPOT Level 1A ``METADATA.DIM`` stating ``scene`` (what :func:`parse_dimap` reads, with
    the paths and units of real products; times on the microsecond grid)."""
    epoch = datetime.fromisoformat(scene.epoch_utc.rstrip("Z"))

    def utc(t_s: float) -> str:
        return (epoch + timedelta(microseconds=round(t_s * 1e6))).strftime("%Y-%m-%dT%H:%M:%S.%f")

    root = ET.Element("Dimap_Document", name="METADATA.DIM")
    meta = _sub(root, "Metadata_Id")
    _sub(meta, "METADATA_FORMAT", "DIMAP", version="1.1")
    _sub(meta, "METADATA_PROFILE", PROFILE)
    _sub(_sub(root, "Dataset_Id"), "DATASET_NAME", scene.dataset_name)
    frame = _sub(root, "Dataset_Frame")
    for i, p in enumerate(scene.frame):
        v = _sub(frame, "Vertex" if i < 4 else "Scene_Center")
        _sub(v, "FRAME_LON", _num(p.lon_deg))
        _sub(v, "FRAME_LAT", _num(p.lat_deg))
        _sub(v, "FRAME_ROW", f"{p.row:g}")
        _sub(v, "FRAME_COL", f"{p.col:g}")
    raster_cs = _sub(root, "Raster_CS")
    _sub(raster_cs, "RASTER_CS_TYPE", "POINT")
    _sub(raster_cs, "PIXEL_ORIGIN", "1")
    prod = _sub(root, "Production")
    _sub(prod, "PRODUCT_TYPE", "SCENE1A")
    _sub(prod, "DATASET_PRODUCER_NAME", producer)
    src = _sub(_sub(_sub(root, "Dataset_Sources"), "Source_Information"), "Scene_Source")
    _sub(src, "IMAGING_DATE", utc(scene.centre_time_s)[:10])
    _sub(src, "IMAGING_TIME", utc(scene.centre_time_s)[11:19])
    _sub(src, "MISSION", "SPOT")
    _sub(src, "MISSION_INDEX", scene.mission_index)
    _sub(src, "INSTRUMENT", scene.instrument)
    _sub(src, "INSTRUMENT_INDEX", scene.instrument_index)
    _sub(src, "SENSOR_CODE", scene.sensor_code)
    _sub(src, "SCENE_PROCESSING_LEVEL", "1A")
    for tag, value in (("INCIDENCE_ANGLE", scene.incidence_deg),
                       ("VIEWING_ANGLE", scene.viewing_angle_deg),
                       ("SUN_AZIMUTH", scene.sun_azimuth_deg),
                       ("SUN_ELEVATION", scene.sun_elevation_deg)):
        if value is not None:
            _sub(src, tag, _num(value))
    dims = _sub(root, "Raster_Dimensions")
    _sub(dims, "NCOLS", scene.n_cols)
    _sub(dims, "NROWS", scene.n_rows)
    _sub(dims, "NBANDS", len(scene.look_angles))
    access = _sub(root, "Data_Access")
    _sub(access, "DATA_FILE_FORMAT", "GEOTIFF", version="1.0")
    _sub(_sub(access, "Data_File"), "DATA_FILE_PATH", href=image_name)
    strip = _sub(root, "Data_Strip")
    eph = _sub(strip, "Ephemeris")
    pts = _sub(eph, "Points")
    for t, p, v in zip(scene.orbit.times_s, scene.orbit.positions_m, scene.orbit.velocities_m_s,
                       strict=True):
        point = _sub(pts, "Point")
        _sub(point, "TIME", utc(t))
        for tag, vec in (("Location", p), ("Velocity", v)):
            el = _sub(point, tag)
            for k, x in zip("XYZ", vec, strict=True):
                _sub(el, k, _num(x))
    _sub(eph, "DORIS_USED", "N")
    att = _sub(strip, "Satellite_Attitudes")

    def angle_list(parent: ET.Element, tag: str, a: SpotAngles) -> None:
        for i in range(a.times_s.size):
            el = _sub(parent, tag)
            _sub(el, "TIME", utc(a.times_s[i]))
            for k in ("YAW", "PITCH", "ROLL"):
                _sub(el, k, _num(getattr(a, k.lower())[i]))
            _sub(el, "OUT_OF_RANGE", "Y" if a.out_of_range[i] else "N")

    if scene.aocs_angles is not None or scene.aocs_speeds is not None:
        aocs = _sub(_sub(att, "Raw_Attitudes"), "Aocs_Attitude")
        if scene.aocs_angles is not None:
            angle_list(_sub(aocs, "Angles_List"), "Angles", scene.aocs_angles)
        if scene.aocs_speeds is not None:
            angle_list(_sub(aocs, "Angular_Speeds_List"), "Angular_Speeds", scene.aocs_speeds)
    if scene.corrected_attitude is not None:
        corr = _sub(_sub(att, "Corrected_Attitudes"), "Corrected_Attitude")
        angle_list(corr, "Angles", scene.corrected_attitude)
    sensor = _sub(strip, "Sensor_Configuration")
    stamp = _sub(sensor, "Time_Stamp")
    _sub(stamp, "LINE_PERIOD", _num(scene.line_period_s))
    _sub(stamp, "SCENE_CENTER_TIME", utc(scene.centre_time_s))
    _sub(stamp, "SCENE_CENTER_LINE", f"{scene.centre_line:g}")
    _sub(stamp, "SCENE_CENTER_COL", f"{round(0.5 * (scene.n_cols + 1)):d}")
    look_list = _sub(sensor, "Instrument_Look_Angles_List")
    for la in scene.look_angles:
        block = _sub(look_list, "Instrument_Look_Angles")
        _sub(block, "BAND_INDEX", la.band_index)
        rows = _sub(block, "Look_Angles_List")
        for d, px, py in zip(la.detector_ids, la.psi_x_rad, la.psi_y_rad, strict=True):
            row = _sub(rows, "Look_Angles")
            _sub(row, "DETECTOR_ID", int(d))
            _sub(row, "PSI_X", _num(px))
            _sub(row, "PSI_Y", _num(py))
    ET.indent(root, space="  ")
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"
