"""Scene and stereo-pair geometry read from any sensor model: ground corners, viewing angles,
ground sample distance, acquisition time, mean terrain height, and for two models the
convergence angle, B/H and the overlap of their footprints.

Everything goes through the :class:`~core.sensors.base.SensorModel` protocol (``localize``
and ``project``), so RPC and rigorous models are treated alike:

- the line of sight of an image point is the straight line through its ground points at two
  heights (``h - dh/2`` and ``h + dh/2``); for a pushbroom model it passes exactly through the
  satellite, for an RPC it is the RPC's own approximation of the ray; a model with a
  ``line_of_sight_ecef(col, row, h)`` method (SAR: its ground points at other heights move
  along the range circle, not towards the sensor) gives it directly;
- incidence is the angle at the ground point between the ellipsoid normal and the direction to
  the satellite, azimuth that direction's bearing, clockwise from north; the across-track
  incidence is the incidence in the vertical plane across the image's own along-track
  direction (the ground direction of increasing rows), positive when the satellite is west of
  the point (the view looks east), negative when it is east (SPOT's sign);
- ground sample distances are ECEF distances between the ground points (at height h) of the
  pixel centres half a pixel either side of the point, across (columns) and along (rows);
- footprints are the ground polygons of the four corner pixels at a height, compared in the
  local East-North plane of the first image's centre.

Angles in degrees, distances in metres, heights WGS84 ellipsoidal. No I/O here.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import UTC, datetime, timedelta

import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.dem import GeoDEM
from core.errors import CoverageError, GeometryError, InputError
from core.geodesy import (
    ecef_to_geodetic,
    enu_rotation,
    enu_to_geodetic,
    geodetic_to_ecef,
    geodetic_to_enu,
    incidence_angles,
)
from core.intersection import intersect_two_rays, lines_of_sight
from core.sensors.base import SensorModel
from core.sensors.pushbroom import PushbroomModel

FloatArray = NDArray[np.float64]
LOS_SPAN_M = 1000.0  # height span of the two points that define a line of sight
AREA_TOL = 1e-12  # relative: polygons smaller than this fraction of the first have no area


@dataclass(frozen=True)
class GroundCorner:
    """An image corner pixel (0-based centre) and its ground point (degrees) at height ``h_m``."""

    col: float
    row: float
    lon_deg: float
    lat_deg: float
    h_m: float


@dataclass(frozen=True, eq=False)
class PointGeometry:
    """Viewing geometry at image points (arrays of the shape of the input points).

    ``los_ecef`` (..., 3) is the unit vector from the ground point towards the sensor.
    """

    lon_deg: FloatArray
    lat_deg: FloatArray
    h_m: FloatArray
    incidence_deg: FloatArray
    across_track_incidence_deg: FloatArray
    azimuth_deg: FloatArray
    gsd_across_m: FloatArray
    gsd_along_m: FloatArray
    los_ecef: FloatArray


@dataclass(frozen=True)
class SceneGeometry:
    """One image at one height: its corners, and the view from its centre pixel.

    ``corners`` are the pixels (0, 0), (cols-1, 0), (cols-1, rows-1), (0, rows-1) in that order;
    ``area_km2`` the area of their quadrilateral; ``acquisition_utc`` the time of the centre
    row (pushbroom models with an orbit epoch), ISO 8601 UTC, else None.
    """

    n_cols: int
    n_rows: int
    h_m: float
    corners: tuple[GroundCorner, ...]
    centre_col: float
    centre_row: float
    centre_lon_deg: float
    centre_lat_deg: float
    incidence_deg: float
    across_track_incidence_deg: float
    azimuth_deg: float
    gsd_across_m: float
    gsd_along_m: float
    area_km2: float
    acquisition_utc: str | None


@dataclass(frozen=True)
class TerrainHeight:
    """Mean terrain height under an image footprint and the share of samples the DEM gave."""

    mean_h_m: float
    covered_pct: float
    n_samples: int


@dataclass(frozen=True)
class PairGeometry:
    """Stereo geometry of two images at a common ground point, the centroid of their overlap.

    ``convergence_deg`` is the angle between the two lines of sight at that point;
    ``b_over_h = 2 tan(convergence / 2)``: the base-to-height ratio of a symmetric pair with the
    same convergence (for views on either side of the vertical in one plane, flat Earth, it
    equals ``tan i1 + tan i2`` only when ``i1 = i2``). ``overlap_pct`` is the area of the
    intersection of the two footprints (corner quadrilaterals at ``h_m``) over the area of the
    first footprint, in percent; ``overlap_area_m2`` that intersection's area.
    """

    h_m: float
    lon_deg: float
    lat_deg: float
    col1: float
    row1: float
    col2: float
    row2: float
    convergence_deg: float
    b_over_h: float
    overlap_pct: float
    incidence1_deg: float
    azimuth1_deg: float
    incidence2_deg: float
    azimuth2_deg: float
    overlap_area_m2: float = float("nan")


# ------------------------------------------------------------------------- one image


def image_corners_px(n_cols: int, n_rows: int) -> tuple[FloatArray, FloatArray]:
    """(col, row) of the corner pixels (0, 0), (cols-1, 0), (cols-1, rows-1), (0, rows-1)."""
    if n_cols < 1 or n_rows < 1:
        raise InputError(f"image size {n_cols}x{n_rows} px is empty; give cols, rows >= 1")
    c1, r1 = float(n_cols - 1), float(n_rows - 1)
    return np.array([0.0, c1, c1, 0.0]), np.array([0.0, 0.0, r1, r1])


def point_geometry(model: SensorModel, col: ArrayLike, row: ArrayLike, h_m: ArrayLike, *,
                   dh_m: float = LOS_SPAN_M) -> PointGeometry:
    """Viewing angles and ground sample distances at image points (col, row) at heights h_m.

    The line of sight is taken through the ground points at ``h - dh_m/2`` and ``h + dh_m/2``;
    the GSD from the ground points at ``col +- 0.5`` and ``row +- 0.5`` at ``h``. All in one
    vectorised ``localize`` call. See the module docstring for the angle conventions.
    """
    if not dh_m > 0:
        raise InputError(f"dh_m must be > 0 m, got {dh_m}")
    c, r, h = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (col, row, h_m)))
    shape, n = c.shape, c.size
    c, r, h = c.ravel(), r.ravel(), h.ravel()
    # 0: the point, 1-2: col -+ 0.5, 3-4: row -+ 0.5, 5-6: h -+ dh/2
    dc = np.array([0.0, -0.5, 0.5, 0.0, 0.0, 0.0, 0.0])[:, None]
    dr = np.array([0.0, 0.0, 0.0, -0.5, 0.5, 0.0, 0.0])[:, None]
    dz = np.array([0.0, 0.0, 0.0, 0.0, 0.0, -0.5, 0.5])[:, None] * dh_m
    cc, rr, hh = (c + dc).ravel(), (r + dr).ravel(), (h + dz).ravel()
    lon, lat = model.localize(cc, rr, hh)
    p = np.stack(geodetic_to_ecef(lon, lat, hh), axis=-1).reshape(7, n, 3)
    d_col, d_row, up = p[2] - p[1], p[4] - p[3], p[6] - p[5]
    los = up / np.linalg.norm(up, axis=-1, keepdims=True)
    own_los = getattr(model, "line_of_sight_ecef", None)
    if callable(own_los):
        los = np.asarray(own_los(c, r, h), dtype=np.float64).reshape(n, 3)
    lon0, lat0 = lon[:n], lat[:n]
    # incidence and across-track incidence as core.geodesy defines them, with the image's
    # along-track direction (d_row) standing for the ground track
    inc, across, _ = incidence_angles(p[0] + los, d_row, p[0], lon0, lat0)
    rot = enu_rotation(lon0, lat0)
    east, north = np.einsum("nj,nj->n", rot[:, 0], los), np.einsum("nj,nj->n", rot[:, 1], los)
    azimuth = np.degrees(np.arctan2(east, north)) % 360.0

    def out(a: FloatArray) -> FloatArray:
        return np.asarray(a, dtype=np.float64).reshape(shape)

    return PointGeometry(
        lon_deg=out(lon0), lat_deg=out(lat0), h_m=out(h), incidence_deg=out(np.degrees(inc)),
        across_track_incidence_deg=out(np.degrees(across)), azimuth_deg=out(azimuth),
        gsd_across_m=out(np.linalg.norm(d_col, axis=-1)),
        gsd_along_m=out(np.linalg.norm(d_row, axis=-1)), los_ecef=los.reshape(shape + (3,)),
    )


def along_track_heading_deg(model: SensorModel, col: ArrayLike, row: ArrayLike,
                            h_m: ArrayLike) -> FloatArray:
    """Bearing (degrees clockwise from north, 0-360) of the ground direction of increasing
    rows at image points (col, row) at heights h_m: the along-track direction of a pushbroom
    image (its platform's ground track, Earth rotation included), the scan direction of any
    image. Taken between the ground points of ``row -+ 0.5``, in the local East-North plane."""
    c, r, h = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (col, row, h_m)))
    shape, c, r, h = c.shape, c.ravel(), r.ravel(), h.ravel()
    lon, lat = model.localize(np.concatenate([c, c]), np.concatenate([r - 0.5, r + 0.5]),
                              np.concatenate([h, h]))
    p = np.stack(geodetic_to_ecef(lon, lat, np.concatenate([h, h])), axis=-1)
    d = p[c.size:] - p[:c.size]
    lon0, lat0, _ = ecef_to_geodetic(*(0.5 * (p[c.size:] + p[:c.size])).T)
    rot = enu_rotation(lon0, lat0)
    east, north = np.einsum("nj,nj->n", rot[:, 0], d), np.einsum("nj,nj->n", rot[:, 1], d)
    return (np.degrees(np.arctan2(east, north)) % 360.0).reshape(shape)


def bearing_difference_deg(a_deg: ArrayLike, b_deg: ArrayLike) -> FloatArray:
    """The smaller angle between two bearings (degrees, 0-180)."""
    d = np.abs(np.asarray(a_deg, dtype=np.float64) - np.asarray(b_deg, dtype=np.float64))
    d = d % 360.0
    return np.minimum(d, 360.0 - d)


def acquisition_time_utc(model: SensorModel, row: float) -> str | None:
    """UTC time (ISO 8601, microseconds, ``Z``) at which ``row`` was acquired, for a pushbroom
    model whose orbit has an ``epoch_utc`` (its epoch plus the row's line time), for a SAR
    model (the row's azimuth time); else None."""
    times_of_image = getattr(model, "times_of_image", None)
    if callable(times_of_image) and getattr(model, "orbit", None) is not None:
        return model.utc_of_times(times_of_image(0.0, row)[0])[0]  # type: ignore[attr-defined]
    if not isinstance(model, PushbroomModel) or not model.orbit.epoch_utc:
        return None
    text = model.orbit.epoch_utc.strip()
    try:
        epoch = datetime.fromisoformat(text.replace("Z", "+00:00"))
    except ValueError as exc:
        raise InputError(f"orbit epoch_utc {text!r} is not an ISO 8601 time; write it like "
                         "2024-06-01T10:00:00Z") from exc
    if epoch.tzinfo is None:
        epoch = epoch.replace(tzinfo=UTC)
    t = epoch.astimezone(UTC) + timedelta(seconds=float(model.line_time_s(row)))
    return t.strftime("%Y-%m-%dT%H:%M:%S.%fZ")


def _enu_polygon(lon_deg: FloatArray, lat_deg: FloatArray, h_m: float,
                 origin: tuple[float, float, float]) -> FloatArray:
    """(k, 2) East, North metres of ground points in the local frame at ``origin``, made
    counter-clockwise."""
    e, n, _ = geodetic_to_enu(lon_deg, lat_deg, np.full(np.shape(lon_deg), h_m), origin)
    poly = np.stack([e, n], axis=-1)
    return poly if signed_area(poly) >= 0 else poly[::-1]


def scene_geometry(model: SensorModel, n_cols: int, n_rows: int, h_m: float = 0.0
                   ) -> SceneGeometry:
    """Corners, centre view (angles, GSD), footprint area and acquisition time at height h_m."""
    col, row = image_corners_px(n_cols, n_rows)
    h_m = float(h_m)
    lon, lat = model.localize(col, row, np.full(4, h_m))
    cc, cr = 0.5 * (n_cols - 1), 0.5 * (n_rows - 1)
    g = point_geometry(model, cc, cr, h_m)
    centre = (float(g.lon_deg), float(g.lat_deg), h_m)
    area_m2 = signed_area(_enu_polygon(lon, lat, h_m, centre))
    return SceneGeometry(
        n_cols=int(n_cols), n_rows=int(n_rows), h_m=h_m,
        corners=tuple(GroundCorner(float(c), float(r), float(lo), float(la), h_m)
                      for c, r, lo, la in zip(col, row, lon, lat, strict=True)),
        centre_col=cc, centre_row=cr, centre_lon_deg=centre[0], centre_lat_deg=centre[1],
        incidence_deg=float(g.incidence_deg),
        across_track_incidence_deg=float(g.across_track_incidence_deg),
        azimuth_deg=float(g.azimuth_deg), gsd_across_m=float(g.gsd_across_m),
        gsd_along_m=float(g.gsd_along_m), area_km2=area_m2 / 1e6,
        acquisition_utc=acquisition_time_utc(model, cr),
    )


def footprint_mean_height_m(model: SensorModel, n_cols: int, n_rows: int, dem: GeoDEM, *,
                            h0_m: float = 0.0, n_side: int = 21, n_iter: int = 5
                            ) -> TerrainHeight:
    """Mean DEM height under the image: an ``n_side`` x ``n_side`` grid of pixels over the whole
    image, each localised at the DEM height under its previous ground point (starting at
    ``h0_m``; points the DEM does not give take the current mean) for ``n_iter`` rounds.

    Raises:
        CoverageError: the DEM gives no height under any sample.
    """
    if n_side < 2 or n_iter < 1:
        raise InputError(f"n_side {n_side} must be >= 2 and n_iter {n_iter} >= 1")
    c, r = np.meshgrid(np.linspace(0, n_cols - 1, n_side), np.linspace(0, n_rows - 1, n_side))
    c, r = c.ravel(), r.ravel()
    h = np.full(c.size, float(h0_m))
    mean, ok = float(h0_m), np.zeros(c.size, dtype=bool)
    for _ in range(n_iter):
        lon, lat = model.localize(c, r, h)
        z = dem.height_m(lon, lat)
        ok = np.isfinite(z)
        if not ok.any():
            raise CoverageError(
                "the DEM gives no height under the image footprint; give a reference DEM "
                "(EPSG:4326) that covers the scene")
        mean = float(np.mean(z[ok]))
        h = np.where(ok, z, mean)
    return TerrainHeight(mean_h_m=mean, covered_pct=100.0 * float(ok.mean()), n_samples=c.size)


# ------------------------------------------------------------------------- polygons


def signed_area(poly: ArrayLike) -> float:
    """Shoelace area of a polygon (k, 2): positive when its vertices turn counter-clockwise."""
    p = np.asarray(poly, dtype=np.float64)
    if p.shape[0] < 3:
        return 0.0
    x, y = p[:, 0], p[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def clip_convex(subject: ArrayLike, clip: ArrayLike) -> FloatArray:
    """Sutherland-Hodgman: the part of polygon ``subject`` (k, 2) inside the convex polygon
    ``clip`` (m, 2). Both counter-clockwise; returns (j, 2), j = 0 when they do not overlap."""
    out = np.asarray(subject, dtype=np.float64).reshape(-1, 2)
    edges = np.asarray(clip, dtype=np.float64).reshape(-1, 2)
    for a, b in zip(edges, np.roll(edges, -1, axis=0), strict=True):
        if out.shape[0] == 0:
            break
        d = b - a
        side = d[0] * (out[:, 1] - a[1]) - d[1] * (out[:, 0] - a[0])  # >= 0: left = inside
        kept: list[FloatArray] = []
        for i in range(out.shape[0]):
            j = i - 1  # previous vertex (wraps to the last)
            if side[i] >= 0:
                if side[j] < 0:
                    kept.append(out[j] + side[j] / (side[j] - side[i]) * (out[i] - out[j]))
                kept.append(out[i])
            elif side[j] >= 0:
                kept.append(out[j] + side[j] / (side[j] - side[i]) * (out[i] - out[j]))
        out = np.array(kept).reshape(-1, 2)
    return out


def polygon_centroid(poly: ArrayLike) -> tuple[float, float]:
    """Area centroid (x, y) of a non-degenerate polygon (k, 2)."""
    p = np.asarray(poly, dtype=np.float64)
    x, y = p[:, 0] - p[0, 0], p[:, 1] - p[0, 1]  # relative to a vertex: well conditioned
    cross = x * np.roll(y, -1) - np.roll(x, -1) * y
    a = 0.5 * np.sum(cross)
    if a == 0:
        raise GeometryError("the polygon has no area; it has no centroid")
    cx = np.sum((x + np.roll(x, -1)) * cross) / (6.0 * a)
    cy = np.sum((y + np.roll(y, -1)) * cross) / (6.0 * a)
    return float(cx + p[0, 0]), float(cy + p[0, 1])


# ------------------------------------------------------------------------- two images


def pair_geometry(model1: SensorModel, size1: tuple[int, int], model2: SensorModel,
                  size2: tuple[int, int], h_m: float = 0.0) -> PairGeometry:
    """Convergence, B/H and overlap of two images (sizes (cols, rows)) at height ``h_m``.

    The footprints (corner quadrilaterals at ``h_m``) are compared in the East-North plane of
    the first image's centre; the common point is the area centroid of their intersection,
    projected into both images, where both lines of sight are taken.

    Raises:
        GeometryError: the footprints do not overlap at ``h_m``.
    """
    h_m = float(h_m)
    polys = []
    origin: tuple[float, float, float] | None = None
    for model, (n_cols, n_rows) in ((model1, size1), (model2, size2)):
        col, row = image_corners_px(n_cols, n_rows)
        lon, lat = model.localize(col, row, np.full(4, h_m))
        if origin is None:
            lo, la = model.localize(0.5 * (n_cols - 1), 0.5 * (n_rows - 1), h_m)
            origin = (float(lo), float(la), h_m)
        polys.append(_enu_polygon(lon, lat, h_m, origin))
    area1 = signed_area(polys[0])
    inter = clip_convex(polys[0], polys[1])
    area = signed_area(inter)
    if area <= AREA_TOL * area1:
        raise GeometryError(
            f"the two image footprints do not overlap at h = {h_m:g} m; give two images of "
            "the same area (check the models: a wrong model puts an image elsewhere)")
    e, n = polygon_centroid(inter)
    lon, lat, _ = enu_to_geodetic(e, n, 0.0, origin)  # type: ignore[arg-type]
    c1, r1 = model1.project(lon, lat, h_m)
    c2, r2 = model2.project(lon, lat, h_m)
    g1 = point_geometry(model1, c1, r1, h_m)
    g2 = point_geometry(model2, c2, r2, h_m)
    u1, u2 = g1.los_ecef.reshape(3), g2.los_ecef.reshape(3)
    conv = float(np.arctan2(np.linalg.norm(np.cross(u1, u2)), float(u1 @ u2)))
    return PairGeometry(
        h_m=h_m, lon_deg=float(lon), lat_deg=float(lat), col1=float(c1), row1=float(r1),
        col2=float(c2), row2=float(r2), convergence_deg=float(np.degrees(conv)),
        b_over_h=2.0 * float(np.tan(0.5 * conv)), overlap_pct=100.0 * min(area / area1, 1.0),
        incidence1_deg=float(g1.incidence_deg), azimuth1_deg=float(g1.azimuth_deg),
        incidence2_deg=float(g2.incidence_deg), azimuth2_deg=float(g2.azimuth_deg),
        overlap_area_m2=float(area),
    )


def centre_rays_height_m(model1: SensorModel, size1: tuple[int, int], model2: SensorModel,
                         size2: tuple[int, int], h_m: float = 0.0, *,
                         dh_m: float = LOS_SPAN_M) -> tuple[float, float]:
    """(h_m, miss_m): the ellipsoidal height where the lines of sight of the two images' centre
    pixels come closest (midpoint of their common perpendicular), and their distance there.

    The lines are taken through the ground points at ``h_m -+ dh_m/2``. For two images centred
    on the same ground point this is that point's height; otherwise it can be anything.

    Raises:
        GeometryError: the two lines of sight are parallel.
    """
    rays = [lines_of_sight(m, 0.5 * (c - 1), 0.5 * (r - 1), h_m - 0.5 * dh_m, h_m + 0.5 * dh_m)
            for m, (c, r) in ((model1, size1), (model2, size2))]
    res = intersect_two_rays(rays[0][0], rays[0][1], rays[1][0], rays[1][1])
    p = res.point_ecef[0]
    if not np.all(np.isfinite(p)):
        raise GeometryError("the centre lines of sight of the two images are parallel; they "
                            "do not fix a height")
    _, _, h = ecef_to_geodetic(*p)
    return float(h), float(res.miss_m[0])
