#!/usr/bin/env bash
# xdem (GlacioHack's DEM analysis library, the reference implementation of Nuth & Kaab's
# coregistration) in its own virtual environment, bench/peers/xdem/.venv (ignored by git):
# nothing of xdem is part of gcpfree. xdem 0.2.3 installs from PyPI with pip.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
python="${PYTHON:-python3.11}"
if [ ! -x "$here/.venv/bin/python" ] || ! "$here/.venv/bin/python" -c "import xdem" 2>/dev/null; then
    "$python" -m venv "$here/.venv"
    "$here/.venv/bin/pip" install --quiet --upgrade pip
    "$here/.venv/bin/pip" install --quiet "xdem==${XDEM_VERSION:-0.2.3}"
fi
"$here/.venv/bin/python" -c "import xdem; print('xdem', xdem.__version__)"
