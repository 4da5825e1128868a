"""Where the wall time of ``gcpfree dsm`` goes, from the shell, on the Pleiades Reunion ROI of
``bench/perf/bench_dsm_cars.py`` (left pixels 150 150 700 700, 0.5 m, EGM96, ``--no-orient``):
the time a user waits, beside CARS's 229 s on the same ROI (measured once with
``bench/perf/bench_dsm_cars.py``; target issue 21: <= 0.1 x, i.e. <= 23 s).

Each run is a fresh process started here, timed from before its start to its exit:

- ``gcpfree``: the command as a user types it (``python -m flows.cli dsm ...``); its temporary
  Prefect API server (no server configured) starts at once and boots while the command
  imports its modules and checks its inputs (``flows._env.prefect_api``);
- ``prefect's own``: the same command with Prefect's own ephemeral mode, as before issue 21:
  the server imported into the command's process and started inside the first flow call.

Both in a fresh ``PREFECT_HOME`` (a user's first run: Prefect creates its database) and again
in the same one (every later run). Then one instrumented run of each prints the timeline: the
interpreter up, the command's modules imported, the API ready, each task of the flow, the exit.

    .venv/bin/python bench/perf/bench_dsm_wall.py [--repeat N]

Prints figures with the load average (2 shared cores: compare the two variants of the same
round, not figures across rounds); asserts nothing.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
DATA = REPO / "tests" / "data" / "pleiades_reunion"
CARS_S = 229.0  # CARS 1.3.0 on the same ROI, two workers (bench/perf/bench_dsm_cars.py)

ARGV = ["dsm", "--left", str(DATA / "img_01.tif"), "--right", str(DATA / "img_02.tif"),
        "--roi", "150", "150", "700", "700", "--resolution", "0.5", "--vertical", "egm96",
        "--no-orient", "--no-progress"]

# the command with Prefect's own ephemeral mode: flows._env.prefect_api made a no-op
PREFECT_OWN = """
import contextlib, sys
import flows._env as env
class _Own:
    def ready(self):
        return None
@contextlib.contextmanager
def _own():
    yield _Own()
env.prefect_api = _own
import flows.cli
sys.exit(flows.cli.main(sys.argv[1:]))
"""

# a timeline of one run: wall-clock marks (seconds since the shell started the process, given
# in BENCH_T0) around the steps, printed on stderr at exit. The modules are wrapped as they are
# imported (an import hook), so the command imports them when it would anyway.
TIMELINE = """
import os, sys, time
T0 = float(os.environ["BENCH_T0"])
marks = [("interpreter up", time.time() - T0)]
def mark(name):
    marks.append((name, time.time() - T0))
import atexit, importlib.abc, importlib.machinery, json
@atexit.register
def _report():
    mark("exit")
    print("TIMELINE " + json.dumps(marks), file=sys.stderr)
import flows._env as env
env.configure_environment(verbose=False)  # as flows.cli.main, before Prefect is imported
own = sys.argv[1] == "own"
def wrap(module, name, label=None):
    f = getattr(module, name)
    def w(*a, **k):
        mark(f"{label or name}: start")
        r = f(*a, **k)
        mark(f"{label or name}: end")
        return r
    setattr(module, name, w)
def wrap_task(module, name):
    t = getattr(module, name)
    wrap(t, "fn", name)
def patch_dem(m):
    for name in ("plan_dense", "match_tiles", "grid_dem_cog"):
        wrap_task(m, name)
def patch_flow(m):
    mark("flows.dsm imported (Prefect and the tasks with it)")
    wrap(m, "pair_dem", "flow body (flow run created)")
def patch_cmd(m):
    wrap(m, "check_pair")
PATCHES = {"tasks.dense.dem": patch_dem, "flows.dsm": patch_flow, "flows.commands.dsm": patch_cmd}
class Hook(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name not in PATCHES:
            return None
        spec = importlib.machinery.PathFinder.find_spec(name, path)
        run = spec.loader.exec_module
        def exec_module(module, _run=run, _name=name):
            _run(module)
            PATCHES[_name](module)
        spec.loader.exec_module = exec_module
        return spec
sys.meta_path.insert(0, Hook())
if own:
    import contextlib
    class _Own:
        def ready(self):
            return None
    @contextlib.contextmanager
    def _own():
        import prefect
        mark("prefect imported (no server started here)")
        yield _Own()
    env.prefect_api = _own
else:
    _start, _ready, _close = env.PrefectApi.start, env.PrefectApi.ready, env.PrefectApi.close
    def start(self, *a, **k):
        mark(f"temporary server started (Prefect imported: {'prefect' in sys.modules})")
        return _start(self, *a, **k)
    def ready(self, *a, **k):
        mark("inputs checked, flow imported: waiting for the server")
        r = _ready(self, *a, **k)
        mark("server healthy, Prefect pointed at it")
        return r
    def close(self, *a, **k):
        mark("flow returned: drain and stop the server")
        r = _close(self, *a, **k)
        mark("server stopped")
        return r
    env.PrefectApi.start, env.PrefectApi.ready, env.PrefectApi.close = start, ready, close
import flows.cli
rc = flows.cli.main(sys.argv[2:])
mark("command returned")
sys.exit(rc)
"""


def run(code: list[str], home: Path, out: Path) -> tuple[float, float, str]:
    """Wall seconds of one process from before its start to its exit, the CPU seconds of it
    and of the processes it waited for (its Prefect server, its workers), and its stderr."""
    env = dict(os.environ, PREFECT_HOME=str(home), DASK_TEMPORARY_DIRECTORY=str(home / "dask"),
               BENCH_T0=repr(time.time()))
    env.pop("PREFECT_API_URL", None)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    r = subprocess.run([sys.executable, *code, "--out", str(out)], cwd=REPO, env=env,
                       capture_output=True, text=True, check=False)
    dt = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if r.returncode:
        raise SystemExit(f"{' '.join(code[:2])} failed:\n{r.stdout[-2000:]}\n{r.stderr[-3000:]}")
    cpu = after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime
    return dt, cpu, r.stderr


def variants() -> dict[str, list[str]]:
    return {"gcpfree": ["-m", "flows.cli", *ARGV], "prefect's own": ["-c", PREFECT_OWN, *ARGV]}


def print_timeline(stderr: str) -> None:
    line = next(ln for ln in stderr.splitlines() if ln.startswith("TIMELINE "))
    marks = json.loads(line[len("TIMELINE "):])
    prev = 0.0
    for name, t in marks:
        print(f"    {t:6.2f} s  (+{t - prev:5.2f})  {name}")
        prev = t


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=2, help="rounds of both variants (default 2)")
    args = ap.parse_args()
    print(f"gcpfree dsm on the Reunion ROI, {os.cpu_count()} cores; CARS {CARS_S:.0f} s "
          f"(target <= {0.1 * CARS_S:.1f} s)")
    times: dict[tuple[str, str], list[tuple[float, float]]] = {}
    with tempfile.TemporaryDirectory(prefix="bench-dsm-wall-") as tmp_name:
        tmp = Path(tmp_name)
        for i in range(args.repeat):
            for name, code in variants().items():
                home = tmp / f"home_{i}_{name.replace(' ', '_').replace(chr(39), '')}"
                for when in ("first run", "later run"):  # a fresh PREFECT_HOME, then the same
                    load = os.getloadavg()[0]
                    dt, cpu, _ = run(code, home, tmp / "dsm.tif")
                    times.setdefault((name, when), []).append((dt, cpu))
                    print(f"round {i + 1}  {name:14s} {when}: {dt:6.1f} s, {cpu:5.1f} s CPU  "
                          f"(load average {load:.1f} before, {os.getloadavg()[0]:.1f} after)",
                          flush=True)
        print("median wall time from the shell (and CPU), and vs CARS's 229 s:")
        for (name, when), ts in times.items():
            med = statistics.median(t for t, _ in ts)
            cpu = statistics.median(c for _, c in ts)
            print(f"  {name:14s} {when}: {med:6.1f} s ({cpu:5.1f} s CPU)   "
                  f"{med / CARS_S:.3f} x CARS")
        for name, flag in (("gcpfree", "new"), ("prefect's own", "own")):
            home = tmp / f"timeline_{flag}"
            run(["-c", TIMELINE, flag, *ARGV], home, tmp / "dsm.tif")  # its database made
            load = os.getloadavg()[0]
            dt, cpu, err = run(["-c", TIMELINE, flag, *ARGV], home, tmp / "dsm.tif")
            print(f"timeline of a later run, {name} ({dt:.1f} s, {cpu:.1f} s CPU, load average "
                  f"{load:.1f}):")
            print_timeline(err)


if __name__ == "__main__":
    main()
