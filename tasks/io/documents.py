"""JSON documents through one library: pydantic's ``TypeAdapter`` over the project's frozen
dataclasses, one schema per document.

Why pydantic: it comes with Prefect (no new dependency), it validates with the path of the
value that is wrong, and it writes the JSON Schema of each document (:mod:`tasks.io.schemas`,
the site's product pages). core/ stays NumPy/SciPy: the dataclasses there carry only their type
hints, and this module turns those hints into what pydantic validates and serialises.

The pattern, to move a document onto it:

1. The value is a frozen dataclass (in core/, or a task's result class). Its fields and their
   type hints are the schema: :func:`record` makes of it the type pydantic reads and writes:
   ``float`` written as a number, NaN as ``null`` and ``null`` read back as NaN; NumPy arrays
   as (nested) lists; tuples back as tuples; nested dataclasses, ``X | None``, mappings and
   ``Literal`` as their hints say; an ``Enum`` by its name. Fields with a default may be
   absent (a file written before the field existed), unknown keys are ignored. Per class,
   :class:`Layout` says where the file's keys differ from the fields: ``keys`` (a field
   written under another name), ``omit_default`` (left out when at its default),
   ``computed`` (keys written from the value and ignored on read), ``inline`` (a dataclass
   field whose keys are written at this level), ``spread`` (a mapping field whose items are
   written at this level, and read back from the keys that are no field's), ``types`` (a
   field's pydantic-ready type when its hint does not say how the file holds it), ``order``
   (the file's order of the keys, when it is not the fields'), ``tag`` (key, value: written
   first, and what tells the members of a union of dataclasses apart on read; with
   ``tag_default`` the key may be absent, meaning this class; ``tag_written`` False: the key
   is not written), ``finite`` (its numbers must be finite: null, NaN and infinities
   refused), ``as_list`` (written as the list of its values in the fields' order: a box, a
   point). Register it with :func:`layout`, once per class, where the document is defined.
2. The document is a :class:`Document`: its file name, the dataclass of the whole file (the
   envelope too: ``format``, ``version`` and constant keys are fields with their defaults),
   what to give instead of a bad file (the message's hint), and the ``format``/``version``
   its reader checked before (checked the same way; None: not checked).
3. Callers: ``DOC.dump(value)`` a JSON-ready dict (:func:`core.jsonio.to_json` writes it, the
   one writer), ``DOC.load(data)`` the value (one-line InputError naming the document and the
   key path), ``DOC.write(path, value)``, ``DOC.read(path)`` and ``DOC.json_schema()``; a
   part of a document: :func:`plain` (a recorded value as the JSON-ready values its document
   writes) and :func:`adapter` (``adapter(T).validate_python(values)``: a value of ``T``).

Example (gcps.json, :data:`tasks.io.products.GCPS`; ``GcpSet`` is the document's dataclass,
its envelope fields with their defaults, then ``points: tuple[ControlPoint, ...]``)::

    layout(ControlPoint, keys={"image_points": "images"})
    GCPS = Document("gcps.json", GcpSet, hint="give the gcps.json written by gcpfree orient")
    GCPS.write(out / "gcps.json", GcpSet(points=gcps))
"""

from __future__ import annotations

import dataclasses
import enum
import math
import types
import typing
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import (
    Annotated,
    Any,
    Generic,
    Literal,
    NotRequired,
    TypeVar,
    Union,
    get_args,
    get_origin,
)

import numpy as np
from pydantic import (
    AfterValidator,
    BeforeValidator,
    Discriminator,
    PlainSerializer,
    PlainValidator,
    Tag,
    TypeAdapter,
    ValidationError,
    WithJsonSchema,
    WrapSerializer,
)
from typing_extensions import TypedDict  # pydantic needs this one before Python 3.12

from core.errors import InputError

T = TypeVar("T")


# ------------------------------------------------------------------------------ leaf types


def _number(v: Any) -> float:
    """A JSON number as a float; null (a NaN the writer wrote) as NaN."""
    if v is None:
        return math.nan
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ValueError("must be a number")  # noqa: TRY004 - pydantic reports ValueErrors
    return float(v)


def _finite(v: Any) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise ValueError("must be a finite number")
    return float(v)


def _integer(v: Any) -> int:
    if isinstance(v, bool) or not isinstance(v, int):
        raise ValueError("must be an integer")  # noqa: TRY004 - as above
    return v


def _array(v: Any) -> np.ndarray:
    """A (nested) list of numbers (nulls for NaN) as a float64 array."""
    def ok(x: Any) -> bool:
        if isinstance(x, list):
            return all(ok(e) for e in x)
        return x is None or (isinstance(x, (int, float)) and not isinstance(x, bool))

    if isinstance(v, np.ndarray):
        return v
    if not isinstance(v, list) or not ok(v):
        raise ValueError("must be a (nested) list of numbers")
    try:
        return np.array(v, dtype=np.float64)  # None -> nan
    except ValueError:
        raise ValueError("must be a rectangular nested list of numbers") from None


NUMBER_SCHEMA = {"anyOf": [{"type": "number"}, {"type": "null"}],
                 "description": "null stands for NaN"}
# written as Python numbers: a NumPy scalar in a field (a focal length computed with NumPy)
# made pydantic's own serialisers fail ("Unexpected Value")
Number = Annotated[float, PlainValidator(_number), PlainSerializer(float, return_type=float),
                   WithJsonSchema(NUMBER_SCHEMA)]
Finite = Annotated[float, PlainValidator(_finite), PlainSerializer(float, return_type=float),
                   WithJsonSchema({"type": "number"})]
Integer = Annotated[int, PlainValidator(_integer), PlainSerializer(int, return_type=int),
                    WithJsonSchema({"type": "integer"})]
Array = Annotated[np.ndarray, PlainValidator(_array),
                  PlainSerializer(lambda a: np.asarray(a).tolist()),
                  WithJsonSchema({"type": "array", "description": "numbers, nested by axis"})]


def _by_name(cls: type[enum.Enum]) -> Any:
    def read(v: Any) -> enum.Enum:
        if isinstance(v, cls):
            return v
        if not isinstance(v, str) or v not in cls.__members__:
            raise ValueError(f"must be one of {list(cls.__members__)}")
        return cls[v]

    return Annotated[cls, PlainValidator(read), PlainSerializer(lambda e: e.name),
                     WithJsonSchema({"enum": list(cls.__members__)})]


# ------------------------------------------------------------------------------ records


@dataclass(frozen=True)
class Layout:
    """Where a class's JSON differs from its fields (see the module docstring)."""

    keys: Mapping[str, str] = field(default_factory=dict)
    omit_default: tuple[str, ...] = ()
    computed: Mapping[str, Callable[[Any], Any]] = field(default_factory=dict)
    inline: tuple[str, ...] = ()
    spread: str | None = None
    types: Mapping[str, Any] = field(default_factory=dict)
    order: tuple[str, ...] = ()
    tag: tuple[str, str] | None = None
    tag_default: bool = False
    tag_written: bool = True
    finite: bool = False
    as_list: bool = False


_LAYOUTS: dict[type, Layout] = {}


def layout(cls: type, **kw: Any) -> None:
    """Register the :class:`Layout` of ``cls`` (before its first :func:`record`)."""
    if cls in _LAYOUTS:
        raise RuntimeError(f"{cls.__name__}'s layout is registered twice")
    _LAYOUTS[cls] = Layout(**kw)
    if cls in _RECORDED:  # a record made before (without it) is made again
        record.cache_clear()
        _adapter.cache_clear()
        _RECORDED.clear()
        _KEYS.clear()


_RECORDED: set[type] = set()


def shape(tp: Any, finite: bool = False) -> Any:
    """The pydantic-ready type of a field's type hint ``tp`` (``finite``: its floats)."""
    origin, args = get_origin(tp), get_args(tp)
    if tp is float:
        return Finite if finite else Number
    if tp is int:
        return Integer
    if tp is np.ndarray or origin is np.ndarray:
        return Array
    if isinstance(tp, type) and issubclass(tp, enum.Enum):
        return _by_name(tp)
    if dataclasses.is_dataclass(tp):
        return record(tp)
    if origin in (Union, types.UnionType):
        return _tagged(args) or Union[tuple(shape(a, finite) for a in args)]  # noqa: UP007
    if origin is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple[shape(args[0], finite), ...]
        return tuple[tuple(shape(a, finite) for a in args)] if args else tuple
    if origin in (Mapping, dict, typing.Mapping):
        return dict[shape(args[0]), shape(args[1], finite)] if args else dict
    if origin is list:
        return list[shape(args[0], finite)]
    if origin is Annotated:
        return shape(args[0], finite)
    return tp  # str, bool, Any, Literal[...]


_KEYS: dict[type, tuple[str, ...]] = {}


@dataclass(frozen=True)
class _Record:
    """How one dataclass meets its JSON: its init fields, their keys, the keys of the file's
    level (an inlined field's own, a spread field's none) and the defaults."""

    cls: type
    lay: Layout
    fields: tuple[dataclasses.Field, ...]
    key: Mapping[str, str]
    defaults: Mapping[str, Any]
    inlined: Mapping[str, tuple[str, ...]]
    spread: str | None
    own: tuple[str, ...]

    def gather(self, d: Any) -> Any:
        """The file's level as the TypedDict's: inlined keys into their field, the keys that
        are no field's into the spread field, a list's values to their fields."""
        if self.lay.as_list:
            names = [self.key[f.name] for f in self.fields]
            if not isinstance(d, (list, tuple)) or len(d) != len(names):
                raise ValueError(f"must be a list of {len(names)} values ({', '.join(names)})")
            return dict(zip(names, d, strict=True))
        if not isinstance(d, dict) or not (self.inlined or self.spread):
            return d
        out = {k: v for k, v in d.items()
               if not any(k in ks for ks in self.inlined.values())}
        for f_key, ks in self.inlined.items():
            out[f_key] = {k: d[k] for k in ks if k in d}
        if self.spread:
            out = {k: v for k, v in out.items() if k in self.own or k in self.inlined}
            out[self.spread] = {k: v for k, v in d.items() if k not in self.own}
        return out

    def build(self, d: Mapping[str, Any]) -> Any:
        return self.cls(**{f.name: d[self.key[f.name]] for f in self.fields
                           if self.key[f.name] in d})

    def write(self, obj: Any, handler: Callable[[Any], Any]) -> Any:
        if not isinstance(obj, self.cls):
            return handler(obj)
        lay = self.lay
        d = {self.key[f.name]: getattr(obj, f.name) for f in self.fields
             if not (f.name in lay.omit_default
                     and _equal(getattr(obj, f.name), self.defaults[f.name]))}
        if lay.tag:  # the union's serialiser checks it
            d = {lay.tag[0]: lay.tag[1], **d}
        out = handler(d)
        if lay.tag and not lay.tag_written:
            out.pop(lay.tag[0])
        flat: dict[str, Any] = {}
        for k, v in out.items():
            if k in self.inlined or k == self.spread:
                flat.update(v)
            else:
                flat[k] = v
        flat.update({k: fn(obj) for k, fn in lay.computed.items()})
        if lay.as_list:
            return list(flat.values())
        return {k: flat[k] for k in lay.order if k in flat} | flat if lay.order else flat


def _record_of(cls: type, lay: Layout, hints: Mapping[str, Any]) -> _Record:
    init = tuple(f for f in dataclasses.fields(cls) if f.init)
    key = {f.name: lay.keys.get(f.name, f.name) for f in init}
    for name in (*lay.inline, *([lay.spread] if lay.spread else [])):
        key[name] = f"<{name}>"  # no key of the file: an error's path leaves it out
    defaults = {f.name: (f.default if f.default is not dataclasses.MISSING
                         else f.default_factory())  # type: ignore[misc]
                for f in init if f.default is not dataclasses.MISSING
                or f.default_factory is not dataclasses.MISSING}
    inlined = {key[n]: _keys_of(hints[n]) for n in lay.inline}
    spread = key[lay.spread] if lay.spread else None
    own = tuple(k for f in init for k in inlined.get(key[f.name], (key[f.name],))
                if k != spread) + tuple(lay.computed) + ((lay.tag[0],) if lay.tag else ())
    return _Record(cls, lay, init, key, defaults, inlined, spread, own)


@cache
def record(cls: type) -> Any:
    """The pydantic-ready type of the dataclass ``cls``: a TypedDict of its init fields (keys
    and presence as its :class:`Layout` says) read into ``cls(**fields)`` and written from the
    instance."""
    _RECORDED.add(cls)
    lay = _LAYOUTS.get(cls, Layout())
    hints = typing.get_type_hints(cls)
    rec = _record_of(cls, lay, hints)
    _KEYS[cls] = rec.own
    items = {}
    for f in rec.fields:
        tp = lay.types.get(f.name) or shape(hints[f.name], lay.finite)
        items[rec.key[f.name]] = NotRequired[tp] if f.name in rec.defaults else tp
    for k in lay.computed:
        items[k] = NotRequired[Any]
    if lay.tag:
        tag_type = Literal[lay.tag[1]]  # type: ignore[valid-type]
        items = {lay.tag[0]: NotRequired[tag_type] if lay.tag_default else tag_type, **items}
    items = {k: items[k] for k in lay.order if k in items} | items  # the schema in file order
    body = TypedDict(cls.__name__, items)  # type: ignore[operator]
    body.__doc__ = cls.__doc__  # the schema's description
    extra: tuple[Any, ...] = ()
    if lay.as_list:
        as_tuple = tuple[tuple(shape(hints[f.name], lay.finite) for f in rec.fields)]  # type: ignore
        extra = (WithJsonSchema({**TypeAdapter(as_tuple).json_schema(), "description": (
            f"{cls.__name__}: {', '.join(rec.key[f.name] for f in rec.fields)}")}),)
    return Annotated[body, BeforeValidator(rec.gather), AfterValidator(rec.build),
                     WrapSerializer(rec.write), *extra]


def _tagged(members: tuple[Any, ...]) -> Any:
    """A union of dataclasses told apart by their :class:`Layout`'s ``tag`` (None when they
    have none): pydantic's discriminated union, the tag read from the file's key."""
    lays = [_LAYOUTS.get(m) if dataclasses.is_dataclass(m) else None for m in members]
    if not all(lay is not None and lay.tag for lay in lays):
        return None
    key = lays[0].tag[0]  # type: ignore[union-attr, index]
    by_tag = {lay.tag[1]: m for lay, m in zip(lays, members, strict=True)}  # type: ignore
    default = next((lay.tag[1] for lay in lays if lay.tag_default), None)  # type: ignore

    def which(v: Any) -> str | None:
        if isinstance(v, dict):
            t = v.get(key, default)
            return t if isinstance(t, str) else None
        return next((t for t, m in by_tag.items() if isinstance(v, m)), None)

    return Annotated[Union[tuple(Annotated[record(m), Tag(t)]  # noqa: UP007
                                 for t, m in by_tag.items())],
                     Discriminator(which, custom_error_type="tag",
                                   custom_error_message=f"must have '{key}' among "
                                                        f"{sorted(by_tag)}")]


def _keys_of(cls: type) -> tuple[str, ...]:
    record(cls)
    return _KEYS[cls]


def _equal(a: Any, b: Any) -> bool:
    try:
        return bool(a == b)
    except ValueError:  # arrays
        return bool(np.array_equal(a, b))


# ------------------------------------------------------------------------------ documents


def _loc(loc: tuple[Any, ...]) -> str:
    # pydantic puts the name of a function validator or union member in the path: keep keys
    parts = [str(p) for p in loc if not (isinstance(p, str) and ("[" in p or p.startswith(
        ("function-", "nullable", "tuple", "list", "dict", "<"))))]
    return ".".join(parts)


def _message(err: ValidationError) -> str:
    """The first error of ``err`` in one line: the key path, what it must be, what it was."""
    e = err.errors(include_url=False)[0]
    where = _loc(tuple(e["loc"]))
    what = e["msg"].removeprefix("Value error, ").replace("Input should be", "must be")
    ctx_error = (e.get("ctx") or {}).get("error")
    if isinstance(ctx_error, InputError):
        return str(ctx_error)
    if e["type"] == "missing":
        return f"key '{where}' is missing"
    if e["type"] == "literal_error":
        return f"key '{where}' {what}, got {e['input']!r:.80}"
    got = e.get("input")
    return f"key '{where or '<root>'}' {what[:1].lower()}{what[1:]}, got {got!r:.80}"


@dataclass(frozen=True)
class Document(Generic[T]):
    """One JSON document: its file ``name``, the type of its value (a dataclass whose fields
    are the document's keys, envelope included: ``format``, ``version`` and constant keys are
    fields with their default), the message's ``hint`` (what to give instead), and the
    envelope checks its reader made before (``format`` and ``version``, None: not checked)."""

    name: str
    value_type: Any
    hint: str
    format: str | None = None
    version: int | None = None

    @property
    def adapter(self) -> TypeAdapter:
        return _adapter(self.value_type)

    def dump(self, value: T) -> dict[str, Any]:
        """The document as JSON-ready values (NaN still NaN: :func:`core.jsonio.to_json`
        writes it as null)."""
        return _plain(self.adapter.dump_python(value, mode="python"))

    def load(self, data: Any, what: str | None = None) -> T:
        """The value of a parsed document; InputError naming ``what`` (default the
        document's name) and the key that is wrong."""
        what = what or self.name
        if not isinstance(data, dict):
            raise InputError(f"{what}: not a JSON object; {self.hint}")
        if self.format is not None and data.get("format") != self.format:
            raise InputError(f"{what}: key 'format' is {data.get('format')!r:.40}, not "
                             f"{self.format!r}; {self.hint}")
        version = data.get("version")
        if self.version is not None and (version != self.version or isinstance(version, bool)):
            if isinstance(version, int) and not isinstance(version, bool) \
                    and version > self.version:
                raise InputError(f"{what}: version {version}, and this gcpfree reads "
                                 f"{self.name} up to version {self.version}; update gcpfree")
            raise InputError(f"{what}: version {version!r:.40} is not {self.version}; "
                             f"{self.hint}")
        try:
            return self.adapter.validate_python(data)
        except ValidationError as exc:
            raise InputError(f"{what}: {_message(exc)}; {self.hint}") from None

    def read(self, path: str | Path) -> T:
        from tasks.io.rasters import read_json

        return self.load(read_json(path, self.name, self.hint), f"{self.name} {path}")

    def write(self, path: str | Path, value: T) -> Path:
        from tasks.io.rasters import atomic_write_json

        return atomic_write_json(Path(path), self.dump(value))

    def json_schema(self) -> dict[str, Any]:
        """The JSON Schema of the document."""
        return {**self.adapter.json_schema(), "title": self.name,
                "x-class": f"{self.value_type.__module__}.{self.value_type.__qualname__}"}


def _plain(v: Any) -> Any:
    """pydantic's python dump with the tuples it keeps as lists (json_ready would turn them
    too; here so that a dumped document equals what the hand-written writers returned)."""
    if isinstance(v, dict):
        return {k: _plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    return v


@cache
def _adapter(value_type: Any) -> TypeAdapter:
    return TypeAdapter(shape(value_type))


def adapter(value_type: Any) -> TypeAdapter:
    """The TypeAdapter of a type hint (a dataclass: its :func:`record`), for a part of a
    document: ``adapter(T).validate_python(json_values)`` reads a value of ``T``."""
    return _adapter(value_type)


def plain(value: Any) -> Any:
    """A recorded dataclass's ``value`` as the JSON-ready values its document writes of it
    (a part of a document, as :meth:`Document.dump` gives the whole)."""
    return _plain(_adapter(type(value)).dump_python(value, mode="python"))


__all__ = ["Array", "Document", "Finite", "Integer", "Layout", "Number", "adapter", "layout",
           "plain", "record", "shape"]
