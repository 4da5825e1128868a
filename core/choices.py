"""The string options' choices, each once: a ``Literal`` type for the configs that take it and
the tuple of its values for their checks and the command line's ``choices`` (the standard
library only, so that ``gcpfree --help`` builds its parser without NumPy).

- ``Corrections``: the terms adjusted per image (``linear``: pushbroom attitude biases and
  rates, RPC affine; ``offset``: biases, RPC shift);
- ``Datum``, ``VerticalChoice``: a height's vertical datum, and what an option may say of a
  DEM's (``auto``: decided by the one datum rule, :func:`core.heights.decide_datum`);
- ``Resampling``: the ortho kernel's image resampling (:class:`core.ortho.ortho.OrthoConfig`);
- ``Measure``, ``TieMeasure``: the tie points' correlation measures
  (:mod:`core.matching.peaks`), and what ``--tie-measure`` may say (``auto``: chosen from the
  two images' suns).
"""

from __future__ import annotations

from typing import Literal, get_args

from core.errors import InputError

Corrections = Literal["linear", "offset"]
CORRECTIONS: tuple[Corrections, ...] = get_args(Corrections)

Datum = Literal["ellipsoidal", "egm96"]
DATUMS: tuple[Datum, ...] = get_args(Datum)
VerticalChoice = Literal["auto", Datum]
VERTICAL_CHOICES: tuple[VerticalChoice, ...] = get_args(VerticalChoice)

Resampling = Literal["nearest", "bilinear", "cubic"]
RESAMPLINGS: tuple[Resampling, ...] = get_args(Resampling)

Measure = Literal["ncc", "orientation"]
MEASURES: tuple[Measure, ...] = get_args(Measure)
TieMeasure = Literal["auto", Measure]
TIE_MEASURES: tuple[TieMeasure, ...] = get_args(TieMeasure)


def check_vertical_choices(owner: object, *names: str, flag: str = "--") -> None:
    """InputError unless each field ``name`` of ``owner`` is one of :data:`VERTICAL_CHOICES`,
    named as its option (``flag`` and the name with hyphens)."""
    for name in names:
        value = getattr(owner, name)
        if value not in VERTICAL_CHOICES:
            raise InputError(f"{flag}{name.replace('_', '-')} {value!r} unknown; use one of "
                             f"{VERTICAL_CHOICES}")
