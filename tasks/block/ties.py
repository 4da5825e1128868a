"""The block's tie points: the tracks of the joint relative orientation (every overlapping
pair's tie points chained through shared pixels, ``relative.tracks.json``) as the adjustment's
tie points, and each stereo pair's share of them as the surface matching takes them."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from core.orientation.ties import TieObservations
from core.orientation.tracks import Tracks
from core.sensors.base import SensorModel
from tasks.absolute.surface_match import TieGround
from tasks.io.rasters import read_json


def track_ground(models: Sequence[SensorModel], col: np.ndarray, row: np.ndarray,
                 source: np.ndarray, h_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each track's ground (lon, lat) on its source image's ray at its height."""
    lon, lat = np.full(h_m.size, np.nan), np.full(h_m.size, np.nan)
    for s in np.unique(source):
        sel = source == s
        lon[sel], lat[sel] = models[int(s)].localize(col[sel, s], row[sel, s], h_m[sel])
    return lon, lat


def read_tracks(path: str, models: Sequence[SensorModel], sigma_px: float
                ) -> tuple[TieObservations, Tracks]:
    """The inlier tracks of a ``relative.tracks.json`` as tie points (their ground on their
    source rays under ``models``, the joint relative orientation's) and as tracks."""
    doc = read_json(path, "tracks file", "run gcpfree block (or dsm --images) again")
    col = np.array(doc["col"], dtype=float)
    row = np.array(doc["row"], dtype=float)
    h = np.array(doc["h_m"], dtype=float)
    inlier = np.array(doc["inlier"], dtype=bool)
    source = np.array(doc["source"], dtype=np.intp)
    col, row, h, source = col[inlier], row[inlier], h[inlier], source[inlier]
    lon, lat = track_ground(models, col, row, source, h)
    return (TieObservations(col, row, lon, lat, h, sigma_px), Tracks(col, row, h))


def pair_ties(ties: TieObservations, i: int, j: int) -> TieGround:
    """The tie points seen in images ``i`` and ``j``, as one pair's (``i`` left)."""
    both = ties.seen[:, i] & ties.seen[:, j]
    return TieGround(ties.lon_deg[both], ties.lat_deg[both], ties.h_m[both],
                     ties.col[both, i], ties.row[both, i], ties.col[both, j],
                     ties.row[both, j], np.ones(int(both.sum())))
