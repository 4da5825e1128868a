"""Run every benchmark in bench/ (each prints its own figures); the tools that need arguments
(``beyond_shift.py``, ``prediction_check.py``: a scene and its orientation) print their usage
and the others go on."""

from __future__ import annotations

import runpy
import sys
from pathlib import Path

HERE = Path(__file__).parent
sys.path[:0] = [str(HERE), str(HERE.parent)]  # bench's own helpers (beyond_shift), the package

for script in sorted(HERE.glob("*.py")):
    if script.name in {"run_all.py", "__init__.py"} or script.name.startswith("_"):
        continue
    print(f"== {script.name}", flush=True)
    try:
        runpy.run_path(str(script), run_name="__main__")
    except SystemExit as stop:  # a tool that needs arguments (beyond_shift.py): say so, go on
        if stop.code not in (None, 0):
            print(f"{script.name} not run: {stop.code}", flush=True)
