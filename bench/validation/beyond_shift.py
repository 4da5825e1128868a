"""Check points of a simulated scene beyond the reference's own misregistration (issue 19).

A GCP-free orientation inherits the reference DEM's registration error whole: every GCP sits
where the reference puts the terrain, a shift common to all that no residual shows. On a
simulated scene the shift drawn is known (``truth/reference_errors.json``), so it can be carried
through the scene's true models and taken out of every check point's residual: what is left is
what the method itself achieves. The same for the prediction: ``report.json``'s predicted
check-point RMS less its reference term (the reference's stated registration sigma through the
ground's partial derivatives at the check points), so measured and predicted are compared on
the part that is not one draw per scene. The figures are :func:`bench.common.beyond_shift`'s,
the ones the studies' tables hold.

    .venv/bin/python bench/validation/beyond_shift.py SCENE_DIR ORIENT_DIR

(the simulator's output and ``gcpfree orient --checkpoints SCENE_DIR/truth/checkpoints.json``'s).
Prints per image the check points' RMS (col / row, px) as measured and beyond the shift, and the
predicted RMS in total and without the reference's term. Asserts nothing.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from bench.common import beyond_shift, line, reference_shift_m


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene", type=Path, help="a gcpfree simulate output")
    ap.add_argument("orient", type=Path, help="gcpfree orient's output for that scene")
    args = ap.parse_args(argv)
    east, north = reference_shift_m(args.scene)
    print(f"reference shift E {east:+.1f} N {north:+.1f} m")
    for name, r in beyond_shift(args.scene, args.orient).items():
        print(line(name, r))


if __name__ == "__main__":
    main()
