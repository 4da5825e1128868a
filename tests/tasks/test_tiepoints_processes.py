"""Tie points in the shared worker processes (runs of blocks) give what threads give."""

from __future__ import annotations

import json
from dataclasses import replace

from tasks.relative.tiepoints import Block, block_runs
from tests.tasks.test_tiepoints import TINY_CFG, reference_cog, search  # noqa: F401 (fixture)


def test_block_runs_take_every_block_once_in_order():
    blocks = [Block(c, 0, c + 1, 1) for c in range(37)]
    runs, processes = block_runs(blocks, 2)
    assert processes and len(runs) == 6 and [b for r in runs for b in r] == blocks
    assert block_runs(blocks, 1) == ([[b] for b in blocks], False)  # one worker: a thread
    assert block_runs(blocks[:7], 2) == ([[b] for b in blocks[:7]], False)  # few blocks


def test_tie_points_in_processes_are_those_of_threads(tiny_clean_scene, reference_cog):
    """25 blocks of 128 px: 2 worker processes (6 runs) against 1 thread, the same document
    (every point, figure and status)."""
    scene = tiny_clean_scene[0]
    cfg = replace(TINY_CFG, tile_px=128)
    one = search(scene, reference_cog, cfg, num_workers=1)
    two = search(scene, reference_cog, cfg, num_workers=2)
    assert len(one.tie_points.left_col) > 100
    assert json.dumps(one.to_dict(), sort_keys=True) == json.dumps(two.to_dict(), sort_keys=True)
