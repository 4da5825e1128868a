"""A refusal states the true reason (issue 17, item 5), as a user sees it in a terminal.

The real Ventoux crops (250 m on the flanks of Mont Ventoux, 1900 m of relief nearby) with the
SRTM tile as the ground: the scene is smaller than one surface-matching window. ``gcpfree pair``
used to refuse it after three minutes of matching as "too flat ... relief found 0.0 m ...
needed about nan m", after a numpy ``RuntimeWarning`` line; it is now refused before anything
runs, with its size and the size a window needs (the relief verdict's own ``too_small`` reason,
for overlaps between, is tested in ``tests/core/matching/test_surface_match.py``). The installed command
runs in a subprocess, so what reaches stderr is exactly what a user reads.
"""

from __future__ import annotations

import os
import re
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
VENTOUX = REPO / "tests" / "data" / "pleiades_ventoux"


COMMANDS = ("orient", "pair")


@pytest.fixture(scope="module")
def refusals(tmp_path_factory) -> Iterator[dict[str, tuple[subprocess.Popen, Path]]]:
    """Both commands started at once on the crops, each with a Prefect home of its own (most
    of a refusal's seconds are its start-up and its temporary Prefect server's, much of that
    waiting): {command: (its process, its --out)}, each waited for by its test."""
    started: dict[str, tuple[subprocess.Popen, Path]] = {}
    try:
        for command in COMMANDS:
            base = tmp_path_factory.mktemp(f"refused_{command}")
            env = {k: v for k, v in os.environ.items() if k != "PYTHONWARNINGS"}
            env["PREFECT_HOME"] = str(base / "prefect")
            started[command] = (subprocess.Popen(
                [str(REPO / ".venv" / "bin" / "gcpfree"), command,
                 "--left", str(VENTOUX / "left_image.tif"),
                 "--right", str(VENTOUX / "right_image.tif"),
                 "--srtm-dir", str(REPO / "tasks" / "data"), "--no-progress",
                 "--out", str(base / "out")],
                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=REPO, env=env),
                base / "out")
        yield started
    finally:
        for proc, _ in started.values():
            if proc.poll() is None:
                proc.kill()
            proc.communicate()


@pytest.mark.parametrize("command", COMMANDS)
def test_a_scene_smaller_than_a_window_is_refused_as_too_small(command, refusals):
    proc, out = refusals[command]
    _, stderr = proc.communicate(timeout=300)
    lines = stderr.strip().splitlines()
    assert proc.returncode == 2 and len(lines) == 1, stderr
    line = lines[0]
    assert line.startswith(f"gcpfree {command}: error: the scene is too small"), line
    # its figures: the overlap in km2 and in reference cells, what one window needs
    m = re.search(r"overlap on about ([0-9.]+) km2 \((\d+) cells of the reference's (\d+) m\), "
                  r"one window needs 100 cells \(about ([0-9.]+) km2\)", line)
    assert m, line
    have_km2, cells, cell_m, need_km2 = float(m[1]), int(m[2]), int(m[3]), float(m[4])
    assert 0.04 < have_km2 < 0.08 and 55 < cell_m < 95  # 250 m x 250 m; 3" SRTM at 44 N
    assert cells < 100 and have_km2 < need_km2
    assert "flat" not in line and "nan" not in line.lower()
    assert not out.exists()
