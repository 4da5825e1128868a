#!/usr/bin/env bash
# CARS (CNES satellite stereo pipeline) in its own virtual environment, bench/peers/cars/.venv
# (ignored by git): nothing of CARS is part of gcpfree. CARS 1.3.0 installs from PyPI with pip.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
python="${PYTHON:-python3.11}"
if [ ! -x "$here/.venv/bin/cars" ]; then
    "$python" -m venv "$here/.venv"
    "$here/.venv/bin/pip" install --quiet --upgrade pip
    "$here/.venv/bin/pip" install --quiet "cars==${CARS_VERSION:-1.3.0}"
fi
"$here/.venv/bin/python" -c "import cars; print('CARS', cars.__version__)"
