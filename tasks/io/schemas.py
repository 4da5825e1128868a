"""The JSON Schema of each product, by its name: what the site's product pages show.

Generated from the typed classes that write and read the products (:mod:`tasks.io.products`,
:mod:`tasks.io.model_files`, :mod:`tasks.absolute.report`, on :mod:`tasks.io.documents`), so
a page cannot drift from the files. ``summary.csv`` is a table: its entry is the schema of one
row, whose properties are the columns in their order (``x-columns``).

Not moved onto the documents yet, so generated from what exists and marked ``x-not-moved``:

- ``rel.json``: no class holds it (``tasks/relative/orientation.py`` writes a dict): the
  schema says its format and, typed, the right model it embeds;
- ``dsm.json`` (a DSM's JSON, :class:`tasks.dense.dem.DemSummary`): the fields of the class
  (its own ``to_dict`` writes the file; report.json's ``relative_dem`` and ``dsm.summary``
  are the same record, written through its layout).
"""

from __future__ import annotations

from typing import Any

from pydantic import TypeAdapter

from tasks.absolute.report import REPORT
from tasks.io.documents import Document, record
from tasks.io.model_files import PUSHBROOM, RPC, SAR
from tasks.io.products import CHECKPOINTS, EVALUATION, GCPS, PAIR, SCENE, WINDOWS

#: the products moved onto :mod:`tasks.io.documents`, by the name of their page
DOCUMENTS: dict[str, Document[Any]] = {
    "gcps.json": GCPS, "windows.json": WINDOWS, "eval.json": EVALUATION, "pair.json": PAIR,
    "checkpoints.json": CHECKPOINTS, "scene.json": SCENE, "model (gcpfree.pushbroom)": PUSHBROOM,
    "model (gcpfree.sar)": SAR, "model (rpc)": RPC, "report.json": REPORT,
}
NOT_MOVED = ("rel.json", "dsm.json")


def _not_moved(name: str, schema: dict[str, Any], how: str) -> dict[str, Any]:
    return {**schema, "title": name, "x-not-moved": how}


def _fields_schema(cls: type, name: str) -> dict[str, Any]:
    return _not_moved(name, TypeAdapter(record(cls)).json_schema(),
                      f"generated from the fields of {cls.__module__}.{cls.__qualname__}; the "
                      "file is written by its own to_dict, whose keys may differ in places")


def summary_csv_schema() -> dict[str, Any]:
    """One row of an archive's ``summary.csv`` (and of ``summary.json``'s ``pairs``)."""
    from tasks.archive.catalog import FIELDS, PairRow

    return {**TypeAdapter(record(PairRow)).json_schema(), "title": "summary.csv",
            "description": "one row per pair; the columns in this order; empty cells for "
                           "unknown figures; numbers with 6 significant digits",
            "x-columns": list(FIELDS)}


def rel_json_schema() -> dict[str, Any]:
    model = PUSHBROOM.json_schema()
    defs = model.pop("$defs", {})
    return _not_moved("rel.json", {
        "$defs": defs, "type": "object",
        "properties": {"format": {"const": "gcpfree.relative"}, "version": {"const": 1},
                       "right_model": model},
        "required": ["format", "version", "right_model"]},
        "no class holds rel.json yet (tasks/relative/orientation.py writes a dict): only its "
        "format and the right model it embeds are typed here")


def product_schemas() -> dict[str, dict[str, Any]]:
    """Every product's JSON Schema, by name (``summary.csv``: one row's)."""
    from tasks.dense.dem import DemSummary

    out = {name: doc.json_schema() for name, doc in DOCUMENTS.items()}
    out["summary.csv"] = summary_csv_schema()
    out["rel.json"] = rel_json_schema()
    out["dsm.json"] = _fields_schema(DemSummary, "dsm.json")
    return out


__all__ = ["DOCUMENTS", "NOT_MOVED", "product_schemas", "summary_csv_schema"]
