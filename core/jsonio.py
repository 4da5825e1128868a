"""JSON in one place: the one reader (:func:`parse_json`, an error that names the document)
and the one strict writer (:func:`to_json`: NaN written as null)."""

from __future__ import annotations

import json
import math
from pathlib import PurePath
from typing import Any

import numpy as np
from numpy.typing import NDArray

from core.errors import InputError


def parse_json(text: str, what: str) -> Any:
    """``json.loads(text)``; InputError naming ``what`` (e.g. "scene.json") when it is not JSON,
    nests deeper than Python can follow or holds an integer longer than Python converts."""
    try:
        return json.loads(text)
    except RecursionError:
        raise InputError(f"{what} is not valid JSON: nested too deeply") from None
    except ValueError as exc:  # JSONDecodeError, and integers over 4300 digits
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise InputError(f"{what} is not valid JSON: {first}") from None


def json_ready(obj: Any) -> Any:
    """``obj`` as strict JSON values: NaN and infinities -> None (JSON has neither), tuples and
    arrays -> lists, NumPy scalars -> Python numbers, paths -> strings, mappings' keys ->
    strings."""
    if isinstance(obj, dict):
        return {str(k): json_ready(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple, np.ndarray)):
        return [json_ready(v) for v in (obj.tolist() if isinstance(obj, np.ndarray) else obj)]
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, PurePath):
        return str(obj)
    return obj


def to_json(obj: Any, indent: int | None = 1) -> str:
    """The one JSON writer: ``obj`` as strict JSON text (:func:`json_ready`; a NaN is written
    as null, never as the ``NaN`` token other JSON readers refuse)."""
    return json.dumps(json_ready(obj), indent=indent, allow_nan=False)


def float_array(values: Any) -> NDArray[np.float64]:
    """A JSON list of numbers (nulls for the NaNs :func:`to_json` wrote) as a float array."""
    return np.array([np.nan if v is None else v for v in values], dtype=np.float64)
