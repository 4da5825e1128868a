"""Relief sufficiency (issue 11): how flat may the terrain be for GCP-free orientation?

Simulates the `tiny` preset (40 m pixels, 100-300 m metadata errors, lens) over N44E005 with
its relief scaled by each factor of GCPFREE_RELIEF_FACTORS (default 0.05 ... 1), runs `gcpfree
orient` on each (degraded SRTM-like reference, no GCP) and prints, per factor: the median relief
of the windows (std of heights about their plane), the windows that qualified, and the check
point RMS (worst of P and L over both images) and the self-calibration's decision, or the
refusal. Writes relief_sweep.png (and .json) into GCPFREE_RELIEF_OUT (default the current
folder) when matplotlib is there. About a minute and a half per factor on 2 cores.
GCPFREE_RELIEF_ERRORS: the simulator's errors, realistic (default: measured attitude profile,
ephemeris and detector errors, an SRTM-like reference with partial canopy and
misregistration) or simple (attitude biases and rates only). Prints figures, asserts nothing.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

FACTORS = [float(f) for f in os.environ.get(
    "GCPFREE_RELIEF_FACTORS", "0.05,0.1,0.15,0.2,0.3,0.5,1.0").split(",")]
ERRORS = os.environ.get("GCPFREE_RELIEF_ERRORS", "realistic")


def cli(args: list[str], env: dict[str, str]) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "flows.cli", *args], capture_output=True,
                          text=True, env=env, check=False)


def one(factor: float, tmp: Path, env: dict[str, str]) -> dict:
    scene = tmp / f"tiny_{factor:g}"
    r = cli(["simulate", "--preset", "tiny", "--seed", "21", "--lens", "--date-change", "0.1",
             "--relief-factor", str(factor), "--errors", ERRORS, "--no-lidar",
             "--out", str(scene)], env)
    if r.returncode:
        raise SystemExit(r.stdout[-1500:] + r.stderr[-1500:])
    out = tmp / f"orient_{factor:g}"
    t0 = time.perf_counter()
    r = cli(["orient", "--left", str(scene / "left.tif"), "--right", str(scene / "right.tif"),
             "--reference", str(scene / "reference.tif"), "--checkpoints",
             str(scene / "truth" / "checkpoints.json"), "--self-calibrate", "--no-progress",
             "--out", str(out)], env)
    row: dict = {"factor": factor, "errors": ERRORS, "seconds": time.perf_counter() - t0}
    windows = out / "windows.json"
    if windows.is_file():
        ws = json.loads(windows.read_text())["windows"]
        reliefs = sorted(w["relief_m"] for w in ws if w["relief_m"] is not None)
        row["relief_m"] = reliefs[len(reliefs) // 2] if reliefs else None
        row["windows"] = len(ws)
    if r.returncode:
        row["refused"] = (r.stderr.strip().splitlines() or ["?"])[-1]
        return row
    rep = json.loads((out / "report.json").read_text())
    row["qualified"] = rep["surface_matching"]["qualified"]
    row["gcps"] = rep["gcps"]["used"]
    row["check_rms_px"] = max(max(c["rms_col_px"], c["rms_row_px"])
                              for c in rep["check_points"].values())
    row["lens"] = (rep["absolute"].get("self_calibration") or {}).get("decision")
    return row


def main() -> None:
    dest = Path(os.environ.get("GCPFREE_RELIEF_OUT", "."))
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        env = dict(os.environ, PREFECT_HOME=str(Path(tmp) / "prefect"))
        for f in FACTORS:
            row = one(f, Path(tmp), env)
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
        print(f"errors {ERRORS}: lowest relief reaching 1 px: factor {low['factor']:g}, "
              f"median window relief {low['relief_m']:.1f} m")
    (dest / "relief_sweep.json").write_text(json.dumps(rows, indent=1))
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
    fig.savefig(dest / "relief_sweep.png", dpi=110)


if __name__ == "__main__":
    main()
