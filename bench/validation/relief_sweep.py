"""Relief sufficiency (issue 11): how flat may the terrain be for GCP-free orientation?

Simulates the ``tiny`` preset (40 m pixels, 100-300 m metadata errors, lens) over N44E005 with
its relief scaled by each of ``--factors`` (default 0.05 ... 1), runs ``gcpfree orient`` on each
(degraded SRTM-like reference, no GCP) and prints, per factor: the median relief of the windows
(std of heights about their plane), the windows that qualified, and the check point RMS (worst
of P and L over both images) and the self-calibration's decision, or the refusal. ``--errors``:
the simulator's errors, ``realistic`` (default: measured attitude profile, ephemeris and
detector errors, an SRTM-like reference with partial canopy and misregistration) or ``simple``
(attitude biases and rates only). About a minute and a half per factor on 2 cores.

    .venv/bin/python bench/validation/relief_sweep.py [--factors 0.05 0.1 ...]
        [--errors realistic|simple] [--out relief_sweep.json] [--keep DIR]

Writes the figures as JSON into ``--out`` (the docs read ``bench/results/relief_sweep.json``
and, with ``--errors simple``, ``relief_sweep_simple.json``) and the plot beside it (``.png``)
when matplotlib is there. Prints figures, asserts nothing.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from bench.common import (
    ERRORS,
    lens_decision,
    orient,
    read_report,
    simulate,
    workspace,
    worst_check_rms,
    write_results,
)

FACTORS = (0.05, 0.1, 0.15, 0.2, 0.3, 0.5, 1.0)


def one(factor: float, errors: str, tmp: Path, env: dict[str, str]) -> dict[str, Any]:
    scene = tmp / f"tiny_{errors}_{factor:g}"
    refused = simulate(scene, env, "tiny", 21, "--lens", "--date-change", "0.1",
                       "--relief-factor", str(factor), "--errors", errors, "--no-lidar")
    if refused is not None:
        raise SystemExit(f"simulate (relief factor {factor:g}): {refused}")
    out = tmp / f"orient_{errors}_{factor:g}"
    seconds, refused = orient(scene, out, env)
    row: dict[str, Any] = {"factor": factor, "errors": errors, "seconds": seconds}
    windows = out / "windows.json"
    if windows.is_file():
        ws = json.loads(windows.read_text())["windows"]
        reliefs = sorted(w["relief_m"] for w in ws if w["relief_m"] is not None)
        row["relief_m"] = reliefs[len(reliefs) // 2] if reliefs else None
        row["windows"] = len(ws)
    if refused is not None:
        return {**row, "refused": refused}
    rep = read_report(out)
    row["qualified"] = rep["surface_matching"]["qualified"]
    row["gcps"] = rep["gcps"]["used"]
    row["check_rms_px"] = worst_check_rms(rep)
    row["lens"] = lens_decision(rep)
    return row


def plot(rows: list[dict[str, Any]], path: Path) -> None:
    """Worst check-point RMS against the median window relief; refusals as dotted lines."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return
    fig, ax = plt.subplots(figsize=(6, 3.6))
    done = [r for r in rows if "check_rms_px" in r and r.get("relief_m")]
    ax.plot([r["relief_m"] for r in done], [r["check_rms_px"] for r in done], "o-",
            label="oriented: worst check-point RMS")
    for r in rows:
        if "refused" in r and r.get("relief_m"):
            ax.axvline(r["relief_m"], color="0.6", ls=":")
    ax.axhline(1.0, color="r", lw=0.8, label="1 pixel")
    ax.set_xscale("log")
    ax.set_xlabel("median relief per 4 km window (std of heights about their plane), m")
    ax.set_ylabel("check points, px")
    ax.set_title("GCP-free orientation vs relief (simulated tiny, 40 m pixels)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--factors", type=float, nargs="+", default=list(FACTORS),
                    help="relief scale factors (default: %(default)s)")
    ap.add_argument("--errors", choices=ERRORS, default="realistic",
                    help="the simulator's errors (default: realistic)")
    ap.add_argument("--out", type=Path, default=Path("relief_sweep.json"),
                    help="the figures' JSON (the plot beside it as .png)")
    ap.add_argument("--keep", type=Path, default=None,
                    help="keep scenes and products there (and reuse them)")
    args = ap.parse_args(argv)
    rows = []
    with workspace(args.keep) as (tmp, env):
        for f in args.factors:
            row = one(f, args.errors, tmp, env)
            rows.append(row)
            relief = f"{row['relief_m']:.1f} m" if row.get("relief_m") is not None else "-"
            result = (row["refused"] if "refused" in row else
                      f"{row['qualified']}/{row['windows']} windows qualified, {row['gcps']} "
                      f"GCPs, check points {row['check_rms_px']:.2f} px")
            print(f"relief factor {f:<5g} relief {relief:>8}: {result}", flush=True)
            if row.get("lens"):
                print(f"  lens terms: {row['lens']}", flush=True)
    ok = [r for r in rows if r.get("check_rms_px", 99) <= 1.0]
    if ok:
        low = min(ok, key=lambda r: r["factor"])
        print(f"errors {args.errors}: lowest relief reaching 1 px: factor {low['factor']:g}, "
              f"median window relief {low['relief_m']:.1f} m")
    write_results(args.out, rows)
    plot(rows, args.out.with_suffix(".png"))


if __name__ == "__main__":
    main()
