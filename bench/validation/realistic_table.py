"""The six-scene table of issue 19: `spot` and `hrs` with `--lens`, simple and realistic
errors, realistic with `--jitter`, each oriented by `gcpfree orient --self-calibrate` (no GCP)
and measured at its check points as measured, beyond the reference's drawn shift and beyond
the used GCPs' common error, beside the predicted RMS (``beyond_shift.py``).

GCPFREE_TABLE_CASES: preset:seed:errors[:jitter] items, comma separated (default the six);
GCPFREE_TABLE_KEEP=DIR keeps scenes and products there, and a case whose ``report.json`` is
already there is not rerun; GCPFREE_TABLE_ALONG_TRACK=0 orients with `--no-along-track` (the
figure the along-track estimation buys). A `spot` or `hrs` scene takes about 10 minutes to
simulate and 4 to orient on 2 cores. Writes realistic_table.json into GCPFREE_TABLE_OUT
(default the current folder). Prints figures, asserts nothing.
"""

from __future__ import annotations

import json
import os
import tempfile
import time
from pathlib import Path

from beyond_shift import beyond_shift, line
from relief_sweep import cli

DEFAULT = ("spot:2:simple,spot:2:realistic,spot:2:realistic:jitter,hrs:1:simple,"
           "hrs:1:realistic,hrs:1:realistic:jitter")
CASES = [c.split(":") for c in os.environ.get("GCPFREE_TABLE_CASES", DEFAULT).split(",")]
ALONG_TRACK = os.environ.get("GCPFREE_TABLE_ALONG_TRACK", "1") != "0"


def one(case: list[str], tmp: Path, env: dict[str, str]) -> dict:
    preset, seed, errors = case[:3]
    jitter = case[3:] == ["jitter"]
    tag = "_".join(case)
    scene, out = tmp / tag, tmp / (f"orient_{tag}" + ("" if ALONG_TRACK else "_no_at"))
    row: dict = {"case": tag}
    if not (scene / "truth" / "checkpoints.json").is_file():
        r = cli(["simulate", "--preset", preset, "--seed", seed, "--lens", "--date-change",
                 "0.1", "--errors", errors, *(["--jitter"] if jitter else []), "--no-lidar",
                 "--out", str(scene)], env)
        if r.returncode:
            row["refused"] = (r.stderr.strip().splitlines() or ["?"])[-1]
            return row
    return {**row, **oriented(scene, out, env, *([] if ALONG_TRACK else ["--no-along-track"]))}


def oriented(scene: Path, out: Path, env: dict[str, str], *options: str) -> dict:
    """``gcpfree orient --self-calibrate`` of the simulated ``scene`` into ``out`` (not run
    again when ``out`` holds a report) with ``options``, and its check points as
    ``beyond_shift`` measures them: ``seconds`` (when run), ``refused`` (the error's last
    line) or ``reference_shift_m`` and ``images``."""
    row: dict = {}
    if not (out / "report.json").is_file():
        t0 = time.perf_counter()
        r = cli(["orient", "--left", str(scene / "left.tif"), "--right",
                 str(scene / "right.tif"), "--reference", str(scene / "reference.tif"),
                 "--checkpoints", str(scene / "truth" / "checkpoints.json"),
                 "--self-calibrate", "--no-progress", *options, "--out", str(out)], env)
        row["seconds"] = time.perf_counter() - t0
        if r.returncode:
            row["refused"] = (r.stderr.strip().splitlines() or ["?"])[-1]
            return row
    shift = json.loads((scene / "truth" / "reference_errors.json").read_text())
    row["reference_shift_m"] = [shift["shift_east_m"], shift["shift_north_m"]]
    row["images"] = beyond_shift(scene, out)
    return row


def main() -> None:
    dest = Path(os.environ.get("GCPFREE_TABLE_OUT", "."))
    keep = os.environ.get("GCPFREE_TABLE_KEEP")
    rows = []
    with tempfile.TemporaryDirectory() as tmp_dir:
        tmp = Path(keep or tmp_dir)
        env = dict(os.environ, PREFECT_HOME=str(tmp / "prefect"))
        for case in CASES:
            row = one(case, tmp, env)
            rows.append(row)
            if "refused" in row:
                print(f"{row['case']}: {row['refused']}", flush=True)
                continue
            e, n = row["reference_shift_m"]
            for name, c in row["images"].items():
                print(f"{row['case']} (shift E {e:+.1f} N {n:+.1f} m) {line(name, c)}",
                      flush=True)
    (dest / "realistic_table.json").write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
