"""Stiffness models: the ``K`` that the Maud step ``dr = gamma K^-1 f`` divides by.

A model answers one question for the step rule (:mod:`ase_maud.method`): at
the current positions, solve ``K d = f`` for the move ``d`` (lengths) from
the forces ``f`` (ASE sign, ``-dE/dr``; ``K`` in force per length).
:meth:`StiffnessModel.at` reads what it needs from the calculator and returns
a :class:`Solver`, frozen at those positions, so that the step rule can keep
it for a step it may take back. Four models, from the cheapest:

- :class:`SecantModel` (``'secant'``): ``K = kappa I``, ``kappa`` the secant
  (Barzilai-Borwein) curvature ``s.y / s.s`` of the last accepted step; for
  calculators with no stiffness at all.
- :class:`NodalModel` (``'nodal'``): the specification's nodal blocks
  ``K_mm`` (property ``stiffness``), each point with every other one held
  fixed: the tensor step ``K_mm^-1 f_m`` or the scalar ``f_m / Tr K_mm``.
- :class:`GlobalModel` (``'global'``): the whole scene, sparse,
  ``P = Q (L (x) I_dim) + blockdiag(|K_mm - Q deg(m) I|)`` with ``L`` the spring
  graph's Laplacian: the springs' Hessian exactly (it is constant) plus the
  repulsion's nodal blocks. O(N + K) to build; solved by a sparse LU
  factorisation, by algebraic multigrid (pyamg) when the factorisation would
  be too large, and matrix-free by conjugate gradients when the spring graph
  is dense (every pair sprung).
- :class:`ExactModel` (``'exact'``): the dense analytic Hessian (property
  ``hessian``), eigen-decomposed: the step is saddle-free Newton. O((dim N)^3)
  per step, for small scenes.

``target='minimum'`` makes every model positive definite: eigenvalues are
replaced by their absolute values and floored at ``floor`` times the largest
(per block for the nodal and global models, over the whole matrix for the
exact one), so no direction is uphill. ``target='stationary'`` keeps the signs
(saddles and maxima are then fixed points of the step). Degrees of freedom
held by :class:`~ase.constraints.FixAtoms` and
:class:`~ase.constraints.FixCartesian` are removed from ``K`` and never move;
other constraints are left to ASE (the optimizer applies them to every move).
A ``dim=2`` scene works with 2x2 blocks and never moves ``z``.

A model is stateless but for caches: what it learns in a run (the secant
curvature) is handed back to the step rule (:meth:`StiffnessModel.observe`),
which keeps it in its state and passes it to :meth:`StiffnessModel.at`. The
step rule's defaults for each model are in :data:`ase_maud.method.STEP_DEFAULTS`.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any

import numpy as np
import scipy.sparse as sp
from ase import Atoms
from ase.constraints import FixAtoms, FixCartesian, FixedLine, FixedPlane
from scipy.sparse.linalg import LinearOperator, cg, splu

from .checks import check
from .neighbours import NearestDistances

#: ``model='auto'`` takes the exact model up to this many free degrees of
#: freedom (dense eigen-decomposition cost against a calculator call; see
#: docs/optimizer.md for the measurement), the global model above.
EXACT_MAX_DOFS = 300
#: The global model uses algebraic multigrid above this many free DOFs.
AMG_MIN_DOFS = 200_000
#: The global model goes matrix-free when the spring graph holds more than
#: this fraction of all pairs (a factorisation would be dense).
DENSE_GRAPH_FRACTION = 0.25
#: ... and has more free DOFs than this (a small dense LU is cheap).
DENSE_MIN_DOFS = 300
#: Relative residual of the iterative solves (CG, multigrid).
SOLVE_RTOL = 1e-10



class Solver(ABC):
    """A stiffness ``K`` frozen at one configuration."""

    @abstractmethod
    def solve(self, forces: np.ndarray) -> np.ndarray:
        """The move ``d`` with ``K d = forces``, shape (N, 3), zero on the
        degrees of freedom FixAtoms and FixCartesian hold and on ``z`` in 2D."""


class StiffnessModel(ABC):
    """What the Maud step divides the forces by; see the module docstring.

    ``target`` ('minimum' or 'stationary') and ``floor`` (relative
    eigenvalue floor; None: the model's :attr:`default_floor`) are checked
    here. ``prop`` names the calculator property whose request computes, in
    the same calculator call as the energy and forces, what :meth:`at`
    needs (None: nothing beyond the forces).
    """

    name: str = ''
    prop: str | None = None
    default_floor = 1e-2

    def __init__(self, target: str = 'minimum', floor: float | None = None):
        self.target = check('target', target) or 'minimum'
        floor = check('floor', floor)
        self.floor = self.default_floor if floor is None else floor

    @abstractmethod
    def at(self, atoms: Atoms, learnt: dict[str, Any] | None = None) -> Solver:
        """The model at ``atoms``' current positions, with what it has learnt
        in the run so far (:meth:`observe`)."""

    def needs(self, atoms: Atoms) -> str | None:
        """The calculator property :meth:`at` will ask for at ``atoms``'
        positions (None: nothing beyond energy and forces); the optimizer
        asks for it together with the forces, in one calculator call."""
        return self.prop

    def observe(self, step: np.ndarray, force_drop: np.ndarray,
                learnt: dict[str, Any]) -> dict[str, Any]:
        """What the model learns from an accepted step ``s`` and ``y = f_old
        - f_new`` (both (N, 3)), given what it had learnt; only the secant
        model learns."""
        return learnt

    def _absolute(self, values: np.ndarray) -> np.ndarray:
        """Eigenvalues made safe to divide by: ``|lambda|`` (or signed, for
        ``'stationary'``) floored at ``floor`` times the largest of each row."""
        size = np.abs(values)
        floor = np.maximum(self.floor * size.max(axis=-1, keepdims=True),
                           np.finfo(float).tiny)
        safe = np.maximum(size, floor)
        if self.target == 'stationary':
            safe = np.where(values < 0, -safe, safe)
        return safe


def free_dofs(atoms: Atoms, dim: int) -> np.ndarray:
    """Boolean (N, dim) mask of the degrees of freedom that FixAtoms and
    FixCartesian leave free (other constraints are not coordinate masks and
    are left to ASE)."""
    free = np.ones((len(atoms), 3))
    for constraint in atoms.constraints:
        if isinstance(constraint, (FixAtoms, FixCartesian)):
            constraint.adjust_forces(atoms, free)
    return free[:, :dim] != 0


#: The constraints that project each atom's move onto a line, a plane or
#: nothing: the exact model represents them exactly (:func:`allowed_basis`).
PROJECTIONS = (FixAtoms, FixCartesian, FixedPlane, FixedLine)


def allowed_basis(atoms: Atoms, dim: int) -> np.ndarray:
    """Orthonormal columns (dim N, m) spanning the moves that FixAtoms,
    FixCartesian, FixedPlane and FixedLine allow (each is a projection of
    every atom's move onto a line, a plane or nothing); other constraints
    are left to ASE."""
    projector = np.zeros((len(atoms), 3, 3))  # P_i, column k = P_i e_k
    for k in range(3):
        unit = np.zeros((len(atoms), 3))
        unit[:, k] = 1.0
        for constraint in atoms.constraints:
            if isinstance(constraint, PROJECTIONS):
                constraint.adjust_forces(atoms, unit)
        projector[:, :, k] = unit
    values, vectors = np.linalg.eigh(projector[:, :dim, :dim])
    atom, column = np.nonzero(values > 0.5)   # eigenvalues are 0 or 1
    basis = np.zeros((dim * len(atoms), len(atom)))
    for j, (i, c) in enumerate(zip(atom, column, strict=True)):
        basis[dim * i:dim * (i + 1), j] = vectors[i, :, c]
    return basis


class _DofSolver(Solver):
    """Gathers the free components of the forces into a vector, solves, and
    scatters the move back into an (N, 3) array."""

    def __init__(self, free: np.ndarray):
        self.free = free  # (N, dim) mask
        self.dim = free.shape[1]

    def solve(self, forces: np.ndarray) -> np.ndarray:
        move = np.zeros((len(self.free), 3))
        rhs = np.asarray(forces, dtype=float).reshape(-1, 3)[:, :self.dim]
        move[:, :self.dim][self.free] = self._solve(rhs[self.free])
        return move

    @abstractmethod
    def _solve(self, rhs: np.ndarray) -> np.ndarray:
        """``K_ff^-1 rhs`` on the free degrees of freedom (1D arrays)."""


def _held_at_zero(move: np.ndarray, free: np.ndarray | None) -> np.ndarray:
    """``move`` (N, 3) with the components outside ``free`` (N, dim) set to
    zero (``z`` too, for dim 2); unchanged if ``free`` is None (no atoms)."""
    if free is not None:
        move[:, free.shape[1]:] = 0.0
        move[:, :free.shape[1]][~free] = 0.0
    return move


def _free_or_none(atoms: Atoms | None) -> np.ndarray | None:
    """The free mask of ``atoms`` (:func:`free_dofs`) in its calculator's
    dimension, or None if there are no atoms to ask (a band of images)."""
    if atoms is None or len(atoms) == 0:
        return None
    return free_dofs(atoms, 2 if getattr(atoms.calc, 'dim', 3) == 2 else 3)


# -- secant ------------------------------------------------------------------


class SecantModel(StiffnessModel):
    """``K = kappa I`` with ``kappa`` the secant curvature of the last step.

    ``kappa0`` (force per length) is the start; ASE's BFGS starts from 70
    eV/A**2. For calculators that give no stiffness.
    """

    name = 'secant'

    def __init__(self, target: str = 'minimum', floor: float | None = None,
                 kappa0: float = 70.0):
        super().__init__(target, floor)
        self.kappa0 = check('kappa0', kappa0)

    def at(self, atoms: Atoms | None, learnt: dict[str, Any] | None = None) -> Solver:
        kappa = (learnt or {}).get('kappa', self.kappa0)
        return _ScaledSolver(float(kappa), _free_or_none(atoms))

    def observe(self, step: np.ndarray, force_drop: np.ndarray,
                learnt: dict[str, Any]) -> dict[str, Any]:
        sy, ss = np.vdot(step, force_drop), np.vdot(step, step)
        return {**learnt, 'kappa': sy / ss} if sy > 0 and ss > 0 else learnt


class _ScaledSolver(Solver):
    """``f / kappa``."""

    def __init__(self, kappa: float, free: np.ndarray | None):
        self.kappa, self.free = kappa, free

    def solve(self, forces):
        return _held_at_zero(np.asarray(forces, dtype=float).reshape(-1, 3)
                             / self.kappa, self.free)


# -- nodal -------------------------------------------------------------------


class NodalModel(StiffnessModel):
    """The specification's nodal blocks ``K_mm`` (calculator property
    ``stiffness``, shape (N, dim, dim)).

    ``method='tensor'``: ``d_m = K_mm^-1 f_m``; ``'scalar'``:
    ``d_m = f_m / Tr K_mm`` (with ``|lambda|`` summed for ``'minimum'``).
    """

    name = 'nodal'
    prop = 'stiffness'

    def __init__(self, target: str = 'minimum', floor: float | None = None,
                 method: str = 'tensor'):
        super().__init__(target, floor)
        self.method = check('method', method)

    def at(self, atoms: Atoms, learnt: dict[str, Any] | None = None) -> Solver:
        blocks = atoms.calc.get_property('stiffness', atoms)
        free = free_dofs(atoms, blocks.shape[1])
        values, vectors = np.linalg.eigh(blocks)
        size = np.abs(values)
        if self.method == 'scalar':
            floor = np.maximum(self.floor * size.max(axis=1), np.finfo(float).tiny)
            total = (size if self.target == 'minimum' else values).sum(axis=1)
            trace = np.where(total < 0, -1.0, 1.0) * np.maximum(np.abs(total), floor)
            return _TraceSolver(trace, free)
        return _BlockSolver(vectors, self._absolute(values), free)


class _TraceSolver(Solver):
    """``d_m = f_m / Tr K_mm``."""

    def __init__(self, trace: np.ndarray, free: np.ndarray):
        self.trace, self.free = trace, free  # (N,), (N, dim)

    def solve(self, forces):
        move = np.asarray(forces, dtype=float).reshape(-1, 3) / self.trace[:, None]
        return _held_at_zero(move, self.free)


class _BlockSolver(Solver):
    """``d_m = V_m |Lambda_m|^-1 V_m^T f_m`` point by point. Other
    constraints than FixAtoms and FixCartesian are applied afterwards, by
    ASE, to the move (as the specification's nodal step has it)."""

    def __init__(self, vectors: np.ndarray, values: np.ndarray, free: np.ndarray):
        self.vectors, self.values = vectors, values  # (N, dim, dim), (N, dim)
        self.free = free

    def solve(self, forces):
        dim = self.values.shape[1]
        move = np.zeros((len(self.values), 3))
        f = np.asarray(forces).reshape(-1, 3)[:, :dim]
        proj = np.einsum('nij,ni->nj', self.vectors, f) / self.values
        move[:, :dim] = np.einsum('nij,nj->ni', self.vectors, proj)
        return _held_at_zero(move, self.free)


# -- exact -------------------------------------------------------------------


class ExactModel(StiffnessModel):
    """The dense analytic Hessian (calculator property ``hessian``,
    (dim N, dim N)) on the moves the constraints allow
    (:func:`allowed_basis`), eigen-decomposed.

    ``floor`` is relative to the largest absolute eigenvalue of the whole
    matrix (default 1e-8: soft collective modes must keep their own
    curvature; rigid-body modes, where the forces have no component, are
    floored).
    """

    name = 'exact'
    prop = 'hessian'
    default_floor = 1e-8

    def at(self, atoms: Atoms, learnt: dict[str, Any] | None = None) -> Solver:
        hessian = atoms.calc.get_property('hessian', atoms)
        dim = hessian.shape[0] // len(atoms)
        basis = allowed_basis(atoms, dim)
        values, vectors = np.linalg.eigh(basis.T @ hessian @ basis)
        return _EigenSolver(basis @ vectors, self._absolute(values),
                            np.ones((len(atoms), dim), dtype=bool))


class _EigenSolver(_DofSolver):
    """``K^-1`` from its eigen-decomposition; also the damped
    ``(K + mu I)^-1`` of trust-region steps, for many ``mu`` at once
    (:meth:`shifted_solve`)."""

    def __init__(self, vectors, values, free):
        super().__init__(free)
        self.vectors, self.values = vectors, values

    def _solve(self, rhs):
        return self.vectors @ ((self.vectors.T @ rhs) / self.values)

    def shifted_solve(self, forces: np.ndarray, shifts: np.ndarray) -> np.ndarray:
        """The moves ``(K + mu I)^-1 f`` (each eigenvalue moved ``mu >= 0``
        away from zero: shorter moves, turned towards the forces), one per
        ``mu`` in ``shifts``: shape (len(shifts), N, 3)."""
        shifts = np.asarray(shifts, dtype=float)
        rhs = np.asarray(forces, dtype=float).reshape(-1, 3)[:, :self.dim][self.free]
        damped = self.values + np.sign(self.values) * shifts[:, None]
        moves = np.zeros((len(shifts), len(self.free), 3))
        moves[:, :, :self.dim][:, self.free] = (
            (self.vectors.T @ rhs) / damped) @ self.vectors.T
        return moves


# -- global sparse -------------------------------------------------------------


class GlobalModel(StiffnessModel):
    """``P = Q (L (x) I_dim) + blockdiag(|K_mm - Q deg(m) I|)``, sparse.

    Needs a calculator with the nodal blocks (property ``stiffness``) and a
    :class:`~ase_maud.potential.MaudPotential` (``calc.potential``: the
    constant ``Q (L (x) I_dim)``), as :class:`~ase_maud.MaudCalculator` has.
    The repulsion part of each nodal block is made positive (``'minimum'``)
    block by block.

    ``P`` and its factorisation are kept while no point has moved more than
    ``refresh`` times its nearest-neighbour distance (``nearest``, shared
    with the step bound) since they were built (the springs' part is exact
    everywhere; only the repulsion blocks age): the calculator is then asked
    for energy and forces alone (see :meth:`needs`). ``refresh=0`` rebuilds
    at every step. The Maud step with this model takes an L-BFGS correction
    over ``P^-1``, which learns the far-field repulsion that ``P`` leaves
    out and the ageing of a kept ``P``.
    """

    name = 'global'
    prop = 'stiffness'

    def __init__(self, target: str = 'minimum', floor: float | None = None,
                 refresh: float = 0.5, nearest: NearestDistances | None = None):
        super().__init__(target, floor)
        self.refresh = check('refresh', refresh)
        self.nearest = nearest or NearestDistances()
        self._kept: tuple[np.ndarray, _SparseSolver] | None = None

    def needs(self, atoms: Atoms) -> str | None:
        return self.prop if self._stale(atoms) else None

    def _stale(self, atoms: Atoms) -> bool:
        if self._kept is None or len(self._kept[0]) != len(atoms):
            return True
        positions = atoms.positions
        moved = np.linalg.norm(positions - self._kept[0], axis=1)
        if len(positions) < 2 or self.refresh == 0:
            return bool(moved.max() > 0)
        return bool(np.any(moved > self.refresh * self.nearest(positions)))

    def at(self, atoms: Atoms, learnt: dict[str, Any] | None = None) -> Solver:
        if not self._stale(atoms):
            return self._kept[1]
        matrix, free, diagonal = self.assemble(atoms)
        size = matrix.shape[0]
        if size > DENSE_MIN_DOFS and matrix.nnz > DENSE_GRAPH_FRACTION * size**2:
            solver = _MatrixFreeSolver(matrix, free, diagonal)
        elif size >= AMG_MIN_DOFS:
            solver = _MultigridSolver(matrix, free)
        else:
            solver = _FactorSolver(matrix, free)
        self._kept = atoms.positions.copy(), solver
        return solver

    def assemble(self, atoms: Atoms) -> tuple[sp.csr_matrix, np.ndarray, np.ndarray]:
        """``P`` on the free degrees of freedom (csr), the (N, dim) mask of
        those, and ``P``'s diagonal blocks (N, dim, dim)."""
        calc = atoms.calc
        blocks = calc.get_property('stiffness', atoms)
        n, dim = blocks.shape[:2]
        springs = calc.potential.spring_hessian(n)
        degree = springs.diagonal()[::dim, None, None] * np.eye(dim)  # Q deg(m) I
        values, vectors = np.linalg.eigh(blocks - degree)
        repulsion = np.einsum('nik,nk,njk->nij', vectors,
                              self._absolute(values), vectors)
        free = free_dofs(atoms, dim)
        keep = np.flatnonzero(free.ravel())
        diagonal = sp.bsr_matrix((repulsion, np.arange(n), np.arange(n + 1)),
                                 shape=(n * dim, n * dim))
        matrix = (springs + diagonal).tocsr()
        return matrix[keep][:, keep], free, repulsion + degree


class _SparseSolver(_DofSolver):
    """A solver that also holds ``P`` on the free DOFs (:attr:`matrix`)."""

    def __init__(self, matrix: sp.csr_matrix, free: np.ndarray):
        super().__init__(free)
        self.matrix = matrix


class _FactorSolver(_SparseSolver):
    """Sparse LU (SuperLU) of the free part of ``P``."""

    def __init__(self, matrix, free):
        super().__init__(matrix, free)
        self.lu = splu(matrix.tocsc(), permc_spec='MMD_AT_PLUS_A')

    def _solve(self, rhs):
        return self.lu.solve(rhs)


class _MultigridSolver(_SparseSolver):
    """Smoothed-aggregation multigrid (pyamg) as a CG preconditioner, for
    ``P`` too large to factorise."""

    def __init__(self, matrix, free):
        import pyamg
        super().__init__(matrix, free)
        self.hierarchy = pyamg.smoothed_aggregation_solver(matrix)

    def _solve(self, rhs):
        return self.hierarchy.solve(rhs, tol=SOLVE_RTOL, accel='cg',
                                    maxiter=200)


class _MatrixFreeSolver(_SparseSolver):
    """CG on sparse products with ``P``, preconditioned by the inverse of its
    diagonal blocks: for dense spring graphs (every pair sprung), whose
    factorisation would be dense. ``Q L`` of a complete graph is
    ``Q (N I - 1 1^T)``: one outlier eigenvalue, so CG needs few iterations.
    """

    def __init__(self, matrix, free, diagonal):
        super().__init__(matrix, free)
        keep = np.flatnonzero(free.ravel())
        n, dim = diagonal.shape[:2]
        inverse = sp.bsr_matrix((np.linalg.inv(diagonal), np.arange(n),
                                 np.arange(n + 1)), shape=(n * dim,) * 2).tocsr()
        self.inverse = inverse[keep][:, keep]

    def _solve(self, rhs):
        size = len(rhs)
        move, _ = cg(LinearOperator((size, size), matvec=self.matrix.dot), rhs,
                     rtol=SOLVE_RTOL, maxiter=10 * size + 100,
                     M=LinearOperator((size, size), matvec=self.inverse.dot))
        return move


MODELS: dict[str, type[StiffnessModel]] = {
    cls.name: cls for cls in (SecantModel, NodalModel, GlobalModel, ExactModel)}


def choose_model(atoms: Atoms, name: str = 'auto', target: str = 'minimum',
                 nearest: NearestDistances | None = None,
                 **options: Any) -> StiffnessModel:
    """The stiffness model ``name`` for ``atoms``' calculator.

    ``'auto'``: ``exact`` while the free degrees of freedom are at most
    :data:`EXACT_MAX_DOFS`, the calculator has a ``hessian`` and every
    constraint is one of :data:`PROJECTIONS` (a Hookean tether, say, adds
    stiffness the Hessian does not hold); else ``global`` if it has the nodal
    blocks and a ``potential`` (a :class:`~ase_maud.potential.MaudPotential`);
    else ``nodal`` if it has the blocks; else ``secant``. ``options`` go to
    the model (``floor``; ``method`` for nodal; ``kappa0`` for secant), and
    each is checked there; an option the chosen model does not take is
    checked here and dropped. ``nearest`` is shared with a model that ages
    with the positions.
    """
    calc = getattr(atoms, 'calc', None)
    offers = set(getattr(calc, 'implemented_properties', ()))
    if name == 'auto':
        dim = 2 if getattr(calc, 'dim', 3) == 2 else 3
        if ('hessian' in offers and free_dofs(atoms, dim).sum() <= EXACT_MAX_DOFS
                and all(isinstance(c, PROJECTIONS) for c in atoms.constraints)):
            name = 'exact'
        elif 'stiffness' in offers and hasattr(calc, 'potential'):
            name = 'global'
        elif 'stiffness' in offers:
            name = 'nodal'
        else:
            name = 'secant'
    if not (isinstance(name, str) and name in MODELS):
        raise ValueError(f"model must be 'auto', one of {sorted(MODELS)} or a "
                         f'StiffnessModel, got {name!r}')
    cls = MODELS[name]
    if cls.prop is not None and cls.prop not in offers:
        raise ValueError(f'model={name!r} needs a calculator with the property '
                         f'{cls.prop!r} (such as MaudCalculator); this one '
                         f'offers {sorted(offers)}')
    taken = {'floor', *_EXTRA_OPTIONS.get(cls, ())}
    for option in set(options) - taken:
        check(option, options[option])
    if cls is GlobalModel:
        options['nearest'] = nearest
        taken.add('nearest')
    return cls(target=target, **{k: v for k, v in options.items() if k in taken})


#: Options beyond ``target`` and ``floor`` that a model takes.
_EXTRA_OPTIONS = {NodalModel: ('method',), SecantModel: ('kappa0',)}
