"""The product reference: one page per document a run writes (``report.json``, ``eval.json``,
``rel.json``, ``pair.json``, ``summary.csv``, ``windows.json``, ``gcps.json``), its schema
generated at build time.

Where the schema comes from, first found wins:

1. the serialisation layer's own JSON schemas, :data:`SCHEMA_MODULE` (``tasks.io.schemas``),
   when it exists: a mapping ``SCHEMAS`` or a function ``product_schemas()`` (or
   ``schemas()``) giving ``name -> JSON schema``, looked up under any of :attr:`Product.keys`;
   the documents it has beyond :data:`PRODUCTS` get a page too;
2. else the layer's documents themselves, the objects of :data:`DOCUMENT_MODULE`
   (``tasks.io.products``) with a ``name`` (the file's) and a ``json_schema()``;
3. else the typed value the code reads the document into (:attr:`Product.typed`, a frozen
   dataclass), turned into a JSON schema by :func:`dataclass_schema` from its fields and type
   hints: field names and types, the class docstrings as descriptions;
4. else (a document the code still writes as a plain dict) no generated schema: the page says
   so, and its notes describe the keys.

Either way one renderer (:func:`render`) turns the JSON schema into tables, so pointing the
pages at the serialisation layer's schemas is the one line :data:`SCHEMA_MODULE`. Hand-written
notes (``docs/reference/notes/products/NAME.md``: what each key means in words) follow.
"""

from __future__ import annotations

import dataclasses
import enum
import importlib
import inspect
import re
import types
import typing
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

SCHEMA_MODULE = "tasks.io.schemas"
DOCUMENT_MODULE = "tasks.io.products"


@dataclass(frozen=True)
class Product:
    """One document: its file name, the command that writes it, its ``format`` tag, the typed
    value it is read into (``module:Class``, or "" when the code has none) and where the
    typed value sits in the document (``""``: the document itself; ``"points[]"``: the items
    of the array ``points``)."""

    name: str
    written_by: str
    format: str
    typed: str = ""
    typed_at: str = ""
    envelope: tuple[str, ...] = ()  # the keys written beside the typed value ("format"...)

    @property
    def keys(self) -> tuple[str, ...]:
        stem = self.name.split(".")[0]
        return (self.name, stem, self.format, self.format.removeprefix("gcpfree."))

    @property
    def slug(self) -> str:
        return re.sub(r"[^a-z0-9]+", "-", self.name.lower()).strip("-")


PRODUCTS = (
    Product("report.json", "`gcpfree orient`, `gcpfree pair`", "gcpfree.orient",
            "tasks.absolute.report:OrientReport", envelope=("format",)),
    Product("eval.json", "`gcpfree evaluate`, `gcpfree pair` (with `--lidar`)",
            "gcpfree.evaluation", "core.evaluation.evaluation_report:EvaluationReport"),
    Product("rel.json", "`gcpfree relative` (and `relative/` of `orient`, `pair`, `dsm`)",
            "gcpfree.relative"),
    Product("pair.json", "`gcpfree pair` (each pair of `gcpfree archive`)", "gcpfree.pair"),
    Product("summary.csv", "`gcpfree archive`, `gcpfree serve`", "gcpfree.archive",
            "tasks.archive.catalog:PairRow", typed_at="rows"),
    Product("windows.json", "`gcpfree orient`, `gcpfree pair`", "",
            "core.matching.surface:WindowMatch", typed_at="windows[]",
            envelope=("tie_point",)),
    Product("gcps.json", "`gcpfree orient`, `gcpfree pair`", "gcpfree.gcps",
            "core.points:ControlPoint", typed_at="points[]",
            envelope=("format", "version", "heights", "image_coordinates")),
)


# ---------------------------------------------------------------------------- sources


def _optional_module(name: str) -> Any:
    try:
        return importlib.import_module(name)
    except ModuleNotFoundError as exc:
        if exc.name and name.startswith(exc.name):
            return None
        raise


def layer_schemas() -> Mapping[str, Any] | None:
    """The serialisation layer's schemas (name -> JSON schema), or None while it is absent:
    :data:`SCHEMA_MODULE`'s, else those of :data:`DOCUMENT_MODULE`'s documents."""
    module = _optional_module(SCHEMA_MODULE)
    if module is None:
        docs = _optional_module(DOCUMENT_MODULE)
        if docs is None:
            return None
        found = {}
        for value in vars(docs).values():
            if (not isinstance(value, type) and isinstance(getattr(value, "name", None), str)
                    and callable(getattr(value, "json_schema", None))):
                found[value.name] = value.json_schema()
        return found or None
    found = getattr(module, "SCHEMAS", None)
    for name in ("product_schemas", "schemas"):
        if found is None and callable(getattr(module, name, None)):
            found = getattr(module, name)()
    if not isinstance(found, Mapping):
        raise TypeError(f"{SCHEMA_MODULE} has neither SCHEMAS nor product_schemas(): see "
                        "docs/_ext/gcpfree_docs/schemas.py")
    return found


LAYER = ("the serialisation layer's JSON schema of the document (`tasks.io.schemas`, on "
         "`tasks.io.documents`)")


def schema_of(product: Product, layer: Mapping[str, Any] | None) -> tuple[dict | None, str]:
    """The product's JSON schema and where it came from (a sentence for the page)."""
    if layer is not None:
        for key in product.keys:
            if key in layer:
                return dict(layer[key]), LAYER
    if product.typed:
        module_name, _, cls_name = product.typed.partition(":")
        cls = getattr(importlib.import_module(module_name), cls_name)
        return dataclass_schema(cls), (
            f"the typed value the code reads it into, `{module_name}.{cls_name}` (its fields "
            "and type hints; see the notes for the keys written around it)")
    return None, ""


# ---------------------------------------------------------------------------- dataclass -> schema

_SCALARS = {int: "integer", float: "number", str: "string", bool: "boolean",
            type(None): "null"}


def _doc(obj: Any) -> str:
    text = inspect.getdoc(obj) or ""
    if text.startswith(f"{getattr(obj, '__name__', '')}("):  # dataclass's generated signature
        return ""
    return " ".join(text.split())


def dataclass_schema(cls: type) -> dict[str, Any]:
    """A JSON schema (draft 2020-12) of a dataclass: its fields as properties, nested
    dataclasses and enums under ``$defs``."""
    defs: dict[str, Any] = {}
    root = _object_schema(cls, defs)
    root["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    root["title"] = cls.__name__
    if defs:
        root["$defs"] = defs
    return root


def _hints(cls: type) -> dict[str, Any]:
    try:
        return typing.get_type_hints(cls)
    except NameError:  # names imported for type checking only: keep what resolves
        module = importlib.import_module(cls.__module__)
        out = {}
        for f in dataclasses.fields(cls):
            try:
                out[f.name] = typing.get_type_hints(
                    type("_", (), {"__annotations__": {f.name: f.type}}),
                    globalns=vars(module))[f.name]
            except NameError:
                out[f.name] = f.type if isinstance(f.type, str) else Any
        return out


def _object_schema(cls: type, defs: dict[str, Any]) -> dict[str, Any]:
    hints = _hints(cls)
    props = {}
    required = []
    for f in dataclasses.fields(cls):
        props[f.name] = _type_schema(hints.get(f.name, Any), defs)
        if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            required.append(f.name)
    out: dict[str, Any] = {"type": "object", "description": _doc(cls), "properties": props}
    if required:
        out["required"] = required
    return out


def _type_schema(hint: Any, defs: dict[str, Any]) -> dict[str, Any]:
    if isinstance(hint, str):  # an annotation that does not resolve here
        return {"description": f"`{hint}`"}
    if hint is Any or hint is object:
        return {}
    if hint in _SCALARS:
        return {"type": _SCALARS[hint]}
    if inspect.isclass(hint) and issubclass(hint, enum.Enum):
        defs.setdefault(hint.__name__, {"type": "string", "description": _doc(hint),
                                         "enum": [m.name for m in hint]})
        return {"$ref": f"#/$defs/{hint.__name__}"}
    if dataclasses.is_dataclass(hint):
        if hint.__name__ not in defs:
            defs[hint.__name__] = {}  # placeholder: a recursive type stops here
            defs[hint.__name__] = _object_schema(hint, defs)
        return {"$ref": f"#/$defs/{hint.__name__}"}
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        return {"anyOf": [_type_schema(a, defs) for a in args]}
    if origin in (tuple, list, Sequence) or (inspect.isclass(origin)
                                             and issubclass(origin, Sequence)):
        items = [a for a in args if a is not Ellipsis]
        if origin is tuple and len(items) > 1 and Ellipsis not in args:
            return {"type": "array", "prefixItems": [_type_schema(a, defs) for a in items]}
        return {"type": "array", **({"items": _type_schema(items[0], defs)} if items else {})}
    if origin in (dict, Mapping) or (inspect.isclass(origin) and issubclass(origin, Mapping)):
        value = args[1] if len(args) == 2 else Any
        return {"type": "object", "additionalProperties": _type_schema(value, defs)}
    if inspect.isclass(hint) and hint.__module__ == "numpy":
        return {"type": "array", "description": "numbers"}
    return {"description": f"`{getattr(hint, '__name__', str(hint))}`"}


# ---------------------------------------------------------------------------- schema -> Markdown


def type_text(s: Mapping[str, Any], prefix: str = "") -> str:
    """A schema's type in a few words, with links to the definitions it refers to (labels
    ``prefix-name``)."""
    if "$ref" in s:
        name = s["$ref"].rsplit("/", 1)[-1]
        return f"{{ref}}`{name} <{_anchor(prefix, name)}>`"
    if "const" in s:
        return f"`{s['const']!r}`".replace("'", '"')
    if "enum" in s:
        return " \\| ".join(f"`{v}`" for v in s["enum"])
    for key in ("anyOf", "oneOf"):
        if key in s:
            return " or ".join(type_text(a, prefix) for a in s[key])
    kind = s.get("type")
    if isinstance(kind, list):
        return " or ".join(kind)
    if kind == "array":
        if "prefixItems" in s:
            return "[" + ", ".join(type_text(a, prefix) for a in s["prefixItems"]) + "]"
        return f"array of {type_text(s['items'], prefix)}" if s.get("items") else "array"
    if kind == "object" and isinstance(s.get("additionalProperties"), Mapping):
        return f"object of {type_text(s['additionalProperties'], prefix)}"
    if kind:
        return str(kind)
    return "any"


def _anchor(prefix: str, name: str) -> str:
    return f"{prefix}-{name.lower()}"


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def _table(schema: Mapping[str, Any], prefix: str) -> list[str]:
    """The keys of an object schema, a row each; the description column only when some key
    has one."""
    required = set(schema.get("required", ()))
    props = schema.get("properties", {})
    described = any(isinstance(s, Mapping) and s.get("description") for s in props.values())
    rows = ["| key | type | required |" + (" description |" if described else ""),
            "|---|---|---|" + ("---|" if described else "")]
    for key, sub in props.items():
        desc = sub.get("description", "") if isinstance(sub, Mapping) else ""
        row = f"| `{key}` | {_cell(type_text(sub, prefix))} | {'yes' if key in required else ''} |"
        rows.append(row + (f" {_cell(desc)} |" if described else ""))
    return rows


def render(schema: Mapping[str, Any], prefix: str) -> list[str]:
    """A JSON schema as Markdown: the document's keys, then each definition it refers to
    (labelled ``prefix-name``: labels are global to the site)."""
    lines = []
    if schema.get("x-not-moved"):
        lines += ["```{note}", f"Not on the serialisation layer yet: {schema['x-not-moved']}.",
                  "```", ""]
    if schema.get("description"):
        lines += [_cell(schema["description"]), ""]
    if schema.get("x-columns"):
        lines += ["Columns, in order: " + ", ".join(f"`{c}`" for c in schema["x-columns"]) + ".",
                  ""]
    if schema.get("properties"):
        lines += _table(schema, prefix) + [""]
    for name, sub in schema.get("$defs", {}).items():
        lines += [f"({_anchor(prefix, name)})=", f"### {name}", ""]
        if sub.get("description"):
            lines += [_cell(sub["description"]), ""]
        if sub.get("properties"):
            lines += _table(sub, prefix) + [""]
        elif "enum" in sub:
            lines += ["One of " + ", ".join(f"`{v}`" for v in sub["enum"]) + ".", ""]
    return lines


def page(product: Product, layer: Mapping[str, Any] | None, notes: Path | None) -> str:
    schema, source = schema_of(product, layer)
    lines = [f"# `{product.name}`", ""]
    if product.written_by:
        lines += [f"Written by {product.written_by}."]
    if product.format:
        lines += ["", (f"Its `format` is `\"{product.format}\"`; a reader refuses another "
                  "format, and a `version` newer than its own.")]
    lines += [""]
    if schema is None:
        lines += ["```{note}",
                  ("The code still writes this document as a plain dict (no typed class, no "
                  "schema of the serialisation layer yet): the keys below are described by "
                  "hand. The page is generated from the schema as soon as one exists."),
                  "```", ""]
    else:
        where = ""
        if source == LAYER:
            pass
        elif product.typed_at:
            where = (f" It describes each item of `{product.typed_at.rstrip('[]')}`"
                     if product.typed_at.endswith("[]") else
                     f" It describes each of the document's {product.typed_at}")
            if product.envelope:
                where += ("; written beside it: " + ", ".join(f"`{k}`" for k in product.envelope))
            where += "."
        elif product.envelope:
            where = " Written beside its fields: " + ", ".join(
                f"`{k}`" for k in product.envelope) + "."
        lines += ["## Schema", "", f"Generated at build time from {source}.{where}", ""]
        lines += render(schema, product.slug)
    if notes is not None:
        lines += [f"```{{include}} ../notes/products/{notes.name}", ":heading-offset: 1",
                  "```", ""]
    return "\n".join(lines)


def index_page(every: tuple[Product, ...]) -> str:
    lines = ["# Products", "",
             ("What a run writes, one page per document, with its schema generated from the "
             "code at build time."), "",
             "| document | written by | format |", "|---|---|---|"]
    lines += [f"| [`{p.name}`]({p.slug}.md) | {p.written_by} | "
              f"{f'`{p.format}`' if p.format else ''} |" for p in every]
    lines += ["", "```{toctree}", ":hidden:", "", *(p.slug for p in every), "```", ""]
    return "\n".join(lines)


def products(layer: Mapping[str, Any] | None) -> tuple[Product, ...]:
    """:data:`PRODUCTS`, then the layer's other documents (checkpoints, model files...)."""
    covered = {k for p in PRODUCTS for k in p.keys}
    extra = tuple(Product(name, "", str(s.get("properties", {}).get("format", {})
                                         .get("const", "")))
                  for name, s in (layer or {}).items() if name not in covered)
    return PRODUCTS + extra


def write_pages(out: Path, notes_dir: Path) -> list[str]:
    """The product pages into ``out``; the slugs written."""
    layer = layer_schemas()
    every = products(layer)
    out.mkdir(parents=True, exist_ok=True)
    known = {p.slug for p in every}
    orphans = sorted(n.stem for n in notes_dir.glob("*.md") if n.stem not in known)
    if orphans:
        raise RuntimeError(f"docs/reference/notes/products/ has notes of no product: {orphans}")
    for product in every:
        notes = notes_dir / f"{product.slug}.md"
        _write_if_changed(out / f"{product.slug}.md",
                          page(product, layer, notes if notes.exists() else None))
    _write_if_changed(out / "index.md", index_page(every))
    return [p.slug for p in every]


def _write_if_changed(path: Path, text: str) -> None:
    if not path.exists() or path.read_text() != text:
        path.write_text(text)
