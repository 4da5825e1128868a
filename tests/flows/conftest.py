"""Fixtures the flow tests share across files: the archive runs of test_archive.py, whose
finished real pair test_archive_kill.py copies."""

from __future__ import annotations

import contextlib
import csv
import io
import json
import os
import shutil
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

# what a finished pair holds up to its orthos (the report, the STAC catalog and the manifest
# are left to a run that resumes it)
SEEDED = ("report.json", "left.json", "right.json", "gcps.json", "windows.json", "dsm.tif",
          "dsm.json", "dsm_mask.tif", "dsm_egm96.tif", "dsm_egm96.json", "dsm_egm96_mask.tif",
          "relative_dem.tif", "relative_dem.json", "relative_dem_mask.tif", "relative",
          "ortho_left.tif", "ortho_left.json", "ortho_right.tif", "ortho_right.json",
          "ortho_compare.json", "ortho_discrepancy.tif", "ortho_discrepancy.png")


def seed_pair(finished: Path, out: Path) -> None:
    """``out`` holds the finished pair's products up to its orthos: an earlier run
    interrupted after them, as the pair flow resumes it."""
    out.mkdir(parents=True)
    for name in SEEDED:
        src = finished / name
        if src.is_dir():
            shutil.copytree(src, out / name)
        else:
            shutil.copy2(src, out / name)


@dataclass(frozen=True)
class ExternalCluster:
    """A Dask cluster started apart from the test process: the scheduler's address, its
    dashboard port and the process id of its only worker."""

    address: str
    dashboard_port: int
    worker_pid: int


@contextlib.contextmanager
def external_dask_cluster(base: Path) -> Iterator[ExternalCluster]:
    """A separately started ``dask scheduler`` and one ``dask worker`` process (no nanny: the
    process started here is the worker) on 127.0.0.1, the worker pointed at the test's Prefect
    API; the scheduler records its task stream from the start."""
    from prefect.settings import PREFECT_API_URL

    dask = Path(sys.executable).parent / "dask"
    info = base / "scheduler.json"
    env = {**os.environ, "PREFECT_API_URL": PREFECT_API_URL.value()}
    log = (base / "dask.log").open("w")
    procs = [subprocess.Popen([str(dask), "scheduler", "--host", "127.0.0.1", "--port", "0",
                               "--dashboard-address", "127.0.0.1:0", "--scheduler-file",
                               str(info)], env=env, stdout=log, stderr=subprocess.STDOUT)]
    try:
        end = time.monotonic() + 120
        while not info.exists() and time.monotonic() < end and procs[0].poll() is None:
            time.sleep(0.2)
        assert info.exists(), (base / "dask.log").read_text()
        procs.append(subprocess.Popen(
            [str(dask), "worker", "--scheduler-file", str(info), "--nthreads", "1",
             "--no-nanny", "--no-dashboard", "--host", "127.0.0.1"],
            env=env, stdout=log, stderr=subprocess.STDOUT))
        address = json.loads(info.read_text())["address"]
        from distributed import Client

        with Client(address, timeout=60) as client:
            client.wait_for_workers(1, timeout=120)
            client.get_task_stream()  # installs the scheduler's task-stream recorder
            port = client.scheduler_info()["services"]["dashboard"]
        yield ExternalCluster(address, port, procs[1].pid)
    finally:
        for p in reversed(procs):
            p.terminate()
            try:
                p.wait(timeout=30)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
        log.close()


@dataclass(frozen=True)
class ExternalRun:
    """The archive of the tiny clean pair and a pair without images run on an external
    cluster: its ROOT, outcome and summary.csv text, the cluster, the scheduler's task stream
    and each worker's process id (asked of the worker) after the run."""

    root: Path
    outcome: Any
    summary_csv: str
    cluster: ExternalCluster
    stream: list[dict[str, Any]]
    pids: dict[str, int]


@pytest.fixture(scope="session")
def external_archive(tiny_clean_scene, tmp_path_factory, prefect_harness) -> ExternalRun:
    """``gcpfree archive`` of {real: the tiny clean pair, broken: no images} on a separately
    started scheduler and worker (tests/flows/test_archive.py): the one archive run of the
    session that orients the real pair (20-30 s), whose products the others resume from."""
    from distributed import Client

    from flows.reprocess_archive import reprocess_archive

    scene, _ = tiny_clean_scene
    base = tmp_path_factory.mktemp("external_archive")
    cat, root = base / "catalog", base / "root"
    cat.mkdir()
    (cat / "real").symlink_to(scene)
    (cat / "broken").mkdir()
    with external_dask_cluster(base) as cluster:
        outcome = reprocess_archive(catalog=cat, out=root, reference=scene / "reference.tif",
                                    dask_address=cluster.address)
        with Client(cluster.address, timeout=60) as client:
            stream = client.get_task_stream()
            pids = client.run(os.getpid)  # each worker's process id, asked of the worker
    return ExternalRun(root, outcome, (root / "summary.csv").read_text(), cluster, stream,
                       pids)


def finished_row(run: ExternalRun) -> dict[str, str]:
    """The real pair's row of the external run's summary.csv (that pair done)."""
    row = {r["id"]: r for r in csv.DictReader(io.StringIO(run.summary_csv))}["real"]
    assert row["status"] == "done", row
    return row


@pytest.fixture(scope="session")
def archive(tiny_clean_scene, external_archive, tmp_path_factory, prefect_harness):
    """``gcpfree archive``'s first run on four pairs (tests/flows/test_archive.py), on a
    LocalCluster of one thread worker: (scene, catalog, root, outcome, summary.csv text,
    summary.json document, the finished pair's files before the run). Its real pair holds the
    external run's products up to its orthos (oriented for real there: an orientation of the
    tiny pair takes 20-30 s), as a run interrupted after them leaves it: this run resumes it
    beside the failing pairs."""
    from flows.reprocess_archive import pair_params, reprocess_archive
    from tasks.archive.catalog import load_catalog
    from tests.flows.test_archive import FINISHED_EVAL, FINISHED_REPORT, complete_pair, snapshot

    scene, _ = tiny_clean_scene
    base = tmp_path_factory.mktemp("archive")
    cat, root = base / "catalog", base / "root"
    cat.mkdir()
    (cat / "real").symlink_to(scene)  # the simulator's folder: left.tif, right.tif, truth/
    (cat / "finished").mkdir()  # no images: processing it would fail
    (cat / "broken").mkdir()
    (cat / "broken" / "notes.txt").write_text("images lost")
    bad = cat / "badmeta"  # the real images, the left one's metadata malformed
    bad.mkdir()
    for name in ("left.tif", "right.tif", "right.json"):
        (bad / name).symlink_to(scene / name)
    (bad / "left.json").write_text('{"format": "gcpfree.pushbroom", "orbit": [1, 2')
    # finished by an earlier run of this archive with the same options (its images since lost)
    entry = next(e for e in load_catalog(cat).pairs if e.id == "finished")
    complete_pair(root / "finished", FINISHED_REPORT, FINISHED_EVAL,
                  json.loads(json.dumps(pair_params(entry, root, None,
                                                    scene / "reference.tif").to_dict())))
    before = snapshot(root / "finished")
    seed_pair(external_archive.root / "real", root / "real")
    outcome = reprocess_archive(catalog=cat, out=root, reference=scene / "reference.tif",
                                workers=1, processes=False, dashboard_address=":0")
    return (scene, cat, root, outcome, (root / "summary.csv").read_text(),
            json.loads((root / "summary.json").read_text()), before)
