"""The archive's catalog of stereo pairs and the summary of a reprocessing run.

A catalog is one of:

- a directory of pair folders, one pair per sub-folder (its name is the pair id). A pair folder
  holds ``left.tif`` and ``right.tif`` (each model found beside its image: ``left.json``,
  ``left.DIM``, a ``.geom`` or the GeoTIFF's RPC; the simulator's layout), or ``left/`` and
  ``right/`` folders each with one image (``IMAGERY.TIF`` beside ``METADATA.DIM`` for SPOT).
  Optional: ``lidar.laz`` (or ``.las``), ``landcover.tif`` (used with lidar only, it classifies
  the lidar evaluation), ``checkpoints.json`` (or ``.csv``), looked for in the pair folder, then
  in its ``truth/`` folder (the simulator's); ``sar.tif`` (a SAR scene of the same ground, its
  model ``sar.xml``/``sar.json`` beside it: SAR-optical GCPs, ``gcpfree orient --sar``);
- a CSV file with a header ``id,left,right[,left_model,right_model,lidar,landcover,
  checkpoints,sar,sar_model]``, or a JSON list of objects with the same keys (or
  ``{"pairs": [...]}``). Relative paths are relative to the catalog file. Beyond these columns
  a pair may carry the options the reader is given (``options``: the archive's, by their names
  in pair.json's ``params``, :mod:`flows.options`), each kept as the catalog writes it (text
  in a CSV, a JSON value) for the flow to read with its type; an empty cell or null is not
  given;
- the JSON ``gcpfree scenes`` writes (``"format": "gcpfree.scenes"``): its ``pairs`` as above,
  each also naming its two scenes, its block and its figures (:data:`SCENE_PAIR_KEYS`), and
  the ``scenes`` (id, image, model), ``overlaps`` (every two overlapping scenes), ``blocks``
  (the scenes and pairs of each connected component) and ``rejected`` files (path, reason),
  read into :class:`Catalog` and checked against each other.

Reading a catalog checks its form only: a pair whose images are missing, or whose option has a
value of another type, is that pair's failure (:func:`check_pair_inputs`), not the catalog's; a
column no pair may have (neither a column nor an option) is the catalog's. The summary
(``ROOT/summary.csv`` and ``ROOT/summary.json``) lists every pair with its status, the reason
of a failure and the figures its products give (GCP count, check-point and GCP residual RMS,
LE68).
"""

from __future__ import annotations

import csv
import difflib
import io
import math
import re
from collections.abc import Collection
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any

from prefect import task
from prefect.cache_policies import NO_CACHE

from core.choices import VerticalChoice
from core.errors import GcpFreeError, InputError
from core.jsonio import parse_json
from tasks.archive.scene_catalog import (
    SCENES_FORMAT,
    BlockEntry,
    RejectedEntry,
    SceneEntry,
    scene_parts,
)
from tasks.io.pair import PairInputs
from tasks.io.rasters import atomic_write_json, atomic_write_text

REQUIRED = ("id", "left", "right")
OPTIONAL = ("left_model", "right_model", "lidar", "landcover", "checkpoints", "sar",
            "sar_model")
COLUMNS = REQUIRED + OPTIONAL
IMAGE_SUFFIXES = (".tif", ".tiff", ".jp2")
PAIR_ID = re.compile(r"[A-Za-z0-9_][A-Za-z0-9._-]*")
#: ``refused``: the method refused the pair's data with its reason (too flat, too small, too few
#: points: :data:`tasks.archive.runs.REFUSALS`), not a failure of the run
STATUSES = ("done", "skipped", "refused", "failed")
SUMMARY_FORMAT = "gcpfree.archive"
#: a scenes catalog's pair keys beyond the columns: its two scenes, its block, its figures
SCENE_PAIR_KEYS = ("left_scene", "right_scene", "block", "figures")
FOLDER_LAYOUT = ("a pair folder holds left.tif and right.tif, or left/ and right/ folders with "
                 "one image each, e.g. IMAGERY.TIF beside METADATA.DIM")


@dataclass(frozen=True)
class PairEntry:
    """One stereo pair of the catalog: its id (the name of its output folder), its files and
    its own options (name, value as the catalog gives it), in catalog order."""

    id: str
    left: Path
    right: Path
    left_model: Path | None = None
    right_model: Path | None = None
    lidar: Path | None = None
    landcover: Path | None = None
    checkpoints: Path | None = None
    sar: Path | None = None
    sar_model: Path | None = None
    options: tuple[tuple[str, Any], ...] = ()

    def pair_inputs(self, reference: Path | None = None, srtm_dir: Path | None = None,
                    reference_vertical: VerticalChoice = "auto") -> PairInputs:
        """The pair's images and models with the ground the archive orients every pair to."""
        return PairInputs(self.left, self.right, self.left_model, self.right_model,
                          reference=reference, reference_vertical=reference_vertical,
                          srtm_dir=srtm_dir)


@dataclass(frozen=True)
class Catalog:
    """The pairs of an archive, in catalog order, and where they were read from; for a
    ``gcpfree scenes`` catalog also its scenes, overlaps (scene id couples), blocks and
    rejected files."""

    source: Path
    pairs: tuple[PairEntry, ...]
    scenes: tuple[SceneEntry, ...] = ()
    overlaps: tuple[tuple[str, str], ...] = ()
    blocks: tuple[BlockEntry, ...] = ()
    rejected: tuple[RejectedEntry, ...] = ()

    @property
    def ids(self) -> tuple[str, ...]:
        return tuple(p.id for p in self.pairs)


# ---------------------------------------------------------------------------- reading


def read_catalog(path: str | Path, options: Collection[str] = ()) -> Catalog:
    """The catalog at ``path``: a directory of pair folders, a ``.csv`` or a ``.json`` file;
    ``options``: the names a pair may carry beyond the columns (the archive's options).

    Raises:
        InputError: the catalog does not exist, cannot be parsed, lists no pair, repeats an
            id, misses a required column or value, or has an unknown column.
    """
    path = Path(path)
    if not path.exists():
        raise InputError(f"catalog {path} does not exist; give a folder of pair folders or a "
                         "CSV/JSON list of pairs")
    extra: dict[str, Any] = {}
    if path.is_dir():
        pairs = _pairs_of_directory(path)
    elif path.suffix.lower() == ".csv":
        pairs = _pairs_of_rows(_csv_rows(path, options), path)
    elif path.suffix.lower() == ".json":
        pairs, extra = _json_catalog(path, options)
    else:
        raise InputError(f"catalog {path}: unknown kind; give a folder of pair folders, a .csv "
                         f"or a .json file with the columns {','.join(COLUMNS)}")
    if not pairs:
        raise InputError(f"catalog {path} lists no pair; "
                         + ("add pair folders (" + FOLDER_LAYOUT + ")" if path.is_dir()
                            else "gcpfree scenes found no stereo pair among its scenes (see "
                            "its overlaps' reasons; the thresholds are options)" if extra
                            else "add one row per pair"))
    seen: set[str] = set()
    for p in pairs:
        if p.id in seen:
            raise InputError(f"catalog {path}: pair id {p.id!r} appears twice; ids name the "
                             "output folders and must be unique")
        seen.add(p.id)
    return Catalog(path, tuple(pairs), **extra)


def _transient(task: Any, task_run: Any, state: Any) -> bool:
    """Retry I/O failures, never a malformed catalog (it would fail the same way again)."""
    return not isinstance(getattr(state, "data", None), GcpFreeError)


@task(name="read-catalog", retries=2, retry_delay_seconds=1, retry_condition_fn=_transient,
      cache_policy=NO_CACHE)
def load_catalog(path: Path, options: Collection[str] = ()) -> Catalog:
    """:func:`read_catalog` as a task: retried on I/O errors (network file systems)."""
    return read_catalog(path, options)


def _read_text(path: Path) -> str:
    try:
        return path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:
        raise InputError(f"catalog {path} is not UTF-8 text ({exc.reason}); give a CSV or JSON "
                         "file") from exc
    except OSError as exc:
        raise InputError(f"cannot read catalog {path}: {exc.strerror}") from exc


def _csv_rows(path: Path, options: Collection[str]) -> list[tuple[str, dict[str, Any]]]:
    text = _read_text(path)
    try:
        reader = csv.DictReader(io.StringIO(text), skipinitialspace=True)
        header = [h.strip() for h in (reader.fieldnames or []) if h is not None]
        rows = list(reader)
    except csv.Error as exc:
        raise InputError(f"catalog {path} is not valid CSV: {exc}") from exc
    if not header:
        raise InputError(f"catalog {path} is empty; its first line is the header "
                         f"{','.join(COLUMNS)} (id,left,right required)")
    _check_columns(header, path, options)
    out = []
    for n, row in enumerate(rows, start=2):
        if None in row:  # more values than header columns
            raise InputError(f"catalog {path} line {n}: more values than the header's "
                             f"{len(header)} columns")
        values = {(k or "").strip(): (v.strip() if isinstance(v, str) else v)
                  for k, v in row.items()}
        if not any(values.values()):
            continue  # blank line
        out.append((f"line {n}", values))
    return out


def _json_doc(path: Path) -> Any:
    try:
        return parse_json(_read_text(path), f"catalog {path}")
    except InputError as exc:
        raise InputError(f"{exc}; give a list of pairs") from None


def _json_catalog(path: Path, options: Collection[str]
                  ) -> tuple[list[PairEntry], dict[str, Any]]:
    """A JSON catalog's pairs, and for a ``gcpfree scenes`` one its other parts."""
    doc = _json_doc(path)
    if isinstance(doc, dict) and doc.get("format") == SCENES_FORMAT:
        return _scenes_catalog(doc, path, options)
    return _pairs_of_rows(_json_rows(doc, path, options), path), {}


def _json_rows(doc: Any, path: Path, options: Collection[str], extra_keys: tuple[str, ...] = ()
               ) -> list[tuple[str, dict[str, Any]]]:
    """The pair objects of a JSON catalog (``extra_keys``: allowed beyond the columns, not
    read)."""
    if isinstance(doc, dict) and "pairs" in doc:
        doc = doc["pairs"]
    if not isinstance(doc, list):
        raise InputError(f"catalog {path}: expected a JSON list of pairs (objects with "
                         f"{', '.join(REQUIRED)}), or {{\"pairs\": [...]}}")
    out = []
    for i, item in enumerate(doc):
        if not isinstance(item, dict):
            raise InputError(f"catalog {path}: pair {i} is a {type(item).__name__}, not an "
                             f"object with {', '.join(REQUIRED)}")
        _check_columns([k for k in item if k not in extra_keys], path, options)
        out.append((f"pair {i}", {k: v for k, v in item.items() if k not in extra_keys}))
    return out


def _scenes_catalog(doc: dict[str, Any], path: Path, options: Collection[str]
                    ) -> tuple[list[PairEntry], dict[str, Any]]:
    """The pairs of a ``gcpfree scenes`` catalog and its other parts, checked against each
    other (:func:`tasks.archive.scene_catalog.scene_parts`)."""
    if doc.get("version") != 1:
        raise InputError(f"catalog {path}: {SCENES_FORMAT} version {doc.get('version')!r} is "
                         "not 1; write it again with this gcpfree's scenes command")
    rows = doc.get("pairs", [])
    pairs = _pairs_of_rows(_json_rows(rows, path, options, SCENE_PAIR_KEYS), path)
    return pairs, scene_parts(doc, path, {p.id for p in pairs},
                              lambda v: _resolve(v, path.parent), _checked_id)


def _check_columns(names: list[str], path: Path, options: Collection[str]) -> None:
    unknown = [str(n) for n in names if n not in COLUMNS and n not in options]
    if unknown:
        close = [m for n in unknown for m in difflib.get_close_matches(n, (*COLUMNS, *options), 1)]
        raise InputError(f"catalog {path}: unknown column(s) {', '.join(unknown)}; "
                         + (f"did you mean {', '.join(close)}? " if close else "")
                         + f"the columns are {','.join(COLUMNS)}"
                         + (f", and {len(options)} options (gcpfree archive --help)"
                            if options else ""))
    missing = [n for n in REQUIRED if n not in names]
    if missing:
        raise InputError(f"catalog {path}: missing column(s) {', '.join(missing)}; "
                         f"id,left,right are required")


def _pairs_of_rows(rows: list[tuple[str, dict[str, Any]]], path: Path) -> list[PairEntry]:
    base = path.parent
    pairs = []
    for where, row in rows:
        values: dict[str, Any] = {}
        for key in COLUMNS:
            v = row.get(key)
            if v is not None and not isinstance(v, str):
                raise InputError(f"catalog {path} {where}: {key} must be a string, not "
                                 f"{type(v).__name__}")
            v = (v or "").strip()
            if not v:
                if key in REQUIRED:
                    raise InputError(f"catalog {path} {where}: {key} is empty; every pair "
                                     "needs an id, a left and a right image")
                continue
            values[key] = v if key == "id" else _resolve(v, base)
        options = tuple((k, _frozen(v)) for k, v in row.items() if k not in COLUMNS
                        and v is not None and v != "")  # empty or null: not given
        pairs.append(PairEntry(id=_checked_id(values["id"], f"catalog {path} {where}"),
                               **{k: v for k, v in values.items() if k != "id"},
                               options=options))
    return pairs


def _frozen(value: Any) -> Any:
    """A JSON value with its lists as tuples (a :class:`PairEntry` is a value)."""
    return tuple(map(_frozen, value)) if isinstance(value, list) else value


def _resolve(value: str, base: Path) -> Path:
    p = Path(value).expanduser()
    return p if p.is_absolute() else base / p


def _checked_id(pair_id: str, where: str) -> str:
    if not PAIR_ID.fullmatch(pair_id):
        raise InputError(f"{where}: pair id {pair_id!r} is not a folder name; use letters, "
                         "digits, '.', '_' and '-' (not starting with '.' or '-')")
    return pair_id


def _pairs_of_directory(path: Path) -> list[PairEntry]:
    folders = sorted(d for d in path.iterdir()
                     if d.is_dir() and not d.name.startswith((".", "_")))
    return [_pair_of_folder(d) for d in folders]


def _one_image(folder: Path) -> Path | None:
    if not folder.is_dir():
        return None
    files = sorted(f for f in folder.iterdir() if f.is_file())
    imagery = [f for f in files if f.stem.upper() == "IMAGERY"
               and f.suffix.lower() in IMAGE_SUFFIXES]
    if imagery:
        return imagery[0]
    images = [f for f in files if f.suffix.lower() in IMAGE_SUFFIXES]
    return images[0] if len(images) == 1 else None


def _first(folder: Path, names: tuple[str, ...]) -> Path | None:
    for where in (folder, folder / "truth"):
        for name in names:
            if (where / name).is_file():
                return where / name
    return None


def _image(folder: Path, side: str) -> Path:
    for name in (f"{side}.tif", f"{side}.tiff", f"{side}.TIF"):
        if (folder / name).is_file():
            return folder / name
    return _one_image(folder / side) or folder / f"{side}.tif"


def _pair_of_folder(folder: Path) -> PairEntry:
    """A pair folder's files; an image not found is given as the expected ``left.tif`` /
    ``right.tif``, so that the pair fails on its own with a clear reason."""
    lidar = _first(folder, ("lidar.laz", "lidar.las"))
    return PairEntry(
        id=_checked_id(folder.name, f"catalog folder {folder}"),
        left=_image(folder, "left"), right=_image(folder, "right"), lidar=lidar,
        landcover=_first(folder, ("landcover.tif",)) if lidar else None,  # classifies lidar
        checkpoints=_first(folder, ("checkpoints.json", "checkpoints.csv")),
        sar=_first(folder, ("sar.tif", "sar.tiff")))


def check_pair_inputs(entry: PairEntry) -> None:
    """The pair's files exist: a clear reason before its orientation starts.

    Raises:
        InputError: an image or a named file is missing.
    """
    for side, image in (("left", entry.left), ("right", entry.right)):
        if not Path(image).is_file():
            raise InputError(f"{side} image {image} does not exist; {FOLDER_LAYOUT}, or "
                             "give the images in a CSV/JSON catalog")
    for key in OPTIONAL:
        p = getattr(entry, key)
        if p is not None and not Path(p).is_file():
            raise InputError(f"{key.replace('_', ' ')} {p} of pair {entry.id} does not "
                             "exist; fix the catalog")


# ---------------------------------------------------------------------------- the summary


@dataclass(frozen=True)
class PairRow:
    """One line of the summary. Figures are None when unknown (no check points, no lidar, a
    failed pair). ``cp_*``: check-point residual RMS after orientation; ``gcp_*``: residual RMS
    of the simulated GCPs; ``le68_m``: LE68 of the DSM against lidar over all classes."""

    id: str
    status: str
    reason: str = ""
    gcps: int | None = None
    cp_left_rms_col_px: float | None = None
    cp_left_rms_row_px: float | None = None
    cp_right_rms_col_px: float | None = None
    cp_right_rms_row_px: float | None = None
    gcp_left_rms_col_px: float | None = None
    gcp_left_rms_row_px: float | None = None
    gcp_right_rms_col_px: float | None = None
    gcp_right_rms_row_px: float | None = None
    le68_m: float | None = None
    out: str = ""

    def __post_init__(self) -> None:
        if self.status not in STATUSES:
            raise ValueError(f"status {self.status!r} is not one of {STATUSES}")


FIELDS = tuple(f.name for f in fields(PairRow))


def _number(v: Any) -> float | None:
    """A finite figure, or None (unknown)."""
    return float(v) if isinstance(v, (int, float)) and math.isfinite(v) else None


def pair_row(entry_id: str, status: str, out: Path, reason: str = "") -> PairRow:
    """The summary line of a pair: its figures read from ``out/report.json``
    (:func:`tasks.absolute.report.read_report`) and ``out/eval.json``
    (:class:`core.evaluation.evaluation_report.EvaluationReport`) when they read back; a failed or
    refused pair reports only its reason."""
    from tasks.absolute.report import read_report
    from tasks.archive.pair import read_evaluation_stats

    figures: dict[str, Any] = {}
    if status not in ("failed", "refused"):
        try:
            report = read_report(Path(out) / "report.json")
        except GcpFreeError:
            report = None
        if report is not None:
            figures["gcps"] = report.gcps.used
            for side in ("left", "right"):
                cp = (report.check_points or {}).get(side)
                fit = report.absolute.images.get(side)
                for axis in ("col", "row"):
                    key = f"rms_{axis}_px"
                    figures[f"cp_{side}_{key}"] = _number(getattr(cp, key, None))
                    figures[f"gcp_{side}_{key}"] = _number(getattr(fit, key, None))
        stats = read_evaluation_stats(Path(out) / "eval.json")
        figures["le68_m"] = _number(stats["all"].le68_m) if stats is not None else None
    return PairRow(id=entry_id, status=status, reason=one_line(reason), out=str(out), **figures)


def one_line(text: str) -> str:
    """The first non-empty line of ``text``, stripped."""
    return next((s.strip() for s in str(text).splitlines() if s.strip()), "")


def summary_csv(rows: list[PairRow] | tuple[PairRow, ...]) -> str:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=FIELDS, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: ("" if v is None else f"{v:.6g}" if isinstance(v, float) else v)
                    for k, v in asdict(r).items()})
    return buf.getvalue()


def summary_doc(rows: list[PairRow] | tuple[PairRow, ...], catalog: Path) -> dict[str, Any]:
    counts = {s: sum(r.status == s for r in rows) for s in STATUSES}
    return {"format": SUMMARY_FORMAT, "version": 1, "catalog": str(catalog), "counts": counts,
            "pairs": [asdict(r) for r in rows]}


@task(name="write-archive-summary", retries=2, retry_delay_seconds=1, cache_policy=NO_CACHE)
def write_summary(rows: tuple[PairRow, ...], root: Path, catalog: Path) -> tuple[Path, Path]:
    """``root/summary.csv`` and ``root/summary.json``, each written atomically."""
    root = Path(root)
    csv_path = atomic_write_text(root / "summary.csv", summary_csv(rows))
    json_path = atomic_write_json(root / "summary.json", summary_doc(rows, catalog))
    return csv_path, json_path


def summary_markdown(rows: list[PairRow] | tuple[PairRow, ...], root: Path) -> str:
    """A short account of the run: counts, the refusals and failures with their reasons,
    where it is."""
    counts = {s: sum(r.status == s for r in rows) for s in STATUSES}
    lines = [f"# Archive reprocessing: {len(rows)} pairs", "",
             (f"{counts['done']} done, {counts['skipped']} skipped (already complete), "
              f"{counts['failed']} failed, {counts['refused']} refused."), "",
             f"Products in `{root}`; the table is `{Path(root) / 'summary.csv'}`."]
    for status, title in (("refused", "Refused pairs"), ("failed", "Failed pairs")):
        listed = [r for r in rows if r.status == status]
        if listed:
            lines += ["", f"## {title}", "", "| pair | reason |", "|---|---|"]
            lines += [f"| {r.id} | {r.reason.replace('|', '/')} |" for r in listed]
    return "\n".join(lines) + "\n"


@task(name="publish-archive-summary", cache_policy=NO_CACHE)
def publish_summary(rows: tuple[PairRow, ...], root: Path) -> None:
    """The summary as Prefect artifacts: a table (one row per pair) and a markdown account."""
    from prefect.artifacts import create_markdown_artifact, create_table_artifact

    create_table_artifact(table=[asdict(r) for r in rows], key="archive-summary",
                          description=f"gcpfree archive: one row per pair ({root})")
    create_markdown_artifact(markdown=summary_markdown(rows, root), key="archive-report",
                             description="gcpfree archive: counts and failures")
