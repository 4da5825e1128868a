"""The six-scene table of issue 19: ``spot`` and ``hrs`` with ``--lens``, simple and realistic
errors, realistic with ``--jitter``, each oriented by ``gcpfree orient --self-calibrate`` (no
GCP) and measured at its check points as measured, beyond the reference's drawn shift and beyond
the used GCPs' common error, beside the predicted RMS (:func:`bench.common.beyond_shift`).

    .venv/bin/python bench/validation/realistic_table.py [--cases PRESET:SEED:ERRORS[:jitter] ...]
        [--no-along-track] [--out realistic_table.json] [--keep DIR]

``--cases``: default the six (``spot:2:simple spot:2:realistic spot:2:realistic:jitter
hrs:1:simple hrs:1:realistic hrs:1:realistic:jitter``); ``--keep DIR`` keeps scenes and products
there, and a case whose ``report.json`` is already there is not rerun; ``--no-along-track``
orients with ``gcpfree orient --no-along-track`` (the figure the along-track estimation buys).
A ``spot`` or ``hrs`` scene takes about 10 minutes to simulate and 4 to orient on 2 cores.
Writes the rows as JSON into ``--out`` (the docs read ``bench/results/realistic_table.json``,
``realistic_table_spot_seeds.json`` and ``realistic_table_hrs_seeds.json``). Prints figures,
asserts nothing.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from bench.common import ERRORS, line, orient_and_measure, simulate, workspace, write_results

CASES = ("spot:2:simple", "spot:2:realistic", "spot:2:realistic:jitter", "hrs:1:simple",
         "hrs:1:realistic", "hrs:1:realistic:jitter")


def case(text: str) -> list[str]:
    """``PRESET:SEED:ERRORS[:jitter]`` checked."""
    parts = text.split(":")
    if len(parts) not in (3, 4) or not parts[1].isdigit() or parts[2] not in ERRORS \
            or parts[3:] not in ([], ["jitter"]):
        raise argparse.ArgumentTypeError(f"{text!r}: give PRESET:SEED:ERRORS[:jitter], "
                                         "e.g. spot:2:realistic:jitter")
    return parts


def one(parts: list[str], tmp: Path, env: dict[str, str], along_track: bool) -> dict[str, Any]:
    preset, seed, errors = parts[:3]
    tag = "_".join(parts)
    scene, out = tmp / tag, tmp / (f"orient_{tag}" + ("" if along_track else "_no_at"))
    refused = simulate(scene, env, preset, seed, "--lens", "--date-change", "0.1", "--errors",
                       errors, *(["--jitter"] if parts[3:] == ["jitter"] else []), "--no-lidar")
    if refused is not None:
        return {"case": tag, "refused": refused}
    return {"case": tag, **orient_and_measure(scene, out, env,
                                              *([] if along_track else ["--no-along-track"]))}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=case, nargs="+", default=[case(c) for c in CASES],
                    metavar="PRESET:SEED:ERRORS[:jitter]", help="default: the six of issue 19")
    ap.add_argument("--no-along-track", dest="along_track", action="store_false",
                    help="orient with --no-along-track")
    ap.add_argument("--out", type=Path, default=Path("realistic_table.json"),
                    help="the rows' JSON")
    ap.add_argument("--keep", type=Path, default=None,
                    help="keep scenes and products there (and reuse them)")
    args = ap.parse_args(argv)
    rows = []
    with workspace(args.keep) as (tmp, env):
        for parts in args.cases:
            row = one(parts, tmp, env, args.along_track)
            rows.append(row)
            if "refused" in row:
                print(f"{row['case']}: {row['refused']}", flush=True)
                continue
            e, n = row["reference_shift_m"]
            for name, c in row["images"].items():
                print(f"{row['case']} (shift E {e:+.1f} N {n:+.1f} m) {line(name, c)}",
                      flush=True)
    write_results(args.out, rows)


if __name__ == "__main__":
    main()
