"""Where images lie on the ground before anything is measured: the heights a scene may have and
the lon/lat box of footprints, one rule each for every step.

- **Heights.** A model that states the heights it is valid for (an RPC's ``HEIGHT_OFF`` +-
  ``HEIGHT_SCALE``) bounds the scene; a rigorous model states none, and then any terrain on
  Earth may be under it (:data:`ANY_TERRAIN_H_M`) until a reference DEM says more.
- **Boxes.** The footprint of an image (or of a window of its pixels) over a height range, as
  a lon/lat box widened by :data:`FOOTPRINT_MARGIN_M`: the metadata of an archive scene may put
  the ground up to about a kilometre from where it is (SPOT 1-4 attitude biases: 100-300 m at
  the scene centre, more at the corners with the rates; the simulator draws the same), so a
  reference DEM or an SRTM mosaic read over the box still covers the true ground. A step that
  searches further (surface matching's shifts) widens the box by its own range on top.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from core.errors import InputError
from core.geodesy import BBox, metres_per_degree
from core.sensors.base import SensorModel

FloatArray = NDArray[np.float64]

#: ellipsoidal heights any terrain may have: from the lowest dry land (the Dead Sea shore,
#: -430 m, where the geoid is +20 m) to above Everest (8849 m, geoid about -30 m)
ANY_TERRAIN_H_M: tuple[float, float] = (-500.0, 9000.0)
#: how far from its footprint the true ground of an image may lie (see the module docstring)
FOOTPRINT_MARGIN_M = 1000.0

#: a window of an image's pixels: (col0, row0, col1, row1), half-open, 0-based
PixelBox = tuple[int, int, int, int]


def stated_height_range_m(model: SensorModel) -> tuple[float, float] | None:
    """The ellipsoidal heights a model says it is valid for: an RPC's offset +- scale (the
    normalisation of its heights); None for a model that states none (rigorous)."""
    off, scale = getattr(model, "alt_off", None), getattr(model, "alt_scale", None)
    if off is None or scale is None:
        return None
    return float(off) - abs(float(scale)), float(off) + abs(float(scale))


def scene_height_range_m(models: Sequence[SensorModel],
                         given: tuple[float, float] | None = None, *,
                         any_terrain: bool = True) -> tuple[float, float]:
    """The heights to assume under images before a DEM is read: ``given`` (checked), else the
    union of what the models state (:func:`stated_height_range_m`), else
    :data:`ANY_TERRAIN_H_M`, or with ``any_terrain=False`` an InputError asking for heights
    (a step that needs them tight, e.g. dense matching without a reference)."""
    if given is not None:
        lo, hi = map(float, given)
        if not (np.isfinite(lo) and np.isfinite(hi) and hi > lo):
            raise InputError(f"height range {tuple(given)} is empty; give MIN < MAX in "
                             "ellipsoidal metres (--height-range MIN MAX)")
        return lo, hi
    stated = [r for r in map(stated_height_range_m, models) if r is not None]
    if stated:
        return min(r[0] for r in stated), max(r[1] for r in stated)
    if any_terrain:
        return ANY_TERRAIN_H_M
    raise InputError("a rigorous (pushbroom) model states no terrain heights: give "
                     "--reference REF.tif, --srtm-dir DIR or --height-range MIN MAX")


def edge_pixels(box: PixelBox, n_side: int = 21) -> tuple[np.ndarray, np.ndarray]:
    """``n_side`` pixel centres along each edge of a pixel box (col, row)."""
    c0, r0, c1, r1 = box
    if not (c1 > c0 and r1 > r0):
        raise InputError(f"pixel box {box} is empty; give (col0, row0, col1, row1) with "
                         "col1 > col0 and row1 > row0")
    c = np.linspace(c0, c1 - 1, n_side)
    r = np.linspace(r0, r1 - 1, n_side)
    return (np.concatenate([c, c, np.full(n_side, c0), np.full(n_side, c1 - 1.0)]),
            np.concatenate([np.full(n_side, r0), np.full(n_side, r1 - 1.0), r, r]))


def footprint_lonlat(model: SensorModel, n_cols: int, n_rows: int, heights_m: Sequence[float],
                     n_side: int = 21, box: PixelBox | None = None
                     ) -> tuple[FloatArray, FloatArray]:
    """Ground (lon, lat) of ``n_side`` points along each edge of the image (columns
    0..n_cols-1, rows 0..n_rows-1, pixel centres), or of the pixel ``box`` when given, at each
    of ``heights_m``. The points of every height are concatenated: their bounds hold the
    footprint over that height range."""
    col, row = edge_pixels(box if box is not None else (0, 0, int(n_cols), int(n_rows)), n_side)
    lons, lats = [], []
    for h in heights_m:
        lon, lat = model.localize(col, row, np.full(col.shape, float(h)))
        lons.append(np.asarray(lon, dtype=np.float64))
        lats.append(np.asarray(lat, dtype=np.float64))
    return np.concatenate(lons), np.concatenate(lats)


def footprint_box(windows: Sequence[tuple[SensorModel, PixelBox]],
                  heights_m: Sequence[float], margin_m: float = FOOTPRINT_MARGIN_M) -> BBox:
    """The lon/lat box of the ground the pixel ``windows`` see (each a model and a box of its
    pixels, e.g. ``(0, 0, n_cols, n_rows)`` for a whole image) at every height of
    ``heights_m``, widened by ``margin_m`` on every side (metres, converted at the box's
    latitude)."""
    pts = [footprint_lonlat(model, 0, 0, heights_m, box=box) for model, box in windows]
    lon = np.concatenate([p[0] for p in pts])
    lat = np.concatenate([p[1] for p in pts])
    ok = np.isfinite(lon) & np.isfinite(lat)
    if not ok.any():
        raise InputError("no pixel of the images localises on the ground at the heights "
                         f"{tuple(heights_m)}; check the sensor models")
    lon, lat = lon[ok], lat[ok]
    lat_c = 0.5 * (float(lat.min()) + float(lat.max()))
    m_lon, m_lat = (float(v) for v in metres_per_degree(lat_c))
    d_lon, d_lat = margin_m / m_lon, margin_m / m_lat
    return BBox(max(float(lon.min()) - d_lon, -180.0), max(float(lat.min()) - d_lat, -90.0),
                min(float(lon.max()) + d_lon, 180.0), min(float(lat.max()) + d_lat, 90.0))
