"""The speed benchmarks in one run: ``make bench`` (the quick ratios against the peers) and
``make bench-full`` (``--full``: the long ones too).

Quick, under 20 minutes on 2 cores, each peer measured in the same run as gcpfree:

- ``rpc``: RPC projection of 1 M points against rpcm and GDAL's RPC transformer
  (:mod:`bench_rpc`; rpcm from ``bench/peers/rpcm``, skipped when absent);
- ``simulate``: the simulator's golden hashes on ``tiny`` and a 1500 px ``spot`` crop
  (:mod:`bench_simulate`), which also makes the ortho's scene;
- ``ortho``: the crop's ortho against GDAL's RPC warp on the same grid (:mod:`bench_ortho`);
- ``coregister``: Nuth & Kaab against xdem (:mod:`bench_coregister`; ``bench/peers/xdem``);
- ``dsm-cars``: ``gcpfree dsm`` of the Pleiades Reunion ROI against CARS
  (:mod:`bench_dsm_cars`; ``bench/peers/cars``).

``--full`` adds the pushbroom model's throughput, the lidar evaluation and prepare-reference's
memory, the ``spot`` preset's simulation, then on one simulated ``spot`` pair (``--seed 2
--lens --date-change 0.1``, with lidar): tie points, relative orientation, orientation, the
relative DEM, the whole scene's ortho and the whole chain (1 and 2 workers); ``gcpfree dsm``'s
wall time from the shell, the archive on a LocalCluster, and the ``hrg`` preset (hours on 2
cores).

Each benchmark is a child process printing its own figures; a peer that is not installed is
skipped with a line saying how to install it. At the end: every comparison as gcpfree's time
over the peer's (below 1: gcpfree is faster), each step's wall and CPU seconds (user + system
of its whole process tree) and the load averages (figures taken on shared cores are slower:
read the ratios, measured one right after the other). ``--json FILE`` writes the comparisons.

    .venv/bin/python bench/perf/run.py [--full] [--only NAME ...] [--keep DIR] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from bench.common import REPO, load, simulate, workspace

HERE = Path(__file__).resolve().parent
PEERS = REPO / "bench" / "peers"
XDEM = PEERS / "xdem" / ".venv" / "bin" / "python"
CARS = PEERS / "cars" / ".venv" / "bin" / "cars"


@dataclass(frozen=True)
class Step:
    """One benchmark: its name, its script in bench/perf and arguments (given the work folder),
    whether it writes comparisons (``--json``), the peer it needs (a path that must exist and
    the line to print when it does not), and whether it is one of ``--full``'s."""

    name: str
    script: str
    args: Callable[[Path], list[str]] = field(default=lambda work: [])
    compares: bool = False
    needs: tuple[Path, str] | None = None
    full: bool = False


def _spot(work: Path) -> Path:
    return work / "spot"


STEPS = (
    Step("rpc", "bench_rpc.py", compares=True),
    Step("simulate", "bench_simulate.py",
         lambda w: ["--case", "tiny", "spot-crop", "--keep", str(w / "sim")]),
    Step("ortho", "bench_ortho.py",
         lambda w: ["--scene", str(w / "sim" / "spot-crop"), "--crop", "0", "--repeat", "2",
                    "--no-pushbroom"], compares=True),
    Step("coregister", "bench_coregister.py", lambda w: ["--rounds", "1"], compares=True,
         needs=(XDEM, "xdem is not installed (bash bench/peers/xdem/install.sh)")),
    Step("dsm-cars", "bench_dsm_cars.py", compares=True,
         needs=(CARS, "CARS is not installed (bash bench/peers/cars/install.sh)")),
    Step("pushbroom", "bench_pushbroom.py", full=True),
    Step("evaluate", "bench_evaluate.py", full=True),
    Step("reference", "bench_reference.py", full=True),
    Step("simulate-spot", "bench_simulate_preset.py", lambda w: ["--preset", "spot"],
         full=True),
    Step("tiepoints", "bench_tiepoints.py", lambda w: ["--scene", str(_spot(w))], full=True),
    Step("relative", "bench_relative.py", lambda w: ["--scene", str(_spot(w))], full=True),
    Step("orient", "bench_orient.py", lambda w: ["--scene", str(_spot(w))], full=True),
    Step("dsm", "bench_dsm.py", lambda w: ["--scene", str(_spot(w))], full=True),
    Step("ortho-spot", "bench_ortho.py", lambda w: ["--scene", str(_spot(w))], compares=True,
         full=True),
    Step("pair", "bench_pair.py", lambda w: ["--scene", str(_spot(w))], full=True),
    Step("dsm-wall", "bench_dsm_wall.py", full=True),
    Step("archive", "bench_archive.py", full=True),
    Step("hrg", "bench_hrg.py", lambda w: ["--spot", str(_spot(w))], full=True),
)
#: the steps that run on the shared spot scene (simulated once, before the first of them)
ON_SPOT = ("tiepoints", "relative", "orient", "dsm", "ortho-spot", "pair", "hrg")


@dataclass
class Outcome:
    """What one step did: ``status`` (ok, failed with its exit status, or skipped and why),
    its wall and CPU seconds, and the comparisons it wrote."""

    name: str
    status: str
    wall_s: float = 0.0
    cpu_s: float = 0.0
    comparisons: list[dict] = field(default_factory=list)


def children_cpu_s() -> float:
    """User + system seconds of every child process waited for so far (and theirs)."""
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def run_step(step: Step, work: Path, env: dict[str, str]) -> Outcome:
    """One step in a child process, its output on this terminal."""
    if step.needs is not None and not step.needs[0].exists():
        print(f"== {step.name}: skipped, {step.needs[1]}", flush=True)
        return Outcome(step.name, f"skipped: {step.needs[1]}")
    out = work / f"{step.name}.json"
    out.unlink(missing_ok=True)
    argv = [sys.executable, str(HERE / step.script), *step.args(work),
            *(["--json", str(out)] if step.compares else [])]
    print(f"== {step.name}: {' '.join(argv[1:])} ({load()})", flush=True)
    cpu0, t0 = children_cpu_s(), time.perf_counter()
    rc = subprocess.run(argv, cwd=REPO, env=env, check=False).returncode
    wall, cpu = time.perf_counter() - t0, children_cpu_s() - cpu0
    status = "ok" if rc == 0 else f"failed (exit status {rc})"
    print(f"-- {step.name}: {status}, wall {wall:.0f} s, CPU {cpu:.0f} s ({load()})",
          flush=True)
    found = json.loads(out.read_text())["comparisons"] if out.exists() else []
    return Outcome(step.name, status, wall, cpu, found)


def spot_scene(work: Path, env: dict[str, str]) -> Outcome:
    """The ``spot`` pair the long steps share, simulated once (reused under ``--keep``)."""
    print(f"== spot scene: gcpfree simulate --preset spot --seed 2 --lens --date-change 0.1 "
          f"({load()})", flush=True)
    cpu0, t0 = children_cpu_s(), time.perf_counter()
    refused = simulate(_spot(work), env, "spot", 2, "--lens", "--date-change", "0.1")
    wall, cpu = time.perf_counter() - t0, children_cpu_s() - cpu0
    status = "ok" if refused is None else f"failed: {refused}"
    print(f"-- spot scene: {status}, wall {wall:.0f} s, CPU {cpu:.0f} s", flush=True)
    return Outcome("spot scene", status, wall, cpu)


def summary(outcomes: list[Outcome], wall_s: float, cpu_s: float) -> list[str]:
    """The comparisons, then each step's times, then the whole run's."""
    lines = ["", ("gcpfree against the peers, measured in this run (gcpfree's time over the "
                  "peer's; below 1: gcpfree faster):")]
    rows = [c for o in outcomes for c in o.comparisons]
    width = max((len(c["what"]) for c in rows), default=10)
    for c in rows:
        lines.append(f"  {c['what']:<{width}}  {c['peer']:<22} gcpfree {c['gcpfree_s']:8.3f} s, "
                     f"peer {c['peer_s']:8.3f} s: {c['ratio']:6.3f}")
    if not any(c["peer"] == "rpcm" for c in rows) and any(o.name == "rpc" for o in outcomes):
        lines.append('  RPC projection against rpcm: skipped, rpcm is not installed (pip install '
                     '--no-deps "rpcm>=1.4", bench/peers/rpcm)')
    lines += [f"  {o.name}: {o.status}" for o in outcomes if o.status.startswith("skipped")]
    lines += ["", "steps (wall and CPU seconds, CPU of the whole process tree):"]
    lines += [f"  {o.name:<14} {o.wall_s:7.0f} s  {o.cpu_s:7.0f} s CPU  {o.status}"
              for o in outcomes]
    lines.append(f"  {'whole run':<14} {wall_s:7.0f} s  {cpu_s:7.0f} s CPU  on "
                 f"{os.cpu_count()} cores, {load()} (1, 5, 15 min)")
    return lines


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--full", action="store_true", help="the long benchmarks too")
    ap.add_argument("--only", nargs="+", choices=[s.name for s in STEPS], default=None,
                    help="these steps alone")
    ap.add_argument("--keep", type=Path, default=None,
                    help="work there and keep it (scenes are reused by the next run)")
    ap.add_argument("--json", type=Path, default=None, help="write the comparisons there")
    args = ap.parse_args(argv)
    steps = [s for s in STEPS if (args.only is None and (args.full or not s.full))
             or (args.only is not None and s.name in args.only)]
    print(f"gcpfree benchmarks: {', '.join(s.name for s in steps)}; {os.cpu_count()} cores, "
          f"{load()}", flush=True)
    outcomes: list[Outcome] = []
    cpu0, t0 = children_cpu_s(), time.perf_counter()
    with workspace(args.keep, prefix="gcpfree-bench-perf-") as (work, env):
        for step in steps:
            if step.name in ON_SPOT and not any(o.name == "spot scene" for o in outcomes):
                outcomes.append(spot_scene(work, env))
            outcomes.append(run_step(step, work, env))
    print("\n".join(summary(outcomes, time.perf_counter() - t0, children_cpu_s() - cpu0)))
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps({"load": load(), "steps": [
            {"name": o.name, "status": o.status, "wall_s": o.wall_s, "cpu_s": o.cpu_s,
             "comparisons": o.comparisons} for o in outcomes]}, indent=1))
    return 0 if all(o.status == "ok" or o.status.startswith("skipped") for o in outcomes) else 1


if __name__ == "__main__":
    sys.exit(main())
