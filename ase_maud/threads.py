"""Pin every thread pool (OpenMP, BLAS, numba) to one count.

BLAS reads its variables when numpy is first imported, which importing
ase_maud already does; so :func:`pin_threads` can pin BLAS only by starting
the program again with them set (or, called from Python, it warns).
"""

from __future__ import annotations

import os
import sys
import warnings

#: The environment variables of the thread pools a benchmark must state.
THREAD_VARIABLES = ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS',
                    'MKL_NUM_THREADS', 'NUMBA_NUM_THREADS')


def pin_threads(n: int, restart: bool) -> None:
    """Set every :data:`THREAD_VARIABLES` to ``n`` and call
    ``numba.set_num_threads(n)`` (at most numba's pool size).

    If they were not all ``n`` already and numpy is loaded, BLAS may run
    with another count: with ``restart``, re-execute ``python -m ase_maud
    <sys.argv[1:]>`` with them set (right only when run as a program), else
    warn.
    """
    value = str(n)
    in_force = all(os.environ.get(v) == value for v in THREAD_VARIABLES)
    os.environ.update(dict.fromkeys(THREAD_VARIABLES, value))
    if not in_force and 'numpy' in sys.modules:
        if restart:
            os.execv(sys.executable,
                     [sys.executable, '-m', 'ase_maud', *sys.argv[1:]])
        warnings.warn(f'--threads {n}: numpy was imported before the thread '
                      'variables were set, so BLAS may use another count; '
                      'set them in the environment to pin BLAS too',
                      stacklevel=2)
    import numba
    numba.set_num_threads(min(n, numba.config.NUMBA_NUM_THREADS))
