"""``gcpfree archive`` interrupted: a worker process killed in the middle of a run of 8 pairs
(Dask runs its pair again elsewhere: every pair ends done, the summary lists all 8, no
temporary file is left and every product reads back whole), and a run stopped by Ctrl-C
(exit 130; the rerun processes only the pairs missing and leaves the finished ones untouched).

To stay lean, the pairs are one tiny scene listed under 8 ids, each pair folder already holding
the orientation and ortho products of one real run (an earlier run interrupted after its orthos,
as the pair flow resumes it): each pair then writes its report, STAC catalog and manifest.
"""

from __future__ import annotations

import csv
import io
import os
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from tasks.archive.pair import pair_complete
from tests.flows.conftest import finished_row, seed_pair

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def finished_pair(tiny_clean_scene, external_archive):
    """The tiny clean pair finished by a real run of the archive (its pair ``real``, oriented
    on an external cluster's worker: the session fixture ``external_archive`` of
    tests/flows/conftest.py): (scene folder, the finished pair folder, its summary.csv row)."""
    scene, _ = tiny_clean_scene
    return scene, external_archive.root / "real", finished_row(external_archive)


def seeded_archive(base: Path, scene: Path, finished: Path, n: int) -> tuple[Path, Path]:
    """A catalog of ``n`` pairs (the scene under the ids p00, p01...) and a ROOT where each pair
    holds the finished pair's products up to its orthos: (catalog, ROOT)."""
    cat, root = base / "catalog", base / "root"
    cat.mkdir(parents=True)
    for i in range(n):
        (cat / f"p{i:02d}").symlink_to(scene)
        seed_pair(finished, root / f"p{i:02d}")
    return cat, root


def temporary_names(root: Path) -> list[str]:
    """Every file or folder under ``root`` with a temporary name: hidden (the atomic writers'
    ``.<name>.tmp*``, the ``.<dem>.work`` folders) or the STAC writer's ``_stac_*``."""
    return sorted(str(p.relative_to(root)) for p in root.rglob("*")
                  if p.name.startswith((".", "_stac")) or ".tmp" in p.name)


def plant_leftovers(out: Path) -> None:
    """What a writer killed mid-way leaves in a pair folder: a raster half written in the
    atomic writer's temporary folder, a half-written JSON, a STAC folder being built."""
    tmp = out / ".ortho_left.tif.tmp3k2j"
    tmp.mkdir()
    (tmp / "tiled.tif").write_bytes((out / "ortho_left.tif").read_bytes()[:5000])
    (out / ".report.json.tmpq81z").write_text('{"format": "gcpfree.orient", "gcps": {')
    (out / "_stac_tmp_x7").mkdir()
    (out / "_stac_tmp_x7" / "catalog.json").write_text("{")


def summary_rows(root: Path) -> dict[str, dict[str, str]]:
    return {r["id"]: r for r in csv.DictReader(io.StringIO((root / "summary.csv").read_text()))}


@dataclass
class Killer:
    """A thread that waits until ``after`` pairs are complete, then kills (SIGKILL) the process
    of a Dask worker that is running a pair."""

    address: str
    root: Path
    after: int
    pid: int | None = None
    complete_at_kill: int = -1
    error: BaseException | None = None
    _thread: threading.Thread = field(init=False)

    def __post_init__(self) -> None:
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        from distributed import Client

        try:
            with Client(self.address, timeout=60) as client:
                end = time.monotonic() + 900
                while len(list(self.root.glob("*/pair.json"))) < self.after:
                    if time.monotonic() > end:
                        raise TimeoutError(f"fewer than {self.after} pairs done in 15 min")
                    time.sleep(0.1)
                busy = [w for w, keys in client.processing().items() if keys]
                pids = client.run(os.getpid)  # each worker's process id, asked of the worker
                self.pid = pids[busy[0]]
                self.complete_at_kill = len(list(self.root.glob("*/pair.json")))
                os.kill(self.pid, signal.SIGKILL)
        except BaseException as exc:  # noqa: BLE001 - reported by the test
            self.error = exc

    def join(self) -> None:
        self._thread.join(timeout=60)


@pytest.fixture()
def api_for_workers(prefect_harness, monkeypatch):
    """Worker processes inherit the test server's address (no Prefect server of their own)."""
    from prefect.settings import PREFECT_API_URL

    monkeypatch.setenv("PREFECT_API_URL", PREFECT_API_URL.value())


def test_a_worker_killed_mid_run_loses_no_pair(finished_pair, api_for_workers, tmp_path):
    from distributed import Client, LocalCluster

    from flows.reprocess_archive import reprocess_archive

    scene, finished, finished_row = finished_pair
    # 8 pairs (each about 5 CPU-s: report, STAC, manifest): the kill lands after 3 are
    # complete, while each of the two workers has a pair running and at least 3 still wait
    n = 8
    cat, root = seeded_archive(tmp_path, scene, finished, n)
    plant_leftovers(root / f"p{n - 1:02d}")
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=":0") as cluster:
        killer = Killer(cluster.scheduler_address, root, after=3)
        outcome = reprocess_archive(catalog=cat, out=root, reference=scene / "reference.tif",
                                    dask_address=cluster.scheduler_address)
        killer.join()
        with Client(cluster.scheduler_address, timeout=60) as client:
            pids_after = set(client.run(os.getpid).values())
    assert killer.error is None, killer.error
    assert killer.pid is not None and killer.pid not in pids_after  # that process is gone
    assert 3 <= killer.complete_at_kill < n  # killed in the middle of the run
    ids = [f"p{i:02d}" for i in range(n)]
    assert [(r.id, r.status, r.reason) for r in outcome.rows] == [(i, "done", "") for i in ids]
    rows = summary_rows(root)
    assert list(rows) == ids and {r["status"] for r in rows.values()} == {"done"}
    assert {r["gcps"] for r in rows.values()} == {finished_row["gcps"]}  # read from products
    # nothing half-written: every product each manifest lists reads back with its size, and no
    # temporary name is left (those planted in p07 as a killed writer leaves them: removed)
    assert all(pair_complete(root / i) for i in ids)
    assert temporary_names(root) == []


def test_ctrl_c_then_a_rerun_completes_only_what_is_missing(finished_pair, api_for_workers,
                                                           tmp_path):
    from flows.commands import archive as archive_command
    from tests.flows.test_archive import parse, snapshot

    scene, finished, _ = finished_pair
    # 8 pairs: seeded ones have only evaluation, report and STAC left and finish in a burst,
    # and the workers go on while the command shuts down; with 4, all four were once complete
    # by the time the interrupt was counted
    n = 8
    cat, root = seeded_archive(tmp_path, scene, finished, n)
    argv = ["archive", "--catalog", str(cat), "--out", str(root), "--reference",
            str(scene / "reference.tif"), "--dashboard-address", ":0", "--no-progress"]
    # Ctrl-C as a terminal delivers it: a suite started in the background (``make test &``)
    # hands its children SIGINT ignored, which Python then keeps ignored
    proc = subprocess.Popen([sys.executable, "-m", "flows.cli", *argv, "--workers", "2"],
                            cwd=Path(__file__).resolve().parents[2], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        end = time.monotonic() + 900
        while not list(root.glob("*/pair.json")) and proc.poll() is None:
            assert time.monotonic() < end, "no pair finished in 15 min"
            time.sleep(0.1)
        proc.send_signal(signal.SIGINT)  # Ctrl-C, to the command's process
        out, err = proc.communicate(timeout=300)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 130, (out[-2000:], err[-3000:])
    complete = sorted(p.name for p in root.iterdir() if pair_complete(p))
    assert 1 <= len(complete) < n, complete
    assert (f"interrupted with {len(complete)} of {n} pairs complete in {root}; run the same "
            "command again") in err
    assert not (root / "summary.csv").exists()
    before = {i: snapshot(root / i) for i in complete}

    rc = archive_command.run(parse(*argv[1:], "--workers", "1", "--threads"))
    assert rc == 0
    rows = summary_rows(root)
    assert {i: r["status"] for i, r in rows.items()} == {
        i: "skipped" if i in complete else "done" for i in (f"p{k:02d}" for k in range(n))}
    assert {i: snapshot(root / i) for i in complete} == before  # reused, not a byte touched
    assert all(pair_complete(root / i) for i in rows)
    assert temporary_names(root) == []
