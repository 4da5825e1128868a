"""Typed reads from JSON-like dicts for the pushbroom model; errors name the key path."""

from __future__ import annotations

from numbers import Real

import numpy as np
from numpy.typing import NDArray

from core.errors import InputError


def _where(path: str, key: str) -> str:
    return f"{path}.{key}" if path else key


def _need(d: object, key: str, path: str) -> object:
    if not isinstance(d, dict):
        raise InputError(
            f"pushbroom model: '{path or '<root>'}' must be a JSON object, got {type(d).__name__}"
        )
    if key not in d:
        raise InputError(
            f"pushbroom model: key '{_where(path, key)}' is missing; add it "
            "(see the format in core/sensors/pushbroom.py)"
        )
    return d[key]


def _bad(path: str, key: str, what: str, value: object) -> InputError:
    return InputError(
        f"pushbroom model: key '{_where(path, key)}' must be {what}, got {value!r:.80}"
    )


def _is_number(v: object) -> bool:
    return isinstance(v, Real) and not isinstance(v, bool)


def get_float(d: object, key: str, path: str, default: float | None = None) -> float:
    """A finite number at ``d[key]`` (or ``default`` when given and the key is absent)."""
    if default is not None and isinstance(d, dict) and key not in d:
        return default
    v = _need(d, key, path)
    if not _is_number(v) or not np.isfinite(float(v)):  # type: ignore[arg-type]
        raise _bad(path, key, "a finite number", v)
    return float(v)  # type: ignore[arg-type]


def get_int(d: object, key: str, path: str, minimum: int = 1) -> int:
    v = _need(d, key, path)
    if isinstance(v, bool) or not isinstance(v, int) or v < minimum:
        raise _bad(path, key, f"an integer >= {minimum}", v)
    return v


def get_str(d: object, key: str, path: str, default: str | None = None) -> str:
    if default is not None and isinstance(d, dict) and key not in d:
        return default
    v = _need(d, key, path)
    if not isinstance(v, str):
        raise _bad(path, key, "a string", v)
    return v


def get_float_tuple(d: object, key: str, path: str) -> tuple[float, ...]:
    v = _need(d, key, path)
    if not isinstance(v, list) or not v or not all(_is_number(x) for x in v):
        raise _bad(path, key, "a non-empty list of numbers", v)
    return tuple(float(x) for x in v)


def get_float_array(d: object, key: str, path: str, ndim: int) -> NDArray[np.float64]:
    """A numeric (nested) list at ``d[key]`` of ``ndim`` dimensions, as a float64 array."""
    v = _need(d, key, path)

    def ok(x: object, depth: int) -> bool:
        if depth == 0:
            return _is_number(x)
        return isinstance(x, list) and all(ok(e, depth - 1) for e in x)

    if not isinstance(v, list) or not v or not ok(v, ndim):
        what = "a list of numbers" if ndim == 1 else f"a {ndim}-level nested list of numbers"
        raise _bad(path, key, what, v)
    try:
        return np.array(v, dtype=np.float64)
    except ValueError as exc:  # ragged rows
        raise _bad(path, key, "a rectangular nested list of numbers", v) from exc


def get_float_arrays(d: object, path: str, **ndims: int) -> dict[str, NDArray[np.float64]]:
    """The float arrays at the keys named, each of its number of dimensions
    (:func:`get_float_array`), read in the order given."""
    return {key: get_float_array(d, key, path, ndim=n) for key, n in ndims.items()}


def float_lists(obj: object, *names: str) -> dict[str, list]:
    """The arrays ``obj.<name>`` as (nested) lists, keyed by name: what
    :func:`get_float_arrays` reads back."""
    return {name: getattr(obj, name).tolist() for name in names}


def get_str_tuple(d: object, key: str, path: str) -> tuple[str, ...]:
    v = _need(d, key, path)
    if not isinstance(v, list) or not all(isinstance(x, str) for x in v):
        raise _bad(path, key, "a list of strings", v)
    return tuple(v)


def get_dict(d: object, key: str, path: str = "") -> dict:
    """``d[key]`` that must be a JSON object."""
    v = _need(d, key, path)
    if not isinstance(v, dict):
        raise _bad(path, key, "a JSON object", v)
    return v
