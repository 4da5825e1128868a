"""Ground points with their image coordinates: value objects that serialise to JSON.

Ground: WGS84 ``lon_deg``, ``lat_deg``, ellipsoidal ``h_m`` (orthometric heights are named
``H_*``). Image coordinates: ``(col, row)``, 0-based, pixel centres at integers.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from core.errors import InputError


@dataclass(frozen=True)
class GeoPoint:
    """A WGS84 point: degrees and ellipsoidal metres."""

    lon_deg: float
    lat_deg: float
    h_m: float

    def to_list(self) -> list[float]:
        return [self.lon_deg, self.lat_deg, self.h_m]

    @classmethod
    def from_list(cls, v: Any) -> GeoPoint:
        try:
            lon, lat, h = (float(x) for x in v)
        except (TypeError, ValueError) as exc:
            raise InputError(
                f"a ground point must be [lon_deg, lat_deg, h_m], got {v!r:.80}") from exc
        return cls(lon, lat, h)


@dataclass(frozen=True)
class ImagePoint:
    """A position in one image, pixels: ``col`` across track, ``row`` along track."""

    col: float
    row: float

    def to_dict(self) -> dict[str, float]:
        return {"col": self.col, "row": self.row}

    @classmethod
    def from_dict(cls, d: Any) -> ImagePoint:
        try:
            return cls(float(d["col"]), float(d["row"]))
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(
                f"an image point must be {{'col': c, 'row': r}}, got {d!r:.80}") from exc


@dataclass(frozen=True, eq=False)
class CheckPoint:
    """An independent check point: ground truth and its true position in each image.

    ``x_m``, ``y_m`` are its projected coordinates in the CRS of the set it belongs to;
    ``H_egm96_m`` its orthometric height; ``image_points`` maps image names to positions.
    """

    id: int
    lon_deg: float
    lat_deg: float
    h_m: float
    H_egm96_m: float
    x_m: float
    y_m: float
    land_cover: str
    image_points: Mapping[str, ImagePoint] = field(default_factory=dict)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, CheckPoint):
            return NotImplemented
        return self.to_dict() == other.to_dict()

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: the scalar fields, then one ``{col, row}`` object per image name."""
        return {
            "id": self.id, "lon_deg": self.lon_deg, "lat_deg": self.lat_deg, "h_m": self.h_m,
            "H_egm96_m": self.H_egm96_m, "x_m": self.x_m, "y_m": self.y_m,
            "land_cover": self.land_cover,
            **{name: p.to_dict() for name, p in self.image_points.items()},
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], image_names: tuple[str, ...]) -> CheckPoint:
        try:
            return cls(
                id=int(d["id"]), lon_deg=float(d["lon_deg"]), lat_deg=float(d["lat_deg"]),
                h_m=float(d["h_m"]), H_egm96_m=float(d["H_egm96_m"]), x_m=float(d["x_m"]),
                y_m=float(d["y_m"]), land_cover=str(d["land_cover"]),
                image_points={n: ImagePoint.from_dict(d[n]) for n in image_names},
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f"check point record {dict(d)!r:.120} lacks or mistypes {exc}; "
                             "give the file written by gcpfree simulate") from exc


@dataclass(frozen=True)
class CheckPointSet:
    """Check points of a scene: the projected CRS of their ``x_m``/``y_m`` and the images."""

    crs: str
    images: tuple[str, ...]
    points: tuple[CheckPoint, ...]

    HEIGHTS = "h_m WGS84 ellipsoidal, H_egm96_m orthometric"
    IMAGE_COORDINATES = "0-based, pixel centres at integers, (col, row)"

    def to_dict(self) -> dict[str, Any]:
        return {
            "crs": self.crs, "heights": self.HEIGHTS, "image_coordinates": self.IMAGE_COORDINATES,
            "images": list(self.images), "points": [p.to_dict() for p in self.points],
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> CheckPointSet:
        try:
            images = tuple(str(n) for n in d["images"])
            return cls(crs=str(d["crs"]), images=images,
                       points=tuple(CheckPoint.from_dict(p, images) for p in d["points"]))
        except (KeyError, TypeError) as exc:
            raise InputError(f"check point file lacks {exc}; give the checkpoints.json written "
                             "by gcpfree simulate") from exc


@dataclass(frozen=True, eq=False)
class ControlPoint:
    """A ground control point: ground coordinates, its measured position in each image, its
    ground precision (``sigma_xy_m`` horizontal, ``sigma_h_m`` vertical) and where it came
    from (``source``, e.g. ``"srtm_surface_match"``, with the matching window's figures in
    ``provenance``)."""

    id: int
    lon_deg: float
    lat_deg: float
    h_m: float
    image_points: Mapping[str, ImagePoint]
    sigma_xy_m: float
    sigma_h_m: float
    source: str = ""
    provenance: Mapping[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {
            "id": self.id, "lon_deg": self.lon_deg, "lat_deg": self.lat_deg, "h_m": self.h_m,
            "images": {n: p.to_dict() for n, p in self.image_points.items()},
            "sigma_xy_m": self.sigma_xy_m, "sigma_h_m": self.sigma_h_m, "source": self.source,
            "provenance": dict(self.provenance),
        }

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, ControlPoint):
            return NotImplemented
        return self.to_dict() == other.to_dict()

    __hash__ = None  # type: ignore[assignment]


@dataclass(frozen=True)
class GcpSet:
    """The gcps.json document: its envelope (constants) and the GCPs; written and read by
    :data:`tasks.io.products.GCPS`."""

    format: str = "gcpfree.gcps"
    version: int = 1
    heights: str = "h_m WGS84 ellipsoidal"
    image_coordinates: str = CheckPointSet.IMAGE_COORDINATES
    points: tuple[ControlPoint, ...] = ()


def control_points_to_dict(points: tuple[ControlPoint, ...]) -> dict[str, Any]:
    """The gcps.json document as ``tasks.absolute.orientation`` writes it today; the one
    reader (and the writer to move to) is :data:`tasks.io.products.GCPS`, which writes the
    same (``tests/tasks/test_documents.py``)."""
    return {"format": "gcpfree.gcps", "version": 1,
            "heights": "h_m WGS84 ellipsoidal",
            "image_coordinates": "0-based, pixel centres at integers, (col, row)",
            "points": [p.to_dict() for p in points]}
