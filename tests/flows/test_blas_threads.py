"""One BLAS thread per worker in a command's process (flows._env): the parallelism is Dask's,
and OpenBLAS's own threads on the chain's small products only spin. The setting is read when
NumPy loads, so the command line must not load NumPy before it configures the environment."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]

CHILD = """
import sys
import flows.cli  # what `gcpfree` loads before it configures the environment
assert "numpy" not in sys.modules, "the command line loads NumPy before configuring BLAS"
from flows._env import configure_environment
configure_environment()
import ctypes, glob, os
import numpy
libs = glob.glob(os.path.join(os.path.dirname(numpy.__file__), os.pardir, "numpy.libs",
                              "*openblas*"))
threads = "?"
for lib in libs:
    for name in ("scipy_openblas_get_num_threads64_", "openblas_get_num_threads64_",
                 "openblas_get_num_threads"):
        fn = getattr(ctypes.CDLL(lib), name, None)
        if fn is not None:
            threads = str(fn())
print(os.environ["OPENBLAS_NUM_THREADS"], threads)
"""


def child(env_extra: dict[str, str]) -> tuple[str, str]:
    env = {k: v for k, v in os.environ.items()
           if k not in ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")} | env_extra
    r = subprocess.run([sys.executable, "-c", CHILD], cwd=REPO, env=env, capture_output=True,
                       text=True, check=True)
    setting, threads = r.stdout.split()
    return setting, threads


def test_a_command_runs_one_blas_thread_unless_the_user_says_otherwise():
    setting, threads = child({})
    assert setting == "1"
    assert threads in ("1", "?")  # "?": a NumPy build whose BLAS cannot be asked
    setting, threads = child({"OPENBLAS_NUM_THREADS": "2"})
    assert setting == "2"
    assert threads in ("2", "?")
