"""The ``fmm`` backend: the unit repulsion ``sum_{i<j} 1/L_ij`` in O(N).

The repulsion is the 3D Laplace kernel, so FMM3D's ``lfmm3d`` (package
``fmm3dpy``, a dependency of ase-maud) gives at every
point the potential of all the others, its gradient and its Hessian. FMM3D's
kernel is ``1/(4 pi r)`` and it drops each point's own term; with unit charges

- ``energy = 2 pi * sum_i pot_i`` (each pair once);
- ``forces = -4 pi * grad``: minus the gradient of the potential felt at
  ``x_i``, which is ``f_i = sum_j d_ij / L_ij**3`` (:mod:`ase_maud.physics`);
- ``blocks = 4 pi * hess``: the Hessian of that potential with respect to
  ``x_i``, ``sum_j (3 d d^T / L**5 - I / L**3)``, in the same xx, yy, zz, xy,
  xz, yz order as :mod:`.base`.

Accuracy. ``fmm_eps`` is the accuracy asked: the backend promises a force
error, relative to the largest force, of :data:`FORCE_ERROR_PER_EPS` ``*
fmm_eps`` (:func:`force_tolerance`). FMM3D's own ``eps`` is not that error:
its error depends on the scene (a grid without close pairs, whose largest
force is small, is the worst seen) and moves in steps (its expansion orders),
and its time is not monotone in it. So FMM3D is handed
:func:`library_eps` ``(fmm_eps)``, the fastest of its ``eps`` whose worst
measured error, ten times over, is within ``fmm_eps`` (:data:`LIBRARY_EPS`);
``python benchmarks/backend_crossover.py --errors`` checks the promise on
random scenes in 3D and on a plane, with near pairs and far clusters
(docs/calculator.md gives the figures).

Near pairs. FMM3D maps the scene into its unit box, which rounds every
coordinate to about ``1e-16`` of the scene's size ``D`` (the largest extent):
a pair at distance ``L`` gets a relative error near ``1e-16 D / L`` and is
dropped altogether below about ``2**-51 D``, whatever ``fmm_eps``. So the
points whose nearest neighbour is closer than :func:`near_radius`
(``NEAR_ROUNDING * D / fmm_eps``, where that rounding is a tenth of
``fmm_eps``) are taken out of the multipole sums: the pairs among them are
summed exactly by the direct kernel, the pairs between them and the rest by
two FMM calls with separate sources and targets (every such pair is farther
apart than the radius). More than :data:`MAX_NEAR_POINTS` such points is a
:class:`~.base.BeyondTolerance` error (a ValueError) naming the closest pair
and the exact backend. Finding them costs a k-d tree per call.

Cost is O(N), with a fixed cost per call. The fmm3dpy wheel from PyPI is
built without OpenMP and runs on one thread (a source build with OpenMP
follows ``OMP_NUM_THREADS``; declare its threads in
``ASE_MAUD_FMM_THREADS``, :func:`library_threads`), and it holds Python's
GIL. So a call of :data:`POOL_MIN_POINTS` to :data:`POOL_MAX_POINTS` points
is split across :func:`workers` processes (default: the cores available, at
most :data:`MAX_WORKERS`; ``ASE_MAUD_FMM_WORKERS`` sets it, 1 for none, and
then splits larger calls too; one for a declared OpenMP build; Linux only,
where they are forked; :func:`call_workers`): each gets every point as a
source and the points of one slab along the longest axis as targets, and the
sums are one call's to round-off. Each worker builds FMM3D's whole tree, so
the split doubles the memory, and above :data:`POOL_MAX_POINTS` it buys
little time, if any. The workers start at the
first such call and stay (:func:`shutdown` stops them, as does the exit).
:func:`threads`, a call's threads times the workers, is what the ``auto``
backend's crossovers count; they are in docs/calculator.md. Below a few
hundred points FMM3D sums directly and the result is exact to rounding.
"""

from __future__ import annotations

import atexit
import multiprocessing
import os
import sys
import threading
import time
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool

import numpy as np
from scipy.spatial import cKDTree

from ase_maud.backends import direct
from ase_maud.backends.base import Backend, BeyondTolerance, Result
from ase_maud.counting import add_worker_cpu
from ase_maud.physics.pair_law import closest_pair

#: FMM3D's Laplace kernel is ``1 / (4 pi r)``; the repulsion's is ``1 / r``.
FMM3D_SCALE = 4.0 * np.pi
#: Promised force error over ``fmm_eps`` (max over points of the error's
#: norm, relative to the largest force): see the module docstring.
FORCE_ERROR_PER_EPS = 1.0
#: Promised error of the energy, relative to the energy, over the ``eps``
#: FMM3D is handed (:func:`library_eps`): ten times the worst ratio measured
#: at the eps the :data:`LIBRARY_EPS` rows hand over (1.2e-3 at 3e-3; 8e-5 at
#: 1e-4 and at 1e-7; 8e-4 at 1e-8, as an eps below every row is handed over
#: as it is), on the scenes and by the command of :data:`LIBRARY_EPS`
#: (docs/dev/bench/fmm_eps_split/errors_*.csv). The energy, a sum of
#: positive terms, is far more accurate than the largest force: an energy
#: error of ``FORCE_ERROR_PER_EPS * fmm_eps`` would be 10^3-10^5 times what
#: FMM3D gives.
ENERGY_ERROR_PER_LIBRARY_EPS = 1.2e-2
#: A point whose nearest neighbour is closer than ``NEAR_ROUNDING * D /
#: fmm_eps`` (``D`` the scene's largest extent) is summed exactly: FMM3D's
#: own rounding of that pair, about ``1e-16 D / L``, would exceed a tenth of
#: ``fmm_eps``.
NEAR_ROUNDING = 1e-15
#: Most points summed exactly with one another (:data:`NEAR_ROUNDING`), a
#: direct sum over them at every call.
MAX_NEAR_POINTS = 4096
#: The ``eps`` handed to FMM3D for a promised force error: ``{promise:
#: library eps}``, the fastest library eps (by summed CPU time) whose worst
#: error (force relative to the largest force, energy, blocks) times 10 is
#: within the promise, over random points in a cube, on a curved sheet and on
#: a plane and the start of a hanging net (a grid: the worst), 2x10^4 and
#: 6x10^4 points, seeds 0-1; measured by
#: ``OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 NUMBA_NUM_THREADS=2 python
#: benchmarks/fmm_threads.py --out ...`` (docs/dev/bench/fmm_eps_split/).
#: A promise between two rows takes the tighter row's eps; a promise tighter
#: than every row is handed to FMM3D as it is (its error at an eps of 1e-9
#: and below stays under a third of it: docs/calculator.md).
LIBRARY_EPS: dict[float, float] = {
    1e-2: 3e-3, 1e-3: 1e-4, 1e-4: 1e-4, 1e-5: 1e-4, 1e-6: 1e-7, 1e-7: 1e-7,
    1e-8: 1e-7}
#: The environment variable that declares the threads FMM3D runs on: unset
#: or 1 for the PyPI wheel; an OpenMP build's ``OMP_NUM_THREADS``.
THREADS_VARIABLE = 'ASE_MAUD_FMM_THREADS'
#: The environment variable that sets the processes a large call is split
#: across (:func:`workers`; 1: none).
WORKERS_VARIABLE = 'ASE_MAUD_FMM_WORKERS'
#: Most worker processes by default: two measured 1.56-1.77x one on free
#: cores at 6x10^4 points (benchmarks/fmm_threads.py, docs/calculator.md);
#: more were not measured.
MAX_WORKERS = 2
#: Points from which a call is split across the workers (measured from
#: 2x10^4: 1.3-1.6x on free cores by the workers' CPU).
POOL_MIN_POINTS = 20000
#: Most points a call is split across the workers by default: two processes
#: took 0.69-0.91x one's wall at 3x10^5 points but 0.83-1.21x at 10^6 (a
#: grid and a sagging sheet, eps 1e-4 and 1e-7), and every split call held
#: twice the memory (10^6: 14.0 GB against 7.0); measured by
#: ``benchmarks/fmm_threads.py --split-memory`` (docs/calculator.md).
POOL_MAX_POINTS = 500_000


def _positive(variable: str, default: str, meaning: str) -> int:
    """The positive integer in the environment variable, or ValueError
    naming it."""
    value = os.environ.get(variable, default)
    try:
        count = int(value)
    except ValueError:
        count = 0
    if count < 1:
        raise ValueError(f'{variable} must be a positive integer ({meaning}), '
                         f'got {value!r}')
    return count


def library_threads() -> int:
    """The threads one FMM3D call runs on, as declared in
    :data:`THREADS_VARIABLE` (1 if unset: the PyPI wheel has no OpenMP)."""
    return _positive(THREADS_VARIABLE, '1', 'the threads of an OpenMP build '
                     'of fmm3dpy, 1 for the PyPI wheel')


def workers() -> int:
    """The processes a large call is split across (module docstring):
    :data:`WORKERS_VARIABLE` if set; else 1 for a declared OpenMP build
    (it threads itself) or where processes cannot be forked (not Linux);
    else the cores this process may run on, at most :data:`MAX_WORKERS`."""
    if WORKERS_VARIABLE in os.environ:
        return _positive(WORKERS_VARIABLE, '1', 'the processes an FMM call is '
                         'split across, 1: none')
    if library_threads() > 1 or not _can_fork():
        return 1
    return max(1, min(MAX_WORKERS, len(os.sched_getaffinity(0))))


def call_workers(natoms: int) -> int:
    """The processes a call of ``natoms`` points is split across:
    :func:`workers` from :data:`POOL_MIN_POINTS` points up to
    :data:`POOL_MAX_POINTS` (beyond it too where :data:`WORKERS_VARIABLE` is
    set), else 1 (this process)."""
    if natoms < POOL_MIN_POINTS or (natoms > POOL_MAX_POINTS
                                    and WORKERS_VARIABLE not in os.environ):
        return 1
    return workers()


def threads() -> int:
    """The threads the FMM runs on: an FMM3D call's
    (:func:`library_threads`) times the processes a large call is split
    across (:func:`workers`; a call of more than :data:`POOL_MAX_POINTS`
    points runs in one by default); what the ``auto`` backend's crossovers
    count."""
    return library_threads() * workers()


def _can_fork() -> bool:
    """Whether worker processes are forked (Linux: no re-import of the
    user's script; elsewhere, and in a daemonic process such as a
    ``multiprocessing.Pool`` worker, which may have no children, the calls
    stay in this process)."""
    return (sys.platform.startswith('linux')
            and 'fork' in multiprocessing.get_all_start_methods()
            and not multiprocessing.current_process().daemon)


_POOL: dict = {}
#: Held while the pool is made or stopped: threads that each evaluate a scene
#: (a band's images) share one pool.
_POOL_LOCK = threading.RLock()


def _pool(count: int) -> ProcessPoolExecutor:
    """The worker processes, created on first use (forked; each imports
    nothing new) and again after :func:`shutdown`, a fork of this process
    or a broken pool."""
    with _POOL_LOCK:
        pool = _POOL.get('pool')
        if pool is None or _POOL['pid'] != os.getpid() or _POOL['count'] != count:
            shutdown()
            pool = ProcessPoolExecutor(count, mp_context=multiprocessing.get_context('fork'))
            _POOL.update(pool=pool, pid=os.getpid(), count=count)
        return pool


def shutdown() -> None:
    """Stop the worker processes, if any (also at exit); the next large
    call starts them again."""
    with _POOL_LOCK:
        pool = _POOL.pop('pool', None)
        if pool is not None and _POOL.get('pid') == os.getpid():
            pool.shutdown(wait=True, cancel_futures=True)
        _POOL.clear()


atexit.register(shutdown)


def _targets(args):
    """A worker's share: FMM3D with every point a source and ``targets``
    (indices) the targets; their potentials, gradients and Hessians, and the
    CPU seconds the worker spent on them."""
    p, targets, eps, order = args
    start = time.process_time()
    out = _lfmm3d()(eps=eps, sources=np.ascontiguousarray(p.T), charges=np.ones(len(p)),
                    targets=np.ascontiguousarray(p[targets].T), pgt=order)
    return (out.pottarg, out.gradtarg, out.hesstarg if order == 3 else None,
            time.process_time() - start)


def _pooled(p, eps, order, count):
    """The sums over all points by ``count`` workers, each with the targets
    of one slab along the longest axis (the same sums as one call, to
    round-off), as ``(pot sum, grad, hess or None)``; None if the pool
    broke (the caller sums in this process)."""
    axis = int(np.argmax(np.ptp(p, axis=0)))
    slabs = np.array_split(np.argsort(p[:, axis], kind='stable'), count)
    try:
        parts = list(_pool(count).map(_targets, [(p, s, eps, order) for s in slabs]))
    except (BrokenProcessPool, OSError):   # a worker died, or no fork here
        shutdown()
        return None
    grad = np.empty((3, len(p)))
    hess = np.empty((6, len(p))) if order == 3 else None
    pot = 0.0
    for slab, (pot_part, grad_part, hess_part, cpu) in zip(slabs, parts, strict=True):
        add_worker_cpu(cpu)
        pot += pot_part.sum()
        grad[:, slab] = grad_part
        if order == 3:
            hess[:, slab] = hess_part
    return pot, grad, hess


def force_tolerance(fmm_eps: float) -> float:
    """The force error promised at ``fmm_eps``, relative to the largest
    force: ``FORCE_ERROR_PER_EPS * fmm_eps``."""
    return FORCE_ERROR_PER_EPS * fmm_eps


def energy_tolerance(fmm_eps: float) -> float:
    """The energy error promised at ``fmm_eps``, relative to the energy:
    ``ENERGY_ERROR_PER_LIBRARY_EPS * library_eps(fmm_eps)``."""
    return ENERGY_ERROR_PER_LIBRARY_EPS * library_eps(fmm_eps)


def library_eps(fmm_eps: float) -> float:
    """The ``eps`` handed to FMM3D for a promised error of ``fmm_eps``:
    the :data:`LIBRARY_EPS` row at or below ``fmm_eps`` (``fmm_eps`` itself
    below the tightest row)."""
    rows = [promise for promise in LIBRARY_EPS if promise <= fmm_eps]
    return LIBRARY_EPS[max(rows)] if rows else fmm_eps


def eps_for(tol: float) -> float:
    """The ``fmm_eps`` whose promised force error is ``tol``."""
    return tol / FORCE_ERROR_PER_EPS


def near_radius(positions: np.ndarray, fmm_eps: float) -> float:
    """Distance below which a pair is summed exactly (module docstring)."""
    return NEAR_ROUNDING * float(np.ptp(positions, axis=0).max()) / fmm_eps


def _lfmm3d():
    """FMM3D's Laplace FMM, or ImportError saying how to install it."""
    try:
        from fmm3dpy import lfmm3d  # an optional backend: imported on its first call
    except ImportError as err:
        raise ImportError("backend='fmm' needs fmm3dpy: pip install fmm3dpy") from err
    return lfmm3d


def evaluate(positions: np.ndarray, want_blocks: bool = False,
             fmm_eps: float = 1e-6) -> Result:
    """Unit repulsion by the fast multipole method; see the module docstring.

    Returns ``(energy, forces (N, 3), block6 (N, 6) or None)`` like the
    direct sums (:mod:`.base`). Two points at the same position give
    ``energy = inf`` and NaN forces, as the direct sums do (FMM3D itself
    would drop that pair). Too many near points (module docstring) raise
    :class:`~.base.BeyondTolerance`.
    """
    lfmm3d = _lfmm3d()
    p = np.asarray(positions, dtype=float)
    n = len(p)
    if n < 2:  # FMM3D gives NaN for a lone point
        return 0.0, np.zeros((n, 3)), np.zeros((n, 6)) if want_blocks else None
    near = _near_points(p, fmm_eps)
    eps = library_eps(fmm_eps)
    order = 3 if want_blocks else 2
    count = call_workers(n) if near.size == 0 else 1
    pooled = _pooled(p, eps, order, count) if count > 1 else None
    if pooled is not None:
        return _unscale(0.5 * pooled[0], *pooled[1:])
    if near.size == 0:
        out = lfmm3d(eps=eps, sources=np.ascontiguousarray(p.T),
                     charges=np.ones(n), pg=order)
        return _unscale(0.5 * out.pot.sum(), out.grad,
                        out.hess if want_blocks else None)
    far = np.setdiff1d(np.arange(n), near)
    if far.size < 2:
        return direct.evaluate(p, want_blocks)
    return _split(lfmm3d, p, near, far, want_blocks, eps)


def _split(lfmm3d, p, near, far, want_blocks, eps):
    """FMM (at the library's ``eps``) over the far points, each group's field
    at the other group's points by FMM (sources and targets apart), and the
    near points among themselves by the exact direct sum."""
    order = 3 if want_blocks else 2
    far_far = lfmm3d(eps=eps, sources=np.ascontiguousarray(p[far].T),
                     charges=np.ones(far.size),
                     targets=np.ascontiguousarray(p[near].T), pg=order,
                     pgt=order)
    near_far = lfmm3d(eps=eps, sources=np.ascontiguousarray(p[near].T),
                      charges=np.ones(near.size),
                      targets=np.ascontiguousarray(p[far].T), pgt=order)
    # far-far pairs twice in pot, far-near pairs once in pottarg
    pot = 0.5 * far_far.pot.sum() + far_far.pottarg.sum()
    fields = []
    for name in ('grad', 'hess')[:order - 1]:
        field = np.zeros((getattr(far_far, name).shape[0], len(p)))
        field[:, far] = getattr(far_far, name) + getattr(near_far,
                                                         name + 'targ')
        field[:, near] = getattr(far_far, name + 'targ')
        fields.append(field)
    energy, forces, block6 = _unscale(pot, *fields)
    e_near, f_near, b_near = direct.evaluate(p[near], want_blocks)
    forces[near] += f_near
    if want_blocks:
        block6[near] += b_near
    return energy + e_near, forces, block6


def _unscale(pot_sum, grad, hess=None):
    """Energy, forces and blocks (if ``hess`` is given) of the unit
    repulsion from FMM3D's sums."""
    energy = FMM3D_SCALE * float(pot_sum)
    forces = -FMM3D_SCALE * np.ascontiguousarray(grad.T)
    block6 = (None if hess is None
              else FMM3D_SCALE * np.ascontiguousarray(hess.T))
    return energy, forces, block6


def _near_points(p, eps):
    """Sorted indices of the points whose nearest neighbour is within
    :func:`near_radius`; BeyondTolerance if there are too many."""
    radius = near_radius(p, eps)
    tree = cKDTree(p, balanced_tree=False, compact_nodes=False)
    # each pair counted twice, each point once with itself: O(1) memory
    count = (int(tree.count_neighbors(tree, radius)) - len(p)) // 2
    if count == 0:
        return np.zeros(0, dtype=int)
    if count <= 64 * MAX_NEAR_POINTS:   # at most 4 MB of pairs
        pairs = tree.query_pairs(radius, output_type='ndarray')
        near = np.unique(pairs)
        if near.size <= MAX_NEAR_POINTS:
            return near
    i, j, distance = closest_pair(p)
    raise BeyondTolerance(
        f'{count} pairs are closer than {radius:.3g}, among them atoms '
        f'{i} and {j} at {distance:.3g}: FMM3D rounds '
        f'such pairs beyond fmm_eps = {eps:g} and more than '
        f'{MAX_NEAR_POINTS} points are too many to sum exactly; use '
        "backend='numba' (exact) or a larger fmm_eps")


#: FMM3D's fast multipole method, approximate to ``fmm_eps``.
BACKEND = Backend(
    name='fmm', evaluate=evaluate, cost='N', tolerance='fmm_eps',
    parameters={'fmm_eps': 1e-6}, requires=('fmm3dpy',),
    force_tolerance=force_tolerance, energy_tolerance=energy_tolerance,
    summary="FMM3D's fast multipole method, O(N), forces to fmm_eps; "
    f'large calls split across {WORKERS_VARIABLE} processes (default: the '
    f'cores, at most {MAX_WORKERS}; an OpenMP build: declare its threads in '
    f'{THREADS_VARIABLE})')
