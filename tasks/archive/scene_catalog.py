"""What a ``gcpfree scenes`` catalog holds beyond its pairs, as the archive's catalog reader
(:func:`tasks.archive.catalog.read_catalog`) reads it: the scenes (id, image, model), the
overlaps (every two overlapping scenes), the blocks (the scenes and stereo pairs of each
connected component) and the rejected files (path, reason), each checked against the others.
The writer is :meth:`tasks.archive.stereo.SceneCatalog.to_dict`."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from core.errors import InputError

#: the ``format`` of a ``gcpfree scenes`` catalog
SCENES_FORMAT = "gcpfree.scenes"
#: what to do with a catalog that fails a check
AGAIN = "write the catalog again with gcpfree scenes"


@dataclass(frozen=True)
class SceneEntry:
    """A scene: its id, image and model (None: the image's own RPC tags), and its footprint
    as ``gcpfree scenes`` computed it (lon, lat of the corner pixels; empty when the catalog
    gives none)."""

    id: str
    image: Path
    model: Path | None = None
    footprint: tuple[tuple[float, float], ...] = ()


@dataclass(frozen=True)
class BlockEntry:
    """A block: the ids of its scenes and of its stereo pairs."""

    id: str
    scenes: tuple[str, ...]
    pairs: tuple[str, ...] = ()


@dataclass(frozen=True)
class RejectedEntry:
    """A file ``gcpfree scenes`` did not take as a scene, and why."""

    path: Path
    reason: str


def _objects(doc: dict[str, Any], key: str, fields: tuple[str, ...], path: Path
             ) -> list[dict[str, Any]]:
    """``doc[key]``: a list of objects each holding ``fields`` (empty when absent)."""
    items = doc.get(key, [])
    if not isinstance(items, list):
        raise InputError(f"catalog {path}: '{key}' must be a list, not "
                         f"{type(items).__name__}; {AGAIN}")
    for i, item in enumerate(items):
        if not isinstance(item, dict) or any(f not in item for f in fields):
            raise InputError(f"catalog {path}: {key} {i} must be an object with "
                             f"{', '.join(fields)}; {AGAIN}")
    return items


def _names(value: Any, known: set[str], what: str, where: str) -> tuple[str, ...]:
    """A list of ids, each one of ``known``."""
    if isinstance(value, str) or not isinstance(value, list) or not all(
            isinstance(v, str) for v in value):
        raise InputError(f"{where}: {what}s must be a list of ids; {AGAIN}")
    unknown = [v for v in value if v not in known]
    if unknown:
        raise InputError(f"{where} names {what} {', '.join(unknown)} that the catalog does not "
                         f"list; {AGAIN}")
    return tuple(value)


def _footprint(value: Any, where: str) -> tuple[tuple[float, float], ...]:
    """A scene's ``footprint``: three or more [lon, lat] in degrees (none when absent)."""
    if value is None:
        return ()
    if not isinstance(value, list) or len(value) < 3 or not all(
            isinstance(p, list) and len(p) == 2
            and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in p)
            for p in value):
        raise InputError(f"{where}: footprint must be a list of three or more [lon, lat] in "
                         f"degrees; {AGAIN}")
    return tuple((float(p[0]), float(p[1])) for p in value)


def _scenes(doc: dict[str, Any], path: Path, resolve: Callable[[str], Path],
            checked_id: Callable[[str, str], str]) -> tuple[SceneEntry, ...]:
    scenes = []
    for i, s in enumerate(_objects(doc, "scenes", ("id", "image"), path)):
        where = f"catalog {path} scene {i}"
        if not all(isinstance(s.get(k), str) for k in ("id", "image")) or not isinstance(
                s.get("model"), (str, type(None))):
            raise InputError(f"{where}: id, image and model must be strings (model may be "
                             "null)")
        model = s.get("model")
        scenes.append(SceneEntry(checked_id(s["id"], where), resolve(s["image"]),
                                 None if model is None else resolve(model),
                                 _footprint(s.get("footprint"), where)))
    if len({s.id for s in scenes}) < len(scenes):
        raise InputError(f"catalog {path}: a scene id appears twice; ids must be unique")
    return tuple(scenes)


def scene_parts(doc: dict[str, Any], path: Path, pair_ids: set[str],
                resolve: Callable[[str], Path], checked_id: Callable[[str, str], str]
                ) -> dict[str, Any]:
    """The ``scenes``, ``overlaps``, ``blocks`` and ``rejected`` of the catalog document
    ``doc`` read from ``path`` (the fields of :class:`tasks.archive.catalog.Catalog`), whose
    pairs have the ids ``pair_ids``; ``resolve`` makes a path of a written one, ``checked_id``
    checks an id (an output folder's name).

    Raises:
        InputError: a part is malformed, or names a scene or pair the catalog does not list.
    """
    scenes = _scenes(doc, path, resolve, checked_id)
    ids = {s.id for s in scenes}
    for i, row in enumerate(_objects(doc, "pairs", (), path)):
        named = [row[k] for k in ("left_scene", "right_scene") if row.get(k) is not None]
        _names(named, ids, "scene", f"catalog {path} pair {i}")
    overlaps = tuple(
        _names([o["left"], o["right"]], ids, "scene", f"catalog {path} overlap {i}")
        for i, o in enumerate(_objects(doc, "overlaps", ("left", "right"), path)))
    blocks = tuple(
        BlockEntry(checked_id(str(b["id"]), f"catalog {path} block {i}"),
                   _names(b["scenes"], ids, "scene", f"catalog {path} block {b['id']}"),
                   _names(b.get("pairs", []), pair_ids, "pair",
                          f"catalog {path} block {b['id']}"))
        for i, b in enumerate(_objects(doc, "blocks", ("id", "scenes"), path)))
    rejected = tuple(RejectedEntry(resolve(str(r["path"])), str(r["reason"]))
                     for r in _objects(doc, "rejected", ("path", "reason"), path))
    return {"scenes": scenes, "overlaps": overlaps, "blocks": blocks, "rejected": rejected}
