"""What windows.json holds (step 3): every window tried with its centre tie point, the count
per status and the GCPs made from the good ones; written and read by
:data:`tasks.io.products.WINDOWS`."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from core.matching.surface import WindowMatch
from core.points import ControlPoint, GcpSet


@dataclass(frozen=True)
class WindowTried:
    """One window of windows.json: the index of its centre tie point and its match (whose
    keys the file writes beside ``tie_point``)."""

    tie_point: int
    match: WindowMatch


@dataclass(frozen=True)
class WindowsFile:
    """windows.json: every window tried, how many ended in each status (``counts``, by status
    name, in the order they first occur) and the GCPs made from the good ones (as gcps.json
    holds them)."""

    windows: tuple[WindowTried, ...]
    counts: Mapping[str, int]
    gcps: GcpSet

    @classmethod
    def of(cls, centres: ArrayLike, matches: Sequence[WindowMatch],
           gcps: Sequence[ControlPoint]) -> WindowsFile:
        """The document of windows centred on the tie points ``centres`` (indices)."""
        counts: dict[str, int] = {}
        for m in matches:
            counts[m.status.name] = counts.get(m.status.name, 0) + 1
        return cls(tuple(WindowTried(int(c), m)
                         for c, m in zip(np.asarray(centres), matches, strict=True)),
                   counts, GcpSet(points=tuple(gcps)))
