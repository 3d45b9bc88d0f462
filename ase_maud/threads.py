"""Pin every thread pool (OpenMP, BLAS, numba) to one count.

OpenMP and BLAS read their variables (:data:`STARTUP_VARIABLES`) when they
are loaded, which importing ase_maud already does (numpy); threadpoolctl
limits the pools already loaded in place (it calls each library's own
``set_num_threads``), and the variables are set for pools loaded later and
for child processes. numba is pinned in the running process with
``numba.set_num_threads``, up to the size of its pool: only a pool smaller
than asked for needs the program started again (or, called from Python, a
warning).

``NUMBA_NUM_THREADS`` is never written into the environment of a running
process: numba reads it again before every compilation and refuses any
value but the size of the pool it launched ("Cannot set NUMBA_NUM_THREADS to
a different value once the threads have been launched"). A restart passes it
to the new process only.
"""

from __future__ import annotations

import os
import sys
import warnings

#: Read once, when OpenMP and BLAS are loaded.
STARTUP_VARIABLES = ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS')
#: The environment variables of the thread pools a benchmark must state.
THREAD_VARIABLES = (*STARTUP_VARIABLES, 'NUMBA_NUM_THREADS')


def pin_blas(n: int) -> None:
    """Run OpenMP and BLAS on ``n`` threads: the pools loaded so far limited
    in place (threadpoolctl, for the rest of the process), and
    :data:`STARTUP_VARIABLES` set to ``n`` for those loaded later and for
    child processes."""
    from threadpoolctl import threadpool_limits

    os.environ.update(dict.fromkeys(STARTUP_VARIABLES, str(n)))
    threadpool_limits(limits=n)


def pin_threads(n: int, restart: bool) -> None:
    """Run OpenMP, BLAS and numba on ``n`` threads.

    Limits the OpenMP and BLAS pools loaded so far to ``n`` in place
    (threadpoolctl), sets :data:`STARTUP_VARIABLES` to ``n`` for those loaded
    later, and calls ``numba.set_num_threads(n)`` (at most numba's pool
    size). If numba's pool is smaller than ``n``: with ``restart``,
    re-execute ``python -m ase_maud <sys.argv[1:]>`` with every
    :data:`THREAD_VARIABLES` at ``n`` (right only when run as a program),
    else warn.
    """
    import numba  # here: after ase_maud set numba's cache dir

    value = str(n)
    pin_blas(n)
    pool = numba.config.NUMBA_NUM_THREADS
    if pool < n:
        if restart:
            os.execve(sys.executable, [sys.executable, '-m', 'ase_maud', *sys.argv[1:]],
                      {**os.environ, 'NUMBA_NUM_THREADS': value})
        warnings.warn(f"--threads {n}: numba's pool has {pool} threads; set "
                      'NUMBA_NUM_THREADS in the environment to pin it', stacklevel=2)
    numba.set_num_threads(min(n, pool))
