"""GCP-free orientation against a reference made without the simulator's reference code
(issue 19: "held-out terrain and references made independently of the simulator's").

The simulator's ``reference.tif`` and the chain were written by the same hands: a defect shared
by both (a half-cell convention, a noise spectrum the matching happens to suit) would not
show. Here the reference is made from the scene's truth with nothing of ``core.simulation``:
the truth DTM plus ``--canopy`` of the canopy and building height the truth DSM adds (C band
sees part of it; one share for the scene, not per stand), averaged over 90 m (an odd box: an
even one moves the surface half a cell), sampled on the simulator reference's 3" lattice at
positions moved by ``--shift-m`` (at an azimuth drawn from the seed), plus white noise
Gaussian-filtered to a correlation of about ``--corr-m`` and scaled to ``--noise-m``; no voids,
no tilt. The same scene is oriented against both references (``gcpfree orient
--self-calibrate``, no GCP) and measured at its check points (:func:`bench.common.beyond_shift`:
as measured, beyond the reference's shift, beyond the used GCPs' common error).

    .venv/bin/python bench/validation/independent_reference.py [--cases SEED:LON:LAT ...]
        [--scenes DIR ...] [--canopy 0.5] [--shift-m 8] [--noise-m 4] [--corr-m 600]
        [--out independent_reference.json] [--keep DIR]

``--cases``: scenes of the ``tiny`` preset (``--lens``, realistic errors; default three of the
uncertainty sweep's); ``--scenes``: existing simulated scene folders to use as well (a ``spot``
scene: about 4 minutes per orientation); ``--keep DIR`` keeps everything there (and reuses what
is there). Writes the figures as JSON into ``--out`` (the docs read
``bench/results/independent_reference.json`` and, with ``--canopy 0.7 --shift-m 15 --noise-m
6``, ``independent_reference_harsh.json``). Prints figures, asserts nothing.
"""

from __future__ import annotations

import argparse
import json
import sys
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from bench.common import (
    lens_decision,
    line,
    orient_and_measure,
    place,
    read_report,
    simulate,
    workspace,
    write_results,
)

CASES = ("1:5.75:44.75", "3:5.25:44.2", "6:5.45:44.15")


@dataclass(frozen=True)
class ReferenceErrors:
    """What the independent reference gets: the share of the canopy it sees, its
    misregistration (m), its noise (m) and the noise's correlation length (m)."""

    canopy: float = 0.5
    shift_m: float = 8.0
    noise_m: float = 4.0
    corr_m: float = 600.0

    def __post_init__(self) -> None:
        if not 0.0 <= self.canopy <= 1.0 or min(self.shift_m, self.noise_m) < 0.0 \
                or self.corr_m <= 0.0:
            raise ValueError(f"{self}: canopy in 0-1, shift and noise >= 0, correlation > 0")


def make_reference(scene: Path, dest: Path, seed: int, errors: ReferenceErrors
                   ) -> tuple[float, float]:
    """Write ``dest`` on the lattice of ``scene/reference.tif`` from ``scene/truth``
    (:func:`tests.scenes.independent_reference`, no bias), its shift at an azimuth drawn from
    ``seed``; return the shift (east, north, m): the reference shows the world moved by it."""
    from tests.scenes import independent_reference

    azimuth = np.random.default_rng(seed).uniform(0.0, 2.0 * np.pi)
    shift = (errors.shift_m * np.sin(azimuth), errors.shift_m * np.cos(azimuth))
    part = dest.with_suffix(".part.tif")  # a reference there is reused under --keep: whole
    dx, dy = independent_reference(scene, part, shift, errors.noise_m, errors.corr_m,
                                   errors.canopy, bias_m=0.0, seed=seed + 1)
    part.replace(dest)
    return dx, dy


def independent_scene(scene: Path, dest: Path, seed: int, errors: ReferenceErrors) -> Path:
    """``dest``: ``scene`` with links to its images and truth, its own reference and its
    own ``truth/reference_errors.json`` (the shift, what ``beyond_shift`` takes out)."""
    (dest / "truth").mkdir(parents=True, exist_ok=True)
    for src in [*scene.iterdir(), *(scene / "truth").iterdir()]:
        if src.name in ("reference.tif", "reference_errors.json", "truth", "work"):
            continue
        link = dest / src.relative_to(scene)
        if not link.exists():
            link.symlink_to(src.resolve())
    if not (dest / "reference.tif").is_file():
        dx, dy = make_reference(scene, dest / "reference.tif", seed, errors)
        (dest / "truth" / "reference_errors.json").write_text(json.dumps({
            "shift_east_m": dx, "shift_north_m": dy, "canopy_seen": errors.canopy,
            "noise_m": errors.noise_m, "correlation_m": errors.corr_m,
            "source": "bench/validation/independent_reference.py"}, indent=1))
    return dest


def orient(scene: Path, out: Path, env: dict[str, str]) -> dict[str, Any]:
    """:func:`bench.common.orient_and_measure`, with the lens decision of the report."""
    row = orient_and_measure(scene, out, env)
    if "images" in row:
        row["lens"] = lens_decision(read_report(out))
    return row


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", type=place, nargs="*", default=[place(c) for c in CASES],
                    metavar="SEED:LON:LAT", help="tiny scenes (default: three places)")
    ap.add_argument("--scenes", type=Path, nargs="+", default=[],
                    help="existing simulated scenes to use as well")
    defaults = ReferenceErrors()
    ap.add_argument("--canopy", type=float, default=defaults.canopy,
                    help="share of the canopy the reference sees (default %(default)s)")
    ap.add_argument("--shift-m", type=float, default=defaults.shift_m,
                    help="its misregistration, m (default %(default)s)")
    ap.add_argument("--noise-m", type=float, default=defaults.noise_m,
                    help="its noise, m (default %(default)s)")
    ap.add_argument("--corr-m", type=float, default=defaults.corr_m,
                    help="the noise's correlation length, m (default %(default)s)")
    ap.add_argument("--out", type=Path, default=Path("independent_reference.json"),
                    help="the figures' JSON")
    ap.add_argument("--keep", type=Path, default=None,
                    help="keep scenes and products there (and reuse them)")
    args = ap.parse_args(argv)
    try:
        errors = ReferenceErrors(args.canopy, args.shift_m, args.noise_m, args.corr_m)
    except ValueError as exc:
        ap.error(str(exc))
    rows: list[dict[str, Any]] = []
    with workspace(args.keep) as (tmp, env):
        scenes = list(args.scenes)
        for seed, lon, lat in args.cases:
            scene = tmp / f"tiny_{seed}"
            refused = simulate(scene, env, "tiny", seed, "--center", lon, lat, "--lens",
                               "--errors", "realistic", "--no-lidar")
            if refused is not None:
                rows.append({"scene": scene.name, "refused": refused})
                continue
            scenes.append(scene)
        for scene in scenes:  # the draws follow the scene's name, not the order
            indep = independent_scene(scene, tmp / f"{scene.name}_independent",
                                      zlib.crc32(scene.name.encode()), errors)
            row = {"scene": scene.name,
                   "simulator": orient(scene, tmp / f"orient_{scene.name}", env),
                   "independent": orient(indep, tmp / f"orient_{indep.name}", env)}
            rows.append(row)
            for kind in ("simulator", "independent"):
                r = row[kind]
                print(f"{scene.name}, {kind} reference: shift "
                      f"{r.get('reference_shift_m')}, lens: {r.get('lens')}")
                for name, img in r.get("images", {}).items():
                    print("  " + line(name, img))
    settings = {"canopy": errors.canopy, "shift_m": errors.shift_m, "noise_m": errors.noise_m,
                "corr_m": errors.corr_m}
    write_results(args.out, {"settings": settings, "scenes": rows})


if __name__ == "__main__":
    main()
