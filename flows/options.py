"""A pair's options by name: one vocabulary for the archive's catalog (a column or key per
option, per pair), ``gcpfree archive`` and ``gcpfree serve`` (every pair), the flow
``reprocess-archive``'s ``options`` parameter, the commands' parsers (each option's ``dest``)
and the manifest's ``params`` (``pair.json``).

An option is a field of :class:`flows.orient.OrientParams` (``self_calibrate``,
``corrections``, ``min_windows``...), a field of one of its two configs, dotted
(``surface.radius_m``, ``absolute.huber_k``; the adjustment's ``reference_sigma_m`` without
its prefix, as ``pair.json`` has always written it), one of the pair's inputs that is neither
a file nor the ground (``band``, ``tie_measure``), or a field of
:class:`flows.pair.PairParams` (``lidar_vertical``). The list is read from those dataclasses,
so an option added to them is an option here too. Not options: the pair's files (images,
models, lidar, land cover, check points, SAR scene: the catalog's columns), its ground (the
reference or DEM tiles, their datum and geoid: the archive's), its id and folder, and how a
run goes (``workers``, ``progress``).

Values are read as the catalog gives them (text in a CSV, JSON values, Python values from the
command line), each checked against its type (``Literal`` choices, finite numbers), then by
the dataclass that holds it: bad input is one InputError line that names the option.
"""

from __future__ import annotations

import difflib
import math
import types
from collections.abc import Mapping
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any, Literal, TypeVar, Union, get_args, get_origin, get_type_hints

from core.errors import InputError
from flows.orient import OrientParams
from flows.pair import PairParams
from tasks.io.pair import PairInputs

#: fields that are no option: the pair's files, ground, id and folder, how a run goes
NOT_OPTIONS = frozenset({"out", "workers", "progress", "write_report", "checkpoints", "sar",
                         "sar_model", "lidar", "landcover", "pair_id"})
#: the pair's inputs that are options (the others are its files and its ground)
PAIR_OPTIONS = ("band", "tie_measure")
#: the orientation's configs, whose fields are options under their name
CONFIGS = ("surface", "absolute")
#: options named without their config's prefix, as pair.json writes them
UNPREFIXED = ("absolute.reference_sigma_m",)
TRUE, FALSE = ("true", "yes", "1"), ("false", "no", "0")

Params = TypeVar("Params", PairParams, OrientParams)


@dataclass(frozen=True)
class Option:
    """One option: its ``name``, where it lives in :class:`~flows.pair.PairParams`
    (``path``: field names from the top), its type and its default."""

    name: str
    path: tuple[str, ...]
    type: Any
    default: Any

    @property
    def is_orientation(self) -> bool:
        """Whether it is one of :class:`~flows.orient.OrientParams`' (all but the chain's)."""
        return self.path[0] == "orient"

    def of(self, params: PairParams) -> Any:
        """Its value in ``params``."""
        value: Any = params
        for key in self.path:
            value = getattr(value, key)
        return value


#: a pair whose options are all at their defaults
_DEFAULTS = PairParams(OrientParams(PairInputs(Path("left"), Path("right")), Path("out")))


def _options() -> dict[str, Option]:
    out: dict[str, Option] = {}

    def add(cls: type, path: tuple[str, ...], prefix: str = "") -> None:
        hints = get_type_hints(cls)
        for f in fields(cls):
            if f.name in NOT_OPTIONS or (cls is PairInputs and f.name not in PAIR_OPTIONS):
                continue
            if f.name in ("orient", "pair") or (cls is OrientParams and f.name in CONFIGS):
                add(hints[f.name], (*path, f.name), f"{f.name}." if f.name in CONFIGS else "")
                continue
            name = prefix + f.name
            name = name.split(".", 1)[1] if name in UNPREFIXED else name
            out[name] = Option(name, (*path, f.name), hints[f.name], None)

    add(PairParams, ())
    return {name: replace(o, default=o.of(_DEFAULTS)) for name, o in out.items()}


#: every option by name
OPTIONS: dict[str, Option] = _options()


def parse_option(name: str, value: Any, where: str = "") -> Any:
    """The value of the option ``name`` from ``value`` (text, a JSON value or a Python value),
    checked against its type. Raises InputError (prefixed with ``where``) when the option is
    unknown or the value is not one of its type."""
    said = f"{where}: " if where else ""
    option = OPTIONS.get(name)
    if option is None:
        close = difflib.get_close_matches(name, OPTIONS, n=3)
        raise InputError(f"{said}unknown option {name!r}; "
                         + (f"did you mean {' or '.join(close)}?" if close else
                            f"the options are {', '.join(OPTIONS)}"))
    try:
        return _typed(option.type, value)
    except ValueError as exc:
        raise InputError(f"{said}option {name} {value!r}: {exc}") from None


def _typed(tp: Any, value: Any) -> Any:
    """``value`` as the type ``tp``: bool, int, float (finite), str, a Literal, a tuple of
    them (text: separated by spaces or commas), or a union of them, the first that reads the
    value, None included (text: empty, none or null)."""
    text = value.strip() if isinstance(value, str) else None
    origin = get_origin(tp)
    if origin in (Union, types.UnionType):
        if value is None or (text is not None and text.lower() in ("", "none", "null")):
            return None
        refusals = []
        for kind in (a for a in get_args(tp) if a is not type(None)):  # the first that reads it
            try:
                return _typed(kind, value)
            except ValueError as exc:
                refusals.append(str(exc))
        raise ValueError(" or ".join(refusals))
    if origin is Literal:
        found = text if text is not None else value
        if found not in get_args(tp):
            raise ValueError(f"use one of {', '.join(map(str, get_args(tp)))}")
        return found
    if origin is tuple:
        items = text.replace(",", " ").split() if text is not None else value
        if not isinstance(items, (list, tuple)):
            raise ValueError("give a list of values")
        kinds = get_args(tp)
        if len(kinds) == 2 and kinds[1] is Ellipsis:
            kinds = (kinds[0],) * len(items)
        if len(items) != len(kinds):
            raise ValueError(f"give {len(kinds)} values")
        return tuple(_typed(k, v) for k, v in zip(kinds, items, strict=True))
    if tp is bool:
        if isinstance(value, bool):
            return value
        if text is not None and text.lower() in TRUE + FALSE:
            return text.lower() in TRUE
        raise ValueError("give true or false")
    if tp in (int, float):
        what = "a whole number" if tp is int else "a finite number"
        try:
            number = float(text if text is not None else value)
        except (TypeError, ValueError):
            number = math.nan
        if isinstance(value, bool) or not math.isfinite(number) or (
                tp is int and not number.is_integer()):
            raise ValueError(f"give {what}")
        return tp(number)
    if tp is str and isinstance(value, str):
        return value
    raise ValueError(f"expected a value of type {tp}")


def with_options(params: Params, values: Mapping[str, Any], where: str = "") -> Params:
    """``params`` (a :class:`~flows.pair.PairParams`, or an
    :class:`~flows.orient.OrientParams` for the orientation's options alone) with the options
    ``values`` by name (:func:`parse_option`), checked by the dataclasses that hold them.

    Raises:
        InputError: an unknown option, a value not of its type or refused by its dataclass,
            prefixed with ``where`` (e.g. the catalog's pair).
    """
    said = f"{where}: " if where else ""
    top = 1 if isinstance(params, OrientParams) else 0
    changes: dict[str, Any] = {}
    for name, value in values.items():
        typed = parse_option(name, value, where)
        option = OPTIONS[name]
        if top and not option.is_orientation:
            raise InputError(f"{said}{name} is not an option of the orientation")
        node = changes
        for key in option.path[top:-1]:
            node = node.setdefault(key, {})
        node[option.path[-1]] = typed
    try:
        return _replaced(params, changes)
    except InputError as exc:
        raise InputError(f"{said}{exc}") from None


def _replaced(obj: Any, changes: Mapping[str, Any]) -> Any:
    return replace(obj, **{k: _replaced(getattr(obj, k), v) if isinstance(v, dict) else v
                           for k, v in changes.items()})


def check_options(values: Mapping[str, Any], where: str = "") -> None:
    """``values`` checked as :func:`with_options` checks them, on a pair whose other options
    are at their defaults (InputError)."""
    with_options(_DEFAULTS, values, where)


def given_options(namespace: Any) -> dict[str, Any]:
    """The options a command line gives (an argparse namespace's attributes named as options:
    each option's ``dest`` is its name), those at their defaults left out, as JSON values."""
    from core.jsonio import json_ready

    given = {}
    for name, option in OPTIONS.items():
        if hasattr(namespace, name):
            value = parse_option(name, getattr(namespace, name))
            if value != option.default:
                given[name] = value
    return json_ready(given)
