"""When and by which satellite a scene was acquired, from what its product states.

- a SPOT 1-5 ``.DIM`` (and the simulator's): the mission and instrument it names, and the
  time its model gives the centre row (the DIMAP's scene centre time and line period);
- a gcpfree pushbroom ``.json``: the centre row's time from its orbit epoch;
- an RPC product: an OSSIM ``.geom``'s ``support_data.time_range_start``/``_end`` (their
  middle) and ``support_data.sensorID``, else the datastrip named in the GeoTIFF's GML
  metadata (``DS_PHR1B_201308051041444_...``: Pleiades and SPOT 6-7 products, the strip's
  start to the tenth of a second). An RPC alone states neither: both unknown (None).

Plain functions, no Prefect (``gcpfree scenes`` reads many products in seconds).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

from core.sensors.viewing import acquisition_time_utc
from tasks.io.rasters import open_raster
from tasks.io.sensors import LoadedModel

#: a Pleiades / SPOT 6-7 datastrip id: DS_<satellite>_<YYYYMMDDHHMMSS><tenths>_...
_DATASTRIP = re.compile(r"DS_(?P<sat>[A-Z0-9]+)_(?P<t>\d{14})(?P<tenth>\d)?_")
_GEOM_KEY = re.compile(r"^\s*(?P<key>[\w.]+)\s*:\s*(?P<value>.*?)\s*$")


@dataclass(frozen=True)
class Acquisition:
    """``utc``: ISO 8601 with ``Z``, or None when the product does not say; ``satellite``
    and ``instrument`` as the product names them (None when it does not); ``source``: what
    stated the time."""

    utc: str | None
    satellite: str | None = None
    instrument: str | None = None
    source: str = "not stated by the product"

    @property
    def datetime(self) -> datetime | None:
        if self.utc is None:
            return None
        return datetime.fromisoformat(self.utc).astimezone(UTC)


def _iso(t: datetime) -> str:
    return t.astimezone(UTC).strftime("%Y-%m-%dT%H:%M:%S.%fZ")


def _parse_time(text: str) -> datetime | None:
    try:
        t = datetime.fromisoformat(text.strip())
    except ValueError:
        # more than six decimals of seconds (OSSIM writes seven): keep six
        m = re.fullmatch(r"(.*\.\d{6})\d*(Z|[+-]\d\d:?\d\d)?", text.strip())
        if m is None:
            return None
        return _parse_time(m[1] + (m[2] or ""))
    return t if t.tzinfo is not None else t.replace(tzinfo=UTC)


def _geom_acquisition(path: Path) -> Acquisition | None:
    """An OSSIM keyword list's time range and sensor, None when it states no time."""
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError:
        return None
    keys = {m["key"]: m["value"] for line in text.splitlines() if (m := _GEOM_KEY.match(line))}
    t0 = _parse_time(keys.get("support_data.time_range_start", ""))
    t1 = _parse_time(keys.get("support_data.time_range_end", "")) or t0
    if t0 is None or t1 is None:
        return None
    sensor = keys.get("support_data.sensorID", "").replace(" ", "") or None
    return Acquisition(_iso(t0 + (t1 - t0) / 2), sensor, None,
                       f"{path.name}: middle of support_data.time_range")


def _datastrip_acquisition(image: Path) -> Acquisition | None:
    """The datastrip a Pleiades / SPOT 6-7 GeoTIFF names in its GML metadata."""
    try:
        with open_raster(image, "image") as src:
            text = " ".join(src.tags().values())
    except Exception:  # noqa: BLE001 - unreadable here means only: no date stated
        return None
    m = _DATASTRIP.search(text)
    if m is None:
        return None
    try:
        t = datetime.strptime(m["t"], "%Y%m%d%H%M%S").replace(tzinfo=UTC)
    except ValueError:
        return None
    if m["tenth"]:
        t = t.replace(microsecond=100_000 * int(m["tenth"]))
    return Acquisition(_iso(t), m["sat"], None,
                       f"{image.name}: start of datastrip {m[0].rstrip('_')}")


def acquisition_of(loaded: LoadedModel) -> Acquisition:
    """When and by which satellite the scene of ``loaded`` was acquired (see the module
    docstring for what each product says)."""
    model, spot = loaded.model, loaded.spot
    centre_row = 0.5 * (loaded.size[1] - 1)
    if loaded.family == "pushbroom":
        utc = acquisition_time_utc(model, centre_row)
        if spot is not None:
            return Acquisition(utc, f"SPOT {spot.mission_index}",
                               f"{spot.instrument} {spot.instrument_index}",
                               f"{loaded.source.name}: scene centre time")
        return Acquisition(utc, source=f"{loaded.source.name}: orbit epoch and line time"
                           if utc else "not stated by the product")
    if loaded.source.suffix.lower() == ".geom":
        found = _geom_acquisition(loaded.source)
        if found is not None:
            return found
    if loaded.image is not None:
        found = _datastrip_acquisition(loaded.image)
        if found is not None:
            return found
    return Acquisition(None)
