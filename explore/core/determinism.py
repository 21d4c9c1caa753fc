"""Thread counts that do not change results: the same seed gives the same run with 1 thread or all.

Our own parallel kernels split work by whole rays or whole candidates and never sum across
threads (:mod:`explore.mapping.pvs_kernels`, :mod:`explore.mapping.visibility`), so their results do not depend
on the thread count. Open3D's legacy pipelines do: point-to-plane ICP sums its normal equations
in whatever order its threads finish (four 2-thread runs of the same ICP gave four transforms,
differing in the last digits, that later change a decision), and its RANSAC draws from
per-thread generators. Those calls run inside :func:`open3d_serial`. BLAS threads are set to
one by the command line before NumPy loads (:data:`THREAD_VARIABLES`).
"""

from __future__ import annotations

import os
import threading
from collections.abc import Iterator
from contextlib import contextmanager

# Read when the libraries load: the CLI sets these (unless the user did) before importing NumPy.
THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "OMP_NUM_THREADS")

_OPEN3D_LOCK = threading.RLock()


@contextmanager
def open3d_serial() -> Iterator[None]:
    """Run the enclosed Open3D calls on one thread (their results then repeat bit for bit)."""
    import open3d as o3d

    with _OPEN3D_LOCK:
        previous = o3d.utility.get_max_threads()
        o3d.utility.set_max_threads(1)
        try:
            yield
        finally:
            o3d.utility.set_max_threads(previous)


def available_cores() -> int:
    """The cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        return os.cpu_count() or 1


def set_threads(threads: int) -> int:
    """Use ``threads`` (0: every core) for numba kernels and Open3D; returns the number set.

    The results do not depend on it (see the module docstring); only the speed does.
    """
    import numba
    import open3d as o3d

    wanted = available_cores() if threads <= 0 else int(threads)
    count = max(1, min(wanted, numba.config.NUMBA_NUM_THREADS))  # numba's pool was sized when it loaded
    numba.set_num_threads(count)
    o3d.utility.set_max_threads(count)
    return count
