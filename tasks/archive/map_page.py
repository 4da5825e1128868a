"""The archive map of a run as pairs end (:class:`ArchiveMapper`, used by
:mod:`flows.reprocess_archive`): the states and footprints of :mod:`tasks.archive.map` drawn
by :mod:`tasks.archive.map_render` into ``ROOT/map.svg``, ``ROOT/map.html`` and the
``archive-map`` artifact."""

from __future__ import annotations

import time
from collections.abc import Iterable
from pathlib import Path

from prefect import task
from prefect.cache_policies import NO_CACHE

from tasks.archive.catalog import Catalog, one_line
from tasks.archive.map import (
    ArchiveMap,
    PairState,
    catalog_footprints,
    pair_state,
    read_shade,
)
from tasks.archive.runs import PairResult


class ArchiveMapper:
    """The map of one archive run: the pairs ``kept`` (complete from an earlier run) as
    skipped, the others queued until :meth:`ended` gives their result; footprints and relief
    found once; :meth:`refresh` writes the page and publishes the artifact (call it as pairs
    end)."""

    def __init__(self, catalog: Catalog, root: Path, kept: Iterable[str],
                 srtm_dir: Path | None = None, reference: Path | None = None,
                 results: Iterable[PairResult] = ()) -> None:
        self.catalog, self.root = catalog, Path(root)
        self.started = time.time()
        kept = set(kept)
        self.states = {e.id: (pair_state(e.id, "skipped", self.root / e.id) if e.id in kept
                              else PairState(e.id, "queued")) for e in catalog.pairs}
        self.ground = (Path(srtm_dir) if srtm_dir else None,
                       Path(reference) if reference else None)
        self._starts: list[float | None] = []
        for r in results:
            self.ended(r)

    def ended(self, result: PairResult) -> None:
        self.states[result.id] = pair_state(result.id, result.status, self.root / result.id,
                                            result)
        self._starts.append(result.started_s)

    def try_refresh(self, running: Iterable[str] = ()) -> ArchiveMap | None:
        """:meth:`refresh`, a map that cannot be drawn said in one line (never stopping the
        archive)."""
        try:
            return self.refresh(running)
        except Exception as exc:  # noqa: BLE001 - the map is a view of the run, not the run
            print(f"archive map not drawn: {type(exc).__name__}: {one_line(str(exc))}",
                  flush=True)
            return None

    def refresh(self, running: Iterable[str] = ()) -> ArchiveMap:
        """The page written and the artifact published with the pairs ``running`` now (the
        others not ended stay queued)."""
        running = set(running)
        states = tuple(PairState(s.id, "running") if s.status == "queued" and s.id in running
                       else s for s in self.states.values())
        footprints = catalog_footprints(self.catalog)
        box = footprints.box()
        shade, note = (read_shade(box, self.ground[1], self.ground[0]) if box is not None
                       else (None, "no hillshade: no pair has a footprint"))
        # the run began when this map did, or when its first pair started on a worker
        began = min([self.started, *(r for r in self._starts if r is not None)])
        m = ArchiveMap(self.root, states, footprints, shade, note, time.time() - began)
        write_archive_map(m)
        return m


@task(name="write-archive-map", cache_policy=NO_CACHE)
def write_archive_map(m: ArchiveMap) -> tuple[Path, Path]:
    """``ROOT/map.svg`` and ``ROOT/map.html`` (each renamed into place whole), and the
    artifact ``archive-map`` (a new version each refresh)."""
    from prefect.artifacts import create_markdown_artifact

    from tasks.archive.map_render import map_html, map_markdown, map_svg
    from tasks.io.rasters import atomic_write_text

    svg = map_svg(m)
    svg_path = atomic_write_text(m.root / "map.svg", svg)
    html_path = atomic_write_text(m.root / "map.html", map_html(m, svg))
    create_markdown_artifact(markdown=map_markdown(m, svg), key="archive-map",
                             description=f"gcpfree archive: the pairs on a map ({m.root})")
    return html_path, svg_path
