"""`gcpfree archive` throughput and memory (issue 21.7): a catalog of N tiny pairs (one simulated
tiny scene listed N times) reprocessed on a LocalCluster of worker processes.

Runs, in this order, each on a fresh output folder and its own LocalCluster:

- `1 worker`   the peer: the same pairs one at a time in one worker process;
- `2 workers`  the archive as it runs by default on this machine (one pair per worker);
- `2 workers, one killed`  the same, one worker process killed (SIGKILL) once a third of the
  pairs are complete: the figure of what a lost worker costs (its pair is run again elsewhere).

Each prints pairs per minute (wall clock of the whole `reprocess_archive` call, cluster start
and summary included), the peak RSS of each worker process (VmHWM read in the worker, asked
through `client.run`; a worker started again after a kill is a new process, listed apart) and
of this process, and the load average beside the figures (the machine is shared: compare runs of
the same invocation, not across invocations). Prints figures, asserts nothing but the outcome
(every pair done).

    .venv/bin/python bench/perf/bench_archive.py [--pairs 6] [--scene DIR] [--seeded]
        [--runs 1 2 kill]

``--pairs``: the catalog's pairs (default 6); ``--scene``: an existing tiny scene folder, else
one is simulated (about 40 s); ``--seeded``: each pair folder starts with the orientation and
ortho products of one real run, so a pair only writes its report, STAC and manifest (the
throughput of resumed pairs); ``--runs``: which of the three runs (default all).
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import signal
import sys
import tempfile
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from bench.common import load

SEEDED_PRODUCTS = ("report.json", "left.json", "right.json", "gcps.json", "windows.json",
                   "dsm.tif", "dsm.json", "dsm_mask.tif", "dsm_egm96.tif", "dsm_egm96.json",
                   "dsm_egm96_mask.tif", "relative_dem.tif", "relative_dem.json",
                   "relative_dem_mask.tif", "relative", "ortho_left.tif", "ortho_left.json",
                   "ortho_right.tif", "ortho_right.json", "ortho_compare.json",
                   "ortho_discrepancy.tif", "ortho_discrepancy.png")


def peak_rss_mb() -> float:
    """This process's peak resident set size (MB); run in each worker by ``client.run``.

    Linux's VmHWM, the peak of this program's own memory: getrusage's ru_maxrss would report
    the parent's peak in a worker process (spawned by fork and exec, it inherits the maximum of
    the forked copy)."""
    status = Path("/proc/self/status")
    if status.exists():
        for line in status.read_text().splitlines():
            if line.startswith("VmHWM:"):
                return float(line.split()[1]) / 1024.0
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def scene_dir(given: Path | None, tmp: Path) -> Path:
    if given is not None:
        return given
    from tests.scenes import run_scene

    out = tmp / "scene"
    out.mkdir()
    t0 = time.perf_counter()
    run_scene(out, seed=12, jitter=False, lidar=False)
    print(f"tiny scene simulated in {time.perf_counter() - t0:.0f} s ({load()})", flush=True)
    return out


def catalog(base: Path, scene: Path, n: int, seed: Path | None) -> tuple[Path, Path]:
    """``n`` pairs (the scene under ids p00...) and their ROOT, pre-filled from ``seed``."""
    cat, root = base / "catalog", base / "root"
    cat.mkdir(parents=True)
    root.mkdir()
    for i in range(n):
        (cat / f"p{i:02d}").symlink_to(scene)
        if seed is not None:
            (root / f"p{i:02d}").mkdir()
            for name in SEEDED_PRODUCTS:
                src = seed / name
                if src.is_dir():
                    shutil.copytree(src, root / f"p{i:02d}" / name)
                elif src.exists():
                    shutil.copy2(src, root / f"p{i:02d}" / name)
    return cat, root


def kill_after(address: str, root: Path, after: int, killed: list[int]) -> threading.Thread:
    """A thread killing a busy worker's process once ``after`` pairs are complete."""
    from distributed import Client

    def run() -> None:
        with Client(address, timeout=60) as client:
            while len(list(root.glob("*/pair.json"))) < after:
                time.sleep(0.2)
            busy = [w for w, keys in client.processing().items() if keys]
            if busy:
                pid = client.run(os.getpid)[busy[0]]
                os.kill(pid, signal.SIGKILL)
                killed.append(pid)

    th = threading.Thread(target=run, daemon=True)
    th.start()
    return th


def one_run(label: str, base: Path, scene: Path, n: int, workers: int, seed: Path | None,
            kill: bool) -> float:
    """One archive run; prints its figures, returns pairs per minute."""
    from distributed import Client, LocalCluster

    from flows.reprocess_archive import reprocess_archive

    cat, root = catalog(base, scene, n, seed)
    before = load()
    rss: dict[int, float] = {}
    killed: list[int] = []
    with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                      dashboard_address=":0") as cluster, \
            Client(cluster.scheduler_address) as client:
        th = kill_after(cluster.scheduler_address, root, max(1, n // 3), killed) if kill else None
        t0 = time.perf_counter()
        outcome = reprocess_archive(catalog=cat, out=root, reference=scene / "reference.tif",
                                    dask_address=cluster.scheduler_address)
        dt = time.perf_counter() - t0
        if th is not None:
            th.join(timeout=5)
        pids = client.run(os.getpid)
        for w, mb in client.run(peak_rss_mb).items():
            rss[pids[w]] = mb
    if outcome.count("done") != n:
        raise SystemExit(f"{label}: {outcome.lines()}")
    rate = 60.0 * n / dt
    workers_rss = ", ".join(f"pid {p} {mb:.0f} MB" for p, mb in sorted(rss.items()))
    print(f"{label:<24} {n} pairs in {dt:6.1f} s = {rate:5.2f} pairs/min; peak RSS per worker: "
          f"{workers_rss}{f' (killed pid {killed[0]})' if killed else ''}; "
          f"before: {before}, after: {load()}", flush=True)
    return rate


def main(argv: list[str] | None = None) -> None:
    from flows._env import configure_environment

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", type=int, default=6, help="pairs in the catalog (default 6)")
    ap.add_argument("--scene", type=Path, default=None, help="an existing tiny scene folder")
    ap.add_argument("--seeded", action="store_true",
                    help="pairs start with one run's products (resumed pairs)")
    ap.add_argument("--runs", nargs="+", choices=("1", "2", "kill"), default=["1", "2", "kill"],
                    help="1 worker, 2 workers, 2 workers with one killed (default all)")
    args = ap.parse_args(argv)
    if args.pairs < 1:
        ap.error("--pairs must be >= 1")
    n, runs, seeded = args.pairs, args.runs, args.seeded
    tmp = Path(tempfile.mkdtemp(prefix="gcpfree-bench-archive-"))
    configure_environment(prefect_home=tmp / "prefect")
    from prefect.settings import PREFECT_API_URL
    from prefect.testing.utilities import prefect_test_harness

    try:
        scene = scene_dir(args.scene, tmp)
        with prefect_test_harness(server_startup_timeout=120):
            # worker processes report to this server instead of starting one each (~5 s)
            os.environ["PREFECT_API_URL"] = PREFECT_API_URL.value()
            seed = None
            if seeded:
                from flows.reprocess_archive import reprocess_archive

                cat, root = catalog(tmp / "seed", scene, 1, None)
                reprocess_archive(catalog=cat, out=root, reference=scene / "reference.tif",
                                  workers=1, processes=False, dashboard_address=":0")
                seed = root / "p00"
            print(f"{n} {'seeded (report, STAC, manifest only)' if seeded else 'full'} pairs "
                  f"of the tiny scene, {os.cpu_count()} cores", flush=True)
            rates = {}
            for key, label, workers, kill in (("1", "1 worker (peer)", 1, False),
                                              ("2", "2 workers", 2, False),
                                              ("kill", "2 workers, one killed", 2, True)):
                if key in runs:
                    rates[key] = one_run(label, tmp / key, scene, n, workers, seed, kill)
            if "1" in rates and "2" in rates:
                print(f"speed-up 2 workers / 1 worker: {rates['2'] / rates['1']:.2f}")
            if "2" in rates and "kill" in rates:
                print(f"throughput kept with a worker killed: {rates['kill'] / rates['2']:.2f}")
        print(f"this process peak RSS {peak_rss_mb():.0f} MB")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
