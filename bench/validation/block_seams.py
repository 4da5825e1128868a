"""A block oriented as one adjustment against pair-by-pair orientations of the same images
(issue 47): check points per image, and the seams between adjacent orthos both ways.

1. ``gcpfree simulate --preset tiny --block 2x2 --dates 2 --errors realistic --lens`` (seed
   ``--seed``; or the block folder ``--block DIR``), and a reference made from the block's truth
   as a real SRTM differs from the world (:func:`tests.scenes.independent_reference`: shift
   ``--shift-m``, correlated noise, voids on steep slopes, half the canopy seen);
2. ``gcpfree scenes`` and ``gcpfree block --self-calibrate`` against it;
3. every stereo pair of the catalog on its own: ``gcpfree pair --self-calibrate`` (its check
   points taken from the block's, keyed left / right);
4. every image orthorectified over the reference with each orientation (the block's model, its
   pair's model; same cells, same lattice), then every two images of different scenes whose
   orthos overlap correlated as ``gcpfree ortho-compare`` does (windows of 32 cells): the seam's
   median discrepancy, in metres, both ways.

Prints the table and writes ``--out`` (JSON); asserts nothing.

    .venv/bin/python bench/validation/block_seams.py [--block DIR] [--seed 4]
        [--shift-m 6 -5] [--keep WORK] [--out block_seams.json]
"""

from __future__ import annotations

import argparse
import itertools
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[2]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from bench.common import cli, load, refusal, workspace, write_results

CELL_M = 40.0  # the tiny preset's ground sampling


def _run(args: list[str], env: dict[str, str], log: Path) -> float:
    t0 = time.perf_counter()
    r = cli(args, env)
    log.write_text(r.stdout + r.stderr)
    if r.returncode:
        raise SystemExit(f"gcpfree {args[0]}: {refusal(r)} (log {log})")
    return time.perf_counter() - t0


def _pair_checkpoints(block_cps: Path, left: str, right: str, out: Path) -> Path:
    """The block's check points seen in both images of a pair, keyed left / right."""
    doc = json.loads(block_cps.read_text())
    images = doc["images"]
    points = []
    for p in doc["points"]:
        if left in p and right in p:
            q = {k: v for k, v in p.items() if k not in images}
            q["left"], q["right"] = p[left], p[right]
            points.append(q)
    out.write_text(json.dumps({**doc, "images": ["left", "right"], "points": points}))
    return out


def _checks(report: dict[str, Any]) -> dict[str, Any]:
    return report.get("check_points", {})


def _seams(orthos: dict[str, Path], work: Path) -> dict[str, dict[str, Any]]:
    """Every two images of different scenes (``rRcC`` apart) whose orthos share windows."""
    from core.errors import InputError
    from core.ortho.ortho_compare import CompareConfig
    from tasks.ortho.compare import compare_orthos, plan_compare

    out = {}
    for a, b in itertools.combinations(sorted(orthos), 2):
        if a.split("d")[0] == b.split("d")[0]:
            continue  # two dates of one scene: a stereo pair, not a seam
        try:
            plan = plan_compare.fn(orthos[a], orthos[b], CompareConfig(window_px=32, step_px=32))
        except InputError:
            continue  # no common area (a corner)
        s = compare_orthos.fn(plan, work / f"cmp_{a}_{b}.json", num_workers=2).stats.to_dict()
        if s["n_valid"]:
            out[f"{a}-{b}"] = s
    return out


def _orthos(models: dict[str, Path], images: Path, reference: Path, work: Path
            ) -> dict[str, Path]:
    from tasks.io.sensors import load_model
    from tasks.ortho.inputs import describe_dem
    from tasks.ortho.orthorectify import OrthoConfig, orthorectify, plan_ortho

    dem = describe_dem(reference)
    work.mkdir(parents=True, exist_ok=True)
    out = {}
    for name, model in models.items():
        path = work / f"{name}.tif"
        if not path.exists():
            plan = plan_ortho.fn(load_model(images / f"{name}.tif", model=model), dem, CELL_M)
            orthorectify.fn(plan, path, OrthoConfig(), 2)
        out[name] = path
    return out


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--block", type=Path, default=None,
                    help="a gcpfree simulate --block output (default: simulated)")
    ap.add_argument("--seed", type=int, default=4)
    ap.add_argument("--shift-m", type=float, nargs=2, default=(6.0, -5.0),
                    metavar=("EAST", "NORTH"), help="the reference's misregistration")
    ap.add_argument("--keep", type=Path, default=None, help="work folder kept and reused")
    ap.add_argument("--out", type=Path, default=Path("block_seams.json"))
    args = ap.parse_args(argv)
    from tests.scenes import independent_reference

    with workspace(args.keep) as (root, env):
        block = args.block or root / "block"
        if not (block / "truth" / "checkpoints.json").is_file():
            _run(["simulate", "--preset", "tiny", "--seed", str(args.seed), "--block", "2x2",
                  "--dates", "2", "--errors", "realistic", "--lens", "--no-lidar", "--out",
                  str(block)], env, root / "simulate.log")
        ref = root / "reference.tif"
        if not ref.exists():
            independent_reference(block, ref, shift_m=tuple(args.shift_m), seed=47)
        cps = block / "truth" / "checkpoints.json"
        cat = root / "catalog.json"
        _run(["scenes", str(block), "--reference", str(ref), "--out", str(cat)], env,
             root / "scenes.log")
        times = {}
        if not (root / "blk" / "report.json").is_file():
            times["block_s"] = _run(["block", "--catalog", str(cat), "--reference", str(ref),
                                     "--checkpoints", str(cps), "--self-calibrate",
                                     "--no-progress", "--out", str(root / "blk")], env,
                                    root / "block.log")
        checks: dict[str, dict[str, Any]] = {"block": _checks(json.loads(
            (root / "blk" / "report.json").read_text())), "pairs": {}}
        models: dict[str, dict[str, Path]] = {"block": {}, "pairs": {}}
        for p in json.loads(cat.read_text())["pairs"]:
            left, right = Path(p["left"]).stem, Path(p["right"]).stem
            out = root / "pairs" / p["id"]
            if not (out / "report.json").is_file():
                times[p["id"]] = _run([
                    "pair", "--left", p["left"], "--right", p["right"], "--reference", str(ref),
                    "--checkpoints", str(_pair_checkpoints(cps, left, right,
                                                           root / f"cp_{p['id']}.json")),
                    "--self-calibrate", "--no-progress", "--workers", "2", "--out", str(out)],
                    env, root / f"pair_{p['id']}.log")
            pair_checks = _checks(json.loads((out / "report.json").read_text()))
            for side, name in (("left", left), ("right", right)):
                models["block"][name] = root / "blk" / "models" / f"{name}.json"
                models["pairs"][name] = out / f"{side}.json"
                checks["pairs"][name] = pair_checks.get(side)
        seams = {how: _seams(_orthos(m, block / "images", ref, root / f"orthos_{how}"),
                             root / f"orthos_{how}") for how, m in models.items()}
    print(f"{'image':8s} {'block col/row px (pred)':>30s} {'pair by pair col/row px (pred)':>34s}")
    for name in sorted(models["block"]):
        cells = []
        for how in ("block", "pairs"):
            c = checks[how].get(name) or {}
            cells.append(f"{c.get('rms_col_px', np.nan):.3f}/{c.get('rms_row_px', np.nan):.3f} "
                         f"({c.get('predicted_rms_col_px', np.nan):.3f}/"
                         f"{c.get('predicted_rms_row_px', np.nan):.3f})")
        print(f"{name:8s} {cells[0]:>30s} {cells[1]:>34s}")
    both = sorted(set(seams["block"]) & set(seams["pairs"]))
    print(f"\n{'seam':16s} {'windows':>7s} {'block m':>8s} {'pairs m':>8s}")
    b = np.array([seams["block"][k]["m"]["median_norm"] for k in both])
    q = np.array([seams["pairs"][k]["m"]["median_norm"] for k in both])
    for k, x, y in zip(both, b, q, strict=True):
        print(f"{k:16s} {seams['block'][k]['n_valid']:7d} {x:8.2f} {y:8.2f}")
    if both:
        print(f"{len(both)} seams: median {np.median(b):.2f} m (block) against {np.median(q):.2f} "
              f"m (pair by pair), RMS {np.sqrt(np.mean(b**2)):.2f} against "
              f"{np.sqrt(np.mean(q**2)):.2f} m; the block's smaller in {(b < q).sum()}; "
              f"{load()}")
    write_results(args.out, {"check_points": checks, "seams": seams, "seconds": times,
                             "shift_m": list(args.shift_m), "source":
                             "bench/validation/block_seams.py"})


if __name__ == "__main__":
    main()
