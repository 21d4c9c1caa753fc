"""The ``explore`` command line (import name ``explore_cli``; the typer application is in ``main``)."""

import os

# One BLAS / OpenMP thread in the command line's process, set before NumPy loads, so that sums do not
# depend on the thread count (explore.core.determinism.THREAD_VARIABLES; tests/test_determinism.py checks it).
for _name in ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "OMP_NUM_THREADS"):
    os.environ.setdefault(_name, "1")
