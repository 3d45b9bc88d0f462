"""The exact model's minimising step on arrays, compiled: a small scene's
step at the cost of one kernel pass and one factorisation.

:class:`~ase_maud.optimize.strategy.Minimise` with the
:class:`~ase_maud.optimize.models.exact.ExactModel` and its default rule (no
momentum, no memory, a trust region) costs a few hundred microseconds a step
on a scene of tens of points, most of it numpy and Python calls of a few
microseconds each around a kernel pass of a few. Here the same step is
three compiled calls: :func:`~ase_maud.calculator.compiled_sums.scene_terms`,
the energy, forces and Hessian in one pass; :func:`_judge`, the merit test
of the last move (a rise takes it back and halves gamma, else gamma grows:
:func:`~ase_maud.optimize.step_length.merit_change`'s test) and the local
model where the step starts (the Hessian on the free coordinates and its
Cholesky factor, shifted by ``floor`` times its largest row sum:
:meth:`ExactModel.local <ase_maud.optimize.models.exact.ExactModel.local>`);
and :func:`_move`, the Newton move cut by the trust region (the dogleg path
or the damped move: :func:`~ase_maud.optimize.step_length.trust_region`) and
bounded point by point. Where the shifted Hessian is not definite, its
eigen-decomposition is the model's own (:func:`~ase_maud.optimize.models.exact.eigenpairs_of`,
:meth:`~ase_maud.optimize.models.base.StiffnessModel.safe_eigenvalues`),
between the two. The loop around them (:func:`relax`) keeps the run's
monitor, hands each evaluation to the calculator (counted as its calls are)
and leaves the strategy's :class:`~ase_maud.optimize.state.MaudState` where
the step left it. The tests hold it to the Python step: the same moves
to round-off.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator

import numba
import numpy as np
from ase import Atoms

from ase_maud.backends import exact_choice
from ase_maud.calculator.compiled_sums import scene_terms
from ase_maud.calculator.maud_calculator import MaudCalculator
from ase_maud.optimize.models.base import TINY
from ase_maud.optimize.models.exact import EXACT_MAX_DOFS, ExactModel, eigenpairs_of
from ase_maud.optimize.monitor import RunMonitor
from ase_maud.optimize.state import MaudState, Point
from ase_maud.optimize.step_length import (
    DAMPING_TRIALS,
    bound_factors,
    damping_bracket,
    damping_trial,
    largest_length,
    longest,
    merit_tolerance,
    narrowed,
    reach,
)
from ase_maud.optimize.strategy import Minimise, Strategy
from ase_maud.physics.dofs import free_dofs
from ase_maud.physics.neighbours import nearest_over_pairs

#: Kinds of local model: the shifted Hessian's Cholesky factor, or its
#: eigen-decomposition.
CHOLESKY, EIGEN = 1, 2


def applies(strategy: Strategy, state: MaudState, atoms: Atoms) -> bool:
    """Whether the compiled step makes ``strategy``'s steps on ``atoms`` (a
    run on arrays, :func:`ase_maud.optimize.array_loop.applies`): the exact
    model seeking a minimum with its default rule's kind of step (no
    momentum, memory or line search; a trust region), a fresh state, a
    MaudCalculator itself (not a subclass, whose results the compiled pass
    would not make) whose Hessian backend is the compiled one, and a whole
    Hessian the model would form too or one of at most
    :data:`~ase_maud.optimize.models.exact.EXACT_MAX_DOFS` coordinates (the
    model asks for a large held scene's block of it)."""
    rule, calc, model = strategy.rule, atoms.calc, strategy.model
    return (isinstance(strategy, Minimise) and type(model) is ExactModel
            and model.target == 'minimum' and not strategy.learns_noise
            and state.last is None and rule.beta_max == 0 and rule.memory == 0
            and rule.trust_region and not rule.interpolate and not rule.learn_rises
            and rule.image_size is None
            and type(calc) is MaudCalculator   # a subclass may compute otherwise
            and exact_choice(calc.parameters['backend']).backend.name == 'numba'
            and (calc.dim * len(atoms) <= EXACT_MAX_DOFS or model.needs(atoms) == 'hessian'))


def relax(atoms: Atoms, strategy: Minimise, state: MaudState, monitor: RunMonitor,
          step: Callable[[], int], no_step: Callable[[str], None],
          ) -> Iterator[tuple[float, float]]:
    """:func:`ase_maud.optimize.array_loop.relax` by the compiled step: the
    energy and the largest force at the start, then after each step (taken
    when the next value is asked for), each evaluation handed to the
    calculator (:meth:`MaudCalculator.take <ase_maud.MaudCalculator.take>`),
    ``state`` left after each step as the Python step leaves it (its local
    model not kept: built again where a step taken back needs it)."""
    calc, model, rule = atoms.calc, strategy.model, strategy.rule
    potential = calc.potential
    law = potential.scene_arrays(len(atoms))
    free = free_dofs(atoms, 3)
    rows = np.flatnonzero(free[:, :law.dim])   # the Hessian's free coordinates
    index = 3 * (rows // law.dim) + rows % law.dim   # ... as components of an (N, 3) array
    held = np.flatnonzero(~free)   # held components of an (N, 3) array
    positions = atoms.arrays['positions']
    settings = np.array([rule.gamma_max, rule.gamma_growth,
                         -1.0 if rule.maxstep_nn is None else rule.maxstep_nn,
                         -1.0 if rule.maxstep is None else rule.maxstep,
                         model.floor, float(potential.a == 0)])
    numbers = np.array([state.gamma, float(state.k), 0.0, 0.0])   # see _judge
    last_x, last_f = np.zeros((len(atoms), 3)), np.zeros((len(atoms), 3))
    n = len(rows)
    matrix, factor, values = np.zeros((n, n)), np.zeros((n, n)), np.zeros(n)

    def evaluate(held_already: bool = False) -> tuple[float, np.ndarray, np.ndarray, float]:
        """The energy, forces (held components zero), Hessian and largest
        force at the positions, held by the calculator (computed unless
        ``held_already``: the optimizer's first evaluation)."""
        if not held_already:
            energy, forces, hessian, force_scale = scene_terms(positions, law)
            model.work.hessians += 1
            if np.isfinite(energy) and _finite(forces) and _finite(hessian):
                calc.take(atoms, energy, forces, hessian, force_scale)
            else:   # the calculator's own call names the problem
                calc.compute(atoms, ['hessian'])
        results = calc.results
        forces, largest = _free_forces(results['forces'], held)
        return results['energy'], forces, results['hessian'], largest

    energy, forces, hessian, fmax_now = evaluate(
        'hessian' in calc.results and not calc.check_state(atoms))
    started = False
    while True:
        yield energy, fmax_now
        slack = merit_tolerance(numbers[2], 0.0)   # both energies exact: no noise
        if _judge(positions, energy, forces, started, slack, last_x, last_f, numbers, matrix,
                  factor, hessian, rows, settings) and numbers[3] == EIGEN:
            try:   # as the model makes it, its eigenvalues made safe by the model
                found, factor[:] = eigenpairs_of(matrix)
            except np.linalg.LinAlgError as error:
                no_step(f'the {model.name} stiffness model failed ({error})')
            values[:] = model.safe_eigenvalues(found)
        move = _move(last_x, last_f, numbers, matrix, factor, values, index, settings)
        started = True
        state.gamma, state.k = float(numbers[0]), int(numbers[1])
        state.last = Point(last_x.copy(), float(numbers[2]), last_f.copy(), 0.0)
        state.solver = None
        monitor.check(step(), last_x, numbers[2], last_f, state.gamma, rule.gamma0,
                      merit_tolerance(numbers[2], 0.0))
        if not _finite(move):
            no_step(f'the {model.name} stiffness model gave a non-finite move')
        state.v = _moved(positions, last_x, move, held)
        energy, forces, hessian, fmax_now = evaluate()


@numba.njit(cache=True)
def _judge(x, merit, forces, has_last, slack, last_x, last_f, numbers, matrix, factor,
           hessian, rows, settings):
    """The step's start after an evaluation at ``x`` (``merit``, ``forces``
    with held components zero, ``hessian``), as
    :class:`~ase_maud.optimize.strategy.Minimise` judges it with the exact
    model: the last move taken back if it raised the merit (gamma halved,
    the local model kept), else ``x`` where the step starts (gamma grown)
    with its local model (:func:`_local`); whether it was built anew.
    ``slack``: the last merit's (:func:`~ase_maud.optimize.step_length.merit_tolerance`).
    ``last_x``, ``last_f`` (N, 3) and
    ``numbers`` (gamma, steps since a restart, the last merit, the local
    model's kind) are the state, ``matrix`` and ``factor`` its local model,
    all changed in place; ``rows`` are the Hessian's free coordinates;
    ``settings``: gamma_max, gamma_growth, maxstep_nn, maxstep (negative:
    none), floor, and whether the energy is quadratic."""
    gamma_max, growth, floor, quadratic = settings[0], settings[1], settings[4], settings[5] > 0
    rose = False
    if has_last:   # the merit test (merit_change)
        change = merit - numbers[2]
        if abs(change) <= slack:
            change, slack = -0.5 * _dot(last_f + forces, x - last_x), 0.0
        rose = change > slack
    if rose:
        numbers[0] *= 0.5
        numbers[1] = 0.0
        return False
    if has_last:
        numbers[0] = min(numbers[0] * growth, gamma_max)
    _copy(x, last_x)
    _copy(forces, last_f)
    numbers[2] = merit
    numbers[3] = _local(hessian, rows, floor, quadratic, matrix, factor)
    return True


@numba.njit(cache=True)
def _move(last_x, last_f, numbers, matrix, factor, values, index, settings):
    """The move (N, 3) from ``last_x`` (forces ``last_f``) with the local
    model of kind ``numbers[3]``: the Newton move, cut by the trust region
    (the dogleg path for a Cholesky factor, the damped move for an
    eigen-decomposition, ``factor`` its vectors and ``values`` its safe
    eigenvalues) to gamma (``numbers[0]``) times each point's limit, times
    gamma and bounded point by point; one more step since a restart."""
    nearest, longest_allowed, quadratic = settings[2], settings[3], settings[5] > 0
    gamma = numbers[0]
    kind = int(numbers[3])
    limit = _limits(last_x, nearest, longest_allowed, quadratic)
    newton = _solve(kind, factor, values, last_f, index)
    if gamma * longest(newton, limit) <= 1.0:
        direction = newton
    elif kind == CHOLESKY:
        direction = _dogleg(matrix, last_f, newton, gamma, limit, index)
    else:
        direction = _damping(factor, values, last_f, gamma, limit, index)
    numbers[1] += 1.0
    direction = direction * gamma
    return direction * bound_factors(direction, limit).reshape(-1, 1)


@numba.njit(cache=True)
def _finite(values):
    """Whether every entry of the 2D array ``values`` is finite."""
    for i in range(values.shape[0]):
        for k in range(values.shape[1]):
            if not np.isfinite(values[i, k]):
                return False
    return True


@numba.njit(cache=True)
def _free_forces(forces, held):
    """A copy of ``forces`` (N, 3) with its ``held`` components (flat
    indices) zero, and the largest force's length (0 if none)."""
    free = forces.copy()
    free.reshape(-1)[held] = 0.0
    return free, largest_length(free, np.zeros(3))


@numba.njit(cache=True)
def _moved(positions, last_x, move, held):
    """``positions`` (N, 3) moved to ``last_x + move`` but for the ``held``
    components (flat indices), kept where they are; the move made (the
    positions now less ``last_x``)."""
    x = last_x + move
    for k in held:
        x.flat[k] = positions.flat[k]
    _copy(x, positions)
    return x - last_x


@numba.njit(cache=True)
def _copy(source, target):
    """``source``'s entries into ``target`` (both (N, 3)), by a loop: numba's
    slice assignment from an array compiles a formatted shape-mismatch message,
    seconds of a cold cache (docs/dev/bench/step_bookkeeping)."""
    for i in range(source.shape[0]):
        for k in range(source.shape[1]):
            target[i, k] = source[i, k]


@numba.njit(cache=True)
def _dot(a, b):
    """The sum of the products of the entries of ``a`` and ``b``."""
    total = 0.0
    for i in range(a.shape[0]):
        for k in range(a.shape[1]):
            total += a[i, k] * b[i, k]
    return total


@numba.njit(cache=True)
def _local(hessian, rows, floor, quadratic, matrix, factor):
    """The local model at the Hessian ``hessian`` (dim N, dim N) on its
    free coordinates ``rows``: ``matrix``, those rows and columns, and its
    kind. As :meth:`ExactModel.local`: a quadratic energy's own Hessian
    where definite, else the Hessian shifted by ``floor`` times its largest
    absolute row sum where definite (:data:`CHOLESKY`, the lower factor into
    ``factor``), else :data:`EIGEN`: the eigen-decomposition is wanted (the
    caller's, as the model makes it)."""
    n = rows.shape[0]
    for i in range(n):
        for j in range(n):
            matrix[i, j] = hessian[rows[i], rows[j]]
    if quadratic and _cholesky(matrix, 0.0, factor):
        return CHOLESKY
    scale = 0.0
    for i in range(n):
        scale = max(scale, np.abs(matrix[i]).sum())
    return CHOLESKY if _cholesky(matrix, floor * scale, factor) else EIGEN


@numba.njit(cache=True)
def _cholesky(matrix, shift, factor):
    """Whether ``matrix + shift I`` is definite (every pivot positive, as
    LAPACK's potrf asks); its lower Cholesky factor into ``factor`` if it is
    (row by row: loops compile in a fraction of the time of numba's LAPACK
    binding and its exception, and run as fast on tens of unknowns)."""
    n = matrix.shape[0]
    for i in range(n):
        for j in range(i + 1):
            total = matrix[i, j] + (shift if i == j else 0.0)
            for k in range(j):
                total -= factor[i, k] * factor[j, k]
            if i == j:
                if not total > 0:
                    return False
                factor[i, i] = np.sqrt(total)
            else:
                factor[i, j] = total / factor[j, j]
    return True


@numba.njit(cache=True)
def _solve(kind, factor, values, forces, index):
    """The model's ``K^-1 f`` on the free components ``index`` of the
    forces (N, 3), as a move (N, 3)."""
    rhs = forces.reshape(-1)[index]
    n = rhs.shape[0]
    if kind == CHOLESKY:
        y = np.empty(n)
        for i in range(n):
            total = rhs[i]
            for j in range(i):
                total -= factor[i, j] * y[j]
            y[i] = total / factor[i, i]
        for i in range(n - 1, -1, -1):
            total = y[i]
            for j in range(i + 1, n):
                total -= factor[j, i] * y[j]
            y[i] = total / factor[i, i]
    else:
        y = _eigen_sum(factor, _across(factor, rhs) / values)
    return _scatter(y, index, forces.shape[0])


@numba.njit(cache=True)
def _across(vectors, v):
    """``vectors.T @ v``: each column's product with ``v`` (n,)."""
    out = np.zeros(vectors.shape[1])
    for i in range(vectors.shape[0]):
        for j in range(vectors.shape[1]):
            out[j] += vectors[i, j] * v[i]
    return out


@numba.njit(cache=True)
def _eigen_sum(vectors, c):
    """``vectors @ c``: the columns weighted by ``c`` and summed."""
    out = np.zeros(vectors.shape[0])
    for i in range(vectors.shape[0]):
        total = 0.0
        for j in range(vectors.shape[1]):
            total += vectors[i, j] * c[j]
        out[i] = total
    return out


@numba.njit(cache=True)
def _scatter(v, index, natoms):
    """Free components (n,) as a move (N, 3), zero where held."""
    out = np.zeros(3 * natoms)
    for k in range(index.shape[0]):
        out[index[k]] = v[k]
    return out.reshape(natoms, 3)


@numba.njit(cache=True)
def _limits(x, nearest, longest_allowed, quadratic):
    """Each point's longest move (:class:`~ase_maud.optimize.step_length.Limits`):
    ``nearest`` times its distance to its nearest other point, at most
    ``longest_allowed`` (negative: no such bound); none for a quadratic energy."""
    limit = np.full(x.shape[0], np.inf)
    if quadratic:
        return limit
    if nearest >= 0:
        limit = nearest * (nearest_over_pairs(x) if x.shape[0] > 1 else limit)
    if longest_allowed >= 0:
        limit = np.minimum(limit, longest_allowed)
    return limit


@numba.njit(cache=True)
def _dogleg(matrix, forces, newton, gamma, limit, index):
    """:func:`~ase_maud.optimize.step_length.trust_region`'s dogleg path for
    the definite model ``matrix`` on the components ``index``."""
    rhs = forces.reshape(-1)[index]
    curvature = (rhs * _eigen_sum(matrix, rhs)).sum()
    zero = np.zeros_like(forces)
    if not curvature > 0:
        return forces * reach(zero, gamma * forces, limit)
    cauchy = forces * (_dot(forces, forces) / curvature)
    t = reach(zero, gamma * cauchy, limit)
    if t < 1:
        return t * cauchy
    t = reach(gamma * cauchy, gamma * (newton - cauchy), limit)
    if t < 1:
        return cauchy + t * (newton - cauchy)
    return newton


@numba.njit(cache=True)
def _damping(vectors, values, forces, gamma, limit, index):
    """:func:`~ase_maud.optimize.step_length.damping` for the
    eigen-decomposed model: the move ``(K + mu I)^-1 f`` of the smallest
    ``mu`` whose ``gamma`` times keeps every point within ``limit``, by its
    bracket (:func:`~ase_maud.optimize.step_length.damping_trial`)."""
    coefficients = _across(vectors, forces.reshape(-1)[index])
    natoms = forces.shape[0]

    def moves(mu):
        return _scatter(_eigen_sum(vectors, coefficients / (values + mu)), index, natoms)

    def excess(move):
        return np.log(max(gamma * longest(move, limit), TINY))

    high = max(np.abs(values).max() if values.shape[0] else 0.0, TINY)
    best = moves(high)
    f_high = excess(best)
    while f_high > 0:
        high *= 10.0
        best = moves(high)
        f_high = excess(best)
    bracket = damping_bracket(high, f_high)
    for _ in range(DAMPING_TRIALS):
        mid = damping_trial(bracket)
        if mid == 0.0:
            break
        move = moves(mid)
        f = excess(move)
        bracket = narrowed(bracket, mid, f)
        if f <= 0:
            best = move
    return best
