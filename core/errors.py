"""One exception hierarchy for gcpfree.

Every message says what was wrong and what to do about it. The CLI prints
``str(error)`` on one line and exits non-zero for any :class:`GcpFreeError`.
"""

from __future__ import annotations


class GcpFreeError(Exception):
    """Base class of every error gcpfree raises on purpose."""


class InputError(GcpFreeError, ValueError):
    """An input file, metadata key or argument is missing, malformed or inconsistent."""


class CoverageError(InputError):
    """The data given do not cover the area asked for (e.g. SRTM tiles missing)."""


class GeometryError(GcpFreeError):
    """A geometric operation has no valid answer (ray misses the surface, no overlap...)."""


class ConvergenceError(GcpFreeError):
    """An iterative solver did not converge within its iteration budget."""


class InsufficientReliefError(GcpFreeError):
    """The terrain is too flat for surface matching to fix the horizontal position."""


class InsufficientDataError(GcpFreeError):
    """Too few tie points, check points or valid pixels to estimate what was asked."""
