"""The ``auto`` backend: per call, the cheapest backend that meets ``tol``.

``tol`` is the force error allowed, relative to the largest repulsive force
(the largest norm over points of the repulsion's force; for a scene without
springs, the largest force). The direct sum (``numba``) is exact, so it meets
any ``tol``; the FMM (``fmm``, if fmm3dpy is installed) meets it at
``fmm_eps = tol / FORCE_ERROR_PER_EPS`` (:func:`.fmm.eps_for`) and is chosen
when the scene has at least the crossover number of points for that
``fmm_eps``, the dimension and what is asked (energy and forces, or with the
nodal blocks). Should the FMM refuse the scene (too many near pairs,
:mod:`.fmm`), the direct sum is used.

The crossovers are :data:`CROSSOVER`, measured with one thread for each
backend by ``python benchmarks/backend_crossover.py`` (docs/calculator.md has the
table, the date and the command), times the direct sum's threads over the
FMM's (:func:`crossover_points`): the direct sum runs on
``numba.get_num_threads()`` threads, the FMM on :func:`.fmm.threads` (one
for the PyPI wheel; an OpenMP build's threads are declared in
``ASE_MAUD_FMM_THREADS``), and each call's time is taken as its one-thread
time over its threads. Override them for a machine of your own by assigning
to ``ase_maud.backends.auto.CROSSOVER``, or per calculator with the
``crossover`` keyword: a number of points from which the FMM is used
whatever the thread count (``None``, the default: the table).
"""

from __future__ import annotations

import numba
import numpy as np

from ase_maud.backends import direct, fmm
from ase_maud.backends.base import Backend, Choice, Result, evaluate_first

#: Default ``tol``: forces to 1e-8 of the largest repulsive force, a hundred
#: times below an ``fmax`` of 1e-6 of it, and still coarse enough for the FMM
#: on large scenes (docs/calculator.md gives the crossovers).
DEFAULT_TOL = 1e-8

#: Points from which the FMM (rows: its ``fmm_eps``, FMM3D handed
#: :func:`.fmm.library_eps` of it) is faster than the numba direct sum, both
#: on one thread, by (dim, with blocks), in CPU seconds, as
#: ``python benchmarks/backend_crossover.py`` measures them (docs/calculator.md
#: gives the table, its date and the command; a faster kernel, or a change of
#: :data:`.fmm.LIBRARY_EPS`, moves them). The rows 1e-3 and 1e-5 hand FMM3D
#: the same eps, as do 1e-6 and 1e-8: their differences are the clock's noise.
#: Between two rows the crossover is interpolated in log-log; below the last
#: row the FMM is never used.
CROSSOVER: dict[tuple[int, bool], dict[float, int]] = {
    (3, False): {1e-3: 36500, 1e-5: 35100, 1e-6: 72400, 1e-8: 73200,
                 1e-9: 90500, 1e-12: 392900},
    (3, True): {1e-3: 46700, 1e-5: 48800, 1e-6: 82600, 1e-8: 80900,
                1e-9: 110900, 1e-12: 479500},
    (2, False): {1e-3: 25100, 1e-5: 25200, 1e-6: 49600, 1e-8: 49300,
                 1e-9: 60800},
    (2, True): {1e-3: 32200, 1e-5: 35000, 1e-6: 64500, 1e-8: 64300,
                1e-9: 88000},
}
#: The finest ``fmm_eps`` asked of the FMM (a ``tol`` below 10 times it, even
#: with ``crossover`` set, takes the direct sum: FMM3D cannot promise it).
MIN_EPS = 1e-13
#: The coarsest ``fmm_eps`` used: a larger ``tol`` gains little more speed.
MAX_EPS = 1e-3


def thread_ratio() -> float:
    """The direct sum's threads over the FMM's: how much further the
    crossover lies than with one thread each."""
    return numba.get_num_threads() / fmm.threads()


def crossover_points(eps: float, dim: int, want_blocks: bool) -> float:
    """Points from which the FMM at ``eps`` beats the direct sum here: the
    :data:`CROSSOVER` row of ``eps`` (log-log interpolated between rows, the
    coarsest row above it), times numba's thread count over the FMM's
    (:func:`.fmm.threads`); inf below the tightest row."""
    rows = sorted(CROSSOVER[dim, want_blocks].items())   # tightest first
    if eps < rows[0][0]:
        return np.inf
    log_eps, log_n = np.log([row[0] for row in rows]), np.log(
        [row[1] for row in rows])
    points = round(float(np.exp(np.interp(np.log(eps), log_eps, log_n))))
    return points * thread_ratio()


def choose(natoms: int, dim: int, want_blocks: bool,
           tol: float = DEFAULT_TOL, crossover: int | None = None,
           ) -> list[Choice]:
    """The backends to try, in order (module docstring)."""
    exact = Choice(direct.BACKEND, {}, 0.0)
    fewest = min(min(row.values()) for row in CROSSOVER.values())
    if (tol == 0 or not fmm.BACKEND.installed
            or (crossover is None and natoms < fewest * thread_ratio())):
        return [exact]
    eps = min(fmm.eps_for(tol), MAX_EPS)
    start = (crossover_points(eps, dim, want_blocks) if crossover is None
             else crossover)
    if natoms < max(start, 2) or eps < MIN_EPS:
        return [exact]
    return [Choice(fmm.BACKEND, {'fmm_eps': eps}, fmm.force_tolerance(eps),
                   fmm.energy_tolerance(eps)), exact]


def evaluate(positions: np.ndarray, want_blocks: bool = False,
             tol: float = DEFAULT_TOL, crossover: int | None = None) -> Result:
    """Unit repulsion by the backend :func:`choose` picks; points with one
    z are a 2D scene."""
    p = np.asarray(positions, dtype=float)
    dim = 2 if len(p) and np.ptp(p[:, 2]) == 0 else 3
    return evaluate_first(choose(len(p), dim, want_blocks, tol, crossover),
                          p, want_blocks)[0]


#: Per call, the cheapest backend that meets ``tol``.
BACKEND = Backend(
    name='auto', evaluate=evaluate, cost='N', tolerance='tol',
    parameters={'tol': DEFAULT_TOL, 'crossover': None},
    choose=choose, summary='per call, the cheapest backend that meets tol: '
    'the numba direct sum below a measured crossover, the FMM above it '
    '(the default)')
