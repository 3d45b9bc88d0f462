"""Pin every thread pool (OpenMP, BLAS, numba) to one count.

OpenMP and BLAS read their variables (:data:`STARTUP_VARIABLES`) when they
are loaded, which importing ase_maud already does (numpy); so
:func:`pin_threads` can pin them only by starting the program again with
them set (or, called from Python, it warns). numba is pinned in the running
process with ``numba.set_num_threads``, up to the size of its pool.

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


def pin_threads(n: int, restart: bool) -> None:
    """Run OpenMP, BLAS and numba on ``n`` threads.

    Sets :data:`STARTUP_VARIABLES` to ``n`` and calls
    ``numba.set_num_threads(n)`` (at most numba's pool size). If numpy was
    loaded with another count in one of them, or numba's pool is smaller
    than ``n``: with ``restart``, re-execute ``python -m ase_maud
    <sys.argv[1:]>`` with every :data:`THREAD_VARIABLES` at ``n`` (right
    only when run as a program), else warn.
    """
    import numba

    value = str(n)
    late = [v for v in STARTUP_VARIABLES if os.environ.get(v) != value] \
        if 'numpy' in sys.modules else []
    pool = numba.config.NUMBA_NUM_THREADS
    os.environ.update(dict.fromkeys(STARTUP_VARIABLES, value))
    if late or pool < n:
        if restart:
            os.execve(sys.executable, [sys.executable, '-m', 'ase_maud', *sys.argv[1:]],
                      {**os.environ, 'NUMBA_NUM_THREADS': value})
        warnings.warn(f'--threads {n}: '
                      + (f'{", ".join(late)} took effect when numpy was imported, so BLAS '
                         'may use another count; ' if late else '')
                      + (f"numba's pool has {pool} threads; " if pool < n else '')
                      + 'set the thread variables in the environment to pin them',
                      stacklevel=2)
    numba.set_num_threads(min(n, pool))
