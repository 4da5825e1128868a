"""The one thread spawner of the compiled kernels: :func:`run_split` spreads one large call of
a serial, GIL-free Numba kernel (``nogil=True``) over the cores with plain threads, which stays
safe when several threads (Dask's tile workers) call kernels at once and after a fork, unlike
Numba's own thread pools. The kernels live beside their callers: :mod:`core.sensors.rpc_kernels`,
:mod:`core.sensors.orbit_kernels`, :mod:`core.ortho.kernels`.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable

MIN_SPLIT = 65_536  # elements per thread below which a call stays on one thread
_CORES = os.cpu_count() or 1


def run_split(kernel: Callable[..., None], n: int, *args: object,
              min_split: int = MIN_SPLIT) -> None:
    """Run ``kernel(*args, start, stop)`` over ``0 .. n`` in contiguous parts, one thread each
    (as many as the cores and ``n / min_split`` allow; the calling thread takes a part)."""
    k = 1 if n < 2 * min_split else max(1, min(_CORES, n // max(min_split, 1)))
    if k == 1:
        kernel(*args, 0, n)
        return
    bounds = [n * i // k for i in range(k + 1)]
    threads = [threading.Thread(target=kernel, args=(*args, bounds[i], bounds[i + 1]))
               for i in range(1, k)]
    for t in threads:
        t.start()
    try:
        kernel(*args, bounds[0], bounds[1])
    finally:
        for t in threads:
            t.join()

