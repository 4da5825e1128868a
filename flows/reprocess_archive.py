"""Flow ``reprocess-archive``: every stereo pair of a catalog through the ``pair`` flow, pairs
in parallel on Dask, resumable.

catalog (``tasks.archive.catalog``) -> pairs whose ``ROOT/<id>`` is already complete are skipped
(:func:`tasks.archive.pair.pair_complete`) -> the others run concurrently, one ``pair`` flow
per pair inside a Dask task (:func:`tasks.archive.runs.process_pair`, on prefect-dask's
``DaskTaskRunner`` as :func:`tasks.scheduling.archive_task_runner` sizes it: a LocalCluster, or
an existing cluster given its scheduler address) -> ``ROOT/summary.csv`` and
``ROOT/summary.json`` -> Prefect artifacts (the summary table, a markdown account); all along,
``ROOT/map.html`` (:mod:`tasks.archive.map`: the pairs' footprints over an SRTM hillshade by
status and stated accuracy, the counts, throughput and slowest steps) refreshed as pairs end,
with the run's ``archive-map`` artifact.

A pair that the method refuses (terrain too flat, too small) or that fails (bad input, any
exception) is recorded as ``refused`` or ``failed`` with its one-line reason and never stops the
others; a rerun processes only the pairs missing, refused or failed. Only I/O
tasks retry (catalog reading, summary writing); the orientation never does, since it would fail
the same way again.

A worker process that dies (killed, out of memory) takes no pair with it: Dask's scheduler runs
its pair again on another worker, up to ``distributed.scheduler.allowed-failures`` deaths (3 by
default); past that the pair is recorded as failed with that reason. Every product is renamed
into place whole, so a pair run again (or rerun after Ctrl-C) finds only whole products, removes
the temporary files of the attempt that died and resumes after its last finished step; a pair
that an attempt finished is kept as it is.

The flow takes flat, JSON-friendly parameters (not one parameter object) so that a deployment
(``gcpfree serve``, ``prefect.yaml``) can state them and the UI can edit them.
"""

from __future__ import annotations

import functools
import sys
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Self

from prefect import flow

from core.choices import VerticalChoice
from tasks.archive.catalog import (
    Catalog,
    PairEntry,
    PairRow,
    load_catalog,
    pair_row,
    publish_summary,
    write_summary,
)
from tasks.archive.map_page import ArchiveMapper
from tasks.archive.pair import complete_pairs
from tasks.archive.runs import PairResult, failure_reason, process_pair, running_ids

DEFAULT_DASHBOARD = ":8787"


@dataclass(frozen=True, eq=False)
class ArchiveOutcome:
    """The summary rows (catalog order), where they were written, the Dask dashboard used."""

    rows: tuple[PairRow, ...]
    summary_csv: Path
    summary_json: Path
    dashboard: str | None = None

    def count(self, status: str) -> int:
        return sum(r.status == status for r in self.rows)

    def lines(self) -> list[str]:
        out = [(f"pairs                 {len(self.rows)}: {self.count('done')} done, "
                f"{self.count('skipped')} skipped (already complete), "
                f"{self.count('refused')} refused, {self.count('failed')} failed")]
        out += [f"{r.status} {r.id:<15} {r.reason}" for r in self.rows
                if r.status in ("refused", "failed")]
        out += [f"summary               {self.summary_csv}",
                f"                      {self.summary_json}"]
        return out


def pair_params(entry: PairEntry, root: Path, srtm_dir: Path | None, reference: Path | None,
                reference_vertical: VerticalChoice = "auto",
                options: Mapping[str, Any] | None = None,
                geoid: Path | None = None):  # -> PairParams
    """The ``pair`` flow's parameters for one pair of the archive into ``root/<id>`` (one
    worker: the archive's parallelism is over pairs): the pair's files, the archive's ground,
    the archive's ``options`` for every pair, then the pair's own from the catalog (by name,
    :mod:`flows.options`). Raises InputError on bad inputs, naming the option."""
    from dataclasses import replace

    from flows.options import with_options
    from flows.orient import OrientParams
    from flows.pair import PairParams

    pair = replace(entry.pair_inputs(reference, srtm_dir, reference_vertical), geoid=geoid)
    params = PairParams(
        OrientParams(pair=pair, out=Path(root) / entry.id, checkpoints=entry.checkpoints,
                     sar=entry.sar, sar_model=entry.sar_model, workers=1, progress=False),
        lidar=entry.lidar, landcover=entry.landcover, pair_id=entry.id)
    params = with_options(params, options or {}, "the archive's options")
    return with_options(params, dict(entry.options), f"pair {entry.id} of the catalog")


def run_pair(entry: PairEntry, root: Path, srtm_dir: Path | None, reference: Path | None,
             reference_vertical: VerticalChoice = "auto",
             options: Mapping[str, Any] | None = None, geoid: Path | None = None) -> None:
    """One pair of the archive through the ``pair`` flow into ``root/<id>`` (one worker: the
    archive's parallelism is over pairs); what :func:`tasks.archive.runs.process_pair` runs
    in a Dask worker. A pair found complete is left as it is; otherwise the temporary files an
    interrupted attempt left (its worker killed, the run stopped by Ctrl-C) are removed and the
    ``pair`` flow resumes at its first missing product."""
    from flows._env import one_line_errors
    from flows.pair import manifest_defaults, pair_flow
    from tasks.archive.pair import pair_complete, remove_leftovers

    out = Path(root) / entry.id
    with one_line_errors():
        params = pair_params(entry, root, srtm_dir, reference, reference_vertical, options,
                             geoid)
    # an earlier attempt finished it with the same inputs and options, then its worker died
    if pair_complete(out, params.to_dict(), manifest_defaults()):
        print(f"pair {entry.id} already complete in {out}")
        return
    removed = remove_leftovers(out)
    if removed:
        print(f"pair {entry.id}: removed {len(removed)} temporary file(s) of an interrupted "
              f"attempt ({', '.join(p.name for p in removed)})")
    with one_line_errors():
        pair_flow(params)


def _dashboard_link() -> str | None:
    from prefect.context import FlowRunContext

    ctx = FlowRunContext.get()
    client = getattr(ctx.task_runner, "client", None) if ctx else None
    return getattr(client, "dashboard_link", None)


@flow(name="archive-pairs")
def run_pairs(entries: list[PairEntry], root: Path, srtm_dir: Path | None = None,
              reference: Path | None = None, options: dict[str, Any] | None = None,
              progress: bool = False, reference_vertical: VerticalChoice = "auto",
              geoid: Path | None = None, catalog: Catalog | None = None,
              ) -> tuple[list[PairResult], str | None]:
    """The pairs submitted to the flow's Dask task runner; (results in entry order, the Dask
    dashboard link). With the ``catalog`` they belong to, its map is refreshed as each pair
    ends (:class:`tasks.archive.map_page.ArchiveMapper`)."""
    from prefect.futures import as_completed

    link = _dashboard_link()
    if link:
        from prefect.artifacts import create_link_artifact

        print(f"Dask dashboard        {link}", flush=True)
        create_link_artifact(link, link_text="Dask dashboard", key="dask-dashboard",
                             description="the Dask cluster running the pairs")
    run = functools.partial(run_pair, root=Path(root), srtm_dir=srtm_dir, reference=reference,
                            reference_vertical=reference_vertical, options=options,
                            geoid=geoid)
    futures = {process_pair.submit(e, run): e for e in entries}
    results: dict[str, PairResult] = {}
    mapper = _mapper(catalog, root, entries, srtm_dir, reference)
    _refresh(mapper, futures, results)
    with _PairProgress(len(entries), progress) as bar:
        for future in as_completed(list(futures)):
            entry = futures[future]
            try:
                result = future.result()
            except Exception as exc:  # noqa: BLE001 - the task was lost (e.g. its workers died)
                result = PairResult(entry.id, "failed", failure_reason(exc))
            results[entry.id] = result
            bar.advance(result)
            if mapper is not None:
                mapper.ended(result)
                _refresh(mapper, futures, results)
    return [results[e.id] for e in entries], link


def _mapper(catalog: Catalog | None, root: Path, entries: list[PairEntry],
            srtm_dir: Path | None, reference: Path | None) -> ArchiveMapper | None:
    """The map of the run (the catalog's pairs not in ``entries`` kept from an earlier run)."""
    if catalog is None:
        return None
    todo = {e.id for e in entries}
    return ArchiveMapper(catalog, Path(root), [i for i in catalog.ids if i not in todo],
                         srtm_dir, reference)


def _refresh(mapper: ArchiveMapper | None, futures: dict[Any, PairEntry],
             results: dict[str, PairResult]) -> None:
    """The map refreshed, the pairs not ended that Dask is processing shown running."""
    if mapper is not None:
        mapper.try_refresh(running_ids({f: e for f, e in futures.items()
                                        if e.id not in results}))


class _PairProgress:
    """A progress bar over pairs on stderr (rich, Prefect's own console library)."""

    def __init__(self, total: int, enabled: bool) -> None:
        self.total, self.enabled, self.failed = total, enabled, 0
        self._bar = None

    def __enter__(self) -> Self:
        if self.enabled:
            from rich.console import Console
            from rich.progress import (
                BarColumn,
                MofNCompleteColumn,
                Progress,
                TextColumn,
                TimeElapsedColumn,
            )

            self._bar = Progress(TextColumn("pairs"), BarColumn(), MofNCompleteColumn(),
                                 TextColumn("{task.description}"), TimeElapsedColumn(),
                                 console=Console(file=sys.stderr))
            self._bar.__enter__()
            self._task = self._bar.add_task("", total=self.total)
        return self

    def advance(self, result: PairResult) -> None:
        self.failed += result.status == "failed"
        if self._bar is not None:
            self._bar.update(self._task, advance=1,
                             description=f"last {result.id} {result.status}, "
                                         f"{self.failed} failed")

    def __exit__(self, *exc: object) -> None:
        if self._bar is not None:
            self._bar.__exit__(*exc)


@flow(name="reprocess-archive")
def reprocess_archive(catalog: Path, out: Path, srtm_dir: Path | None = None,
                      reference: Path | None = None, dask_address: str | None = None,
                      workers: int | None = None, processes: bool = True,
                      dashboard_address: str = DEFAULT_DASHBOARD,
                      options: dict[str, Any] | None = None, progress: bool = False,
                      reference_vertical: VerticalChoice = "auto",
                      geoid: Path | None = None) -> ArchiveOutcome:
    """Catalog -> skip complete pairs -> the rest on Dask -> summary.csv/json + artifacts.

    ``catalog``: a folder of pair folders or a CSV/JSON list (``tasks.archive.catalog``);
    ``out``: ROOT, one folder per pair id. ``srtm_dir`` or ``reference`` (its heights
    ``reference_vertical``): the ground every pair is oriented to, ``geoid`` the grid its
    orthometric heights refer to when not EGM96 (``--geoid``). ``options``: the options of
    every pair by name (:mod:`flows.options`: ``{"self_calibrate": true, "surface.radius_m":
    3000}``), a catalog's own for a pair winning over them.
    ``dask_address``: an existing scheduler (``tcp://HOST:PORT``), else a LocalCluster of
    ``workers`` (default: one per core, at most one per pair) single-threaded workers, in
    processes unless ``processes`` is False.
    """
    from core.errors import InputError
    from flows.options import OPTIONS
    from flows.pair import manifest_defaults
    from tasks.scheduling import archive_task_runner, schedule

    if (srtm_dir is None) == (reference is None):
        raise InputError("gcpfree archive needs the ground to orient every pair to: give "
                         "--srtm-dir or --reference (one of them)")
    schedule(workers=workers)  # --workers checked before the catalog is read
    cat = load_catalog(Path(catalog), tuple(OPTIONS))
    root = Path(out)
    root.mkdir(parents=True, exist_ok=True)
    wanted = {}  # the parameters each pair would run with: a pair made with others is redone
    for e in cat.pairs:
        try:
            wanted[e.id] = pair_params(e, root, srtm_dir, reference, reference_vertical,
                                       options, geoid).to_dict()
        except InputError:
            pass  # not complete: its run reports the bad input
    done_before = complete_pairs(wanted, root, manifest_defaults())
    todo = [e for e in cat.pairs if e.id not in done_before]
    results: dict[str, PairResult] = {}
    link = None
    if todo:
        runner = archive_task_runner(dask_address, len(todo), workers, processes,
                                     dashboard_address)
        found, link = run_pairs.with_options(task_runner=runner)(
            todo, root, srtm_dir, reference, options, progress,
            reference_vertical=reference_vertical, geoid=geoid, catalog=cat)
        results = {r.id: r for r in found}
    rows = tuple(
        pair_row(e.id, "skipped", root / e.id) if e.id in done_before
        else pair_row(e.id, results[e.id].status, root / e.id, results[e.id].reason)
        for e in cat.pairs)
    csv_path, json_path = write_summary(rows, root, cat.source)
    publish_summary(rows, root)
    ArchiveMapper(cat, root, done_before, srtm_dir, reference, results.values()).try_refresh()
    outcome = ArchiveOutcome(rows, csv_path, json_path, link)
    return outcome
