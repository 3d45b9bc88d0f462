"""Stiffness models: the ``K`` that the Maud step ``dr = gamma K^-1 f`` divides by.

A model answers one question for the step (:mod:`ase_maud.strategy`): at
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
  graph's Laplacian and ``deg(m)`` its diagonal, both weighted by the springs'
  force densities ``q``: the springs' Hessian exactly (it is constant) plus the
  repulsion's nodal blocks. O(N + K) to build; solved by a sparse LU
  factorisation, by algebraic multigrid (pyamg) when the factorisation would
  be too large, and matrix-free by conjugate gradients when the spring graph
  is dense (every pair sprung).
- :class:`ExactModel` (``'exact'``): the dense analytic Hessian (property
  ``hessian``), eigen-decomposed: the step is saddle-free Newton. O((dim N)^3)
  per step, for small scenes.
- :class:`SpringsModel` (``'springs'``): the springs' exact, constant Hessian
  ``Q L`` per coordinate (one N x N matrix for every coordinate), factorised
  once per run; the repulsion is left to the L-BFGS memory of the step rule.
  Energy and forces only, no stiffness property: for large scenes.
- :class:`~ase_maud.nearfield.NearModel` (``'near'``, opt-in, never
  ``'auto'``'s): the springs model's ``P`` plus the repulsion's signed pair
  blocks of near pairs, solved by truncated CG preconditioned by the springs
  factor, for scenes where the repulsion sets the shape.

``target='minimum'`` makes every model positive definite: eigenvalues are
replaced by their absolute values and floored at ``floor`` times the largest
(per block for the nodal and global models, over the whole matrix for the
exact one), so no direction is uphill. ``target='stationary'`` keeps the signs
(saddles and maxima are then fixed points of the step). ``target='saddle'``
gives the Hessian's eigenpairs on the internal moves (rigid-body motions
projected out), signed and unfloored, for the step rule's eigenvector
following: all of them (the exact model, :meth:`ExactModel._internal`), or the
lowest few from Hessian-vector products (the springs model). Degrees of freedom
held by :class:`~ase.constraints.FixAtoms` and
:class:`~ase.constraints.FixCartesian` are removed from ``K`` and never move;
other constraints are left to ASE (the optimizer applies them to every move).
A ``dim=2`` scene works with 2x2 blocks and never moves ``z``.

A model is stateless but for caches: what it learns in a run (the secant
curvature) is handed back to the step rule (:meth:`StiffnessModel.observe`),
which keeps it in its state and passes it to :meth:`StiffnessModel.at`. The
step rule's defaults for each model are in :data:`ase_maud.strategy.STEP_DEFAULTS`.
"""

from __future__ import annotations

import warnings
from abc import ABC, abstractmethod
from collections.abc import Callable
from typing import Any

import numpy as np
import scipy.linalg
import scipy.sparse as sp
from ase import Atoms
from scipy.linalg.lapack import dpotrf, dpotrs, dsyevd
from scipy.sparse.linalg import LinearOperator, cg, splu

from . import physics
from .analysis import Work, hessian_rows
from .calculator import MaudCalculator
from .checks import all_finite, check
from .dofs import allowed_basis, allowed_rigid_modes, free_dofs, project_off, rigid_body_modes
from .neighbours import NearestDistances
from .topology import spring_components

#: ``model='auto'`` takes the exact model up to this many free degrees of
#: freedom (dense eigen-decomposition cost against a calculator call; see
#: docs/optimizer.md for the measurement), the global model above.
EXACT_MAX_DOFS = 150
#: Sparse symmetric positive-definite matrices of this many rows or more are
#: solved by algebraic multigrid, smaller ones are factorised
#: (:func:`spd_inverse`; docs/benchmarks.md has the measurement).
AMG_MIN_DOFS = 200_000
#: The global model goes matrix-free when the spring graph holds more than
#: this fraction of all pairs (a factorisation would be dense).
DENSE_GRAPH_FRACTION = 0.25
#: ... and has more free DOFs than this (a small dense LU is cheap).
DENSE_MIN_DOFS = 300
#: Relative residual of the iterative solves (CG, multigrid).
SOLVE_RTOL = 1e-10
#: Relative residual of the multigrid solves of the springs model, whose
#: solution only starts the L-BFGS recursion.
SPRINGS_RTOL = 1e-6
#: The smallest positive float: the floor of eigenvalues made safe to divide by.
TINY = np.finfo(float).tiny



class Solver(ABC):
    """A stiffness ``K`` frozen at one configuration: a local model."""

    @abstractmethod
    def solve(self, forces: np.ndarray) -> np.ndarray:
        """The move ``d`` with ``K d = forces``, shape (N, 3), zero on the
        degrees of freedom FixAtoms and FixCartesian hold and on ``z`` in 2D."""


class DampedSolver(Solver):
    """A local model a trust region can damp (:func:`ase_maud.search.trust_region`):
    ``definite`` (whether ``K`` is positive definite), ``scale`` (a bound on
    the size of its eigenvalues, force per length), ``K v`` and the damped
    solve ``(K + mu I)^-1 f``."""

    definite: bool
    scale: float

    @abstractmethod
    def dot(self, move: np.ndarray) -> np.ndarray:
        """``K v`` (N, 3) for a move (N, 3)."""

    @abstractmethod
    def damped(self, forces: np.ndarray) -> Callable[[float], np.ndarray | None]:
        """The damped solve of ``forces``: ``mu`` to ``(K + mu I)^-1 f`` (N, 3),
        or None if ``K + mu I`` is not definite (what every ``mu`` shares is
        done once)."""


class ModeSolver(Solver):
    """A local model with eigenpairs on the internal moves, for a saddle
    search (:class:`ase_maud.strategy.Saddle`)."""

    @abstractmethod
    def eigenpairs(self, count: int, guess: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """Eigenvalues (ascending, signed, force per length) and their modes
        as orthonormal moves (k, N, 3): every one for a model whose class has
        :attr:`StiffnessModel.complete_modes`, else the lowest ``count``,
        started from the moves ``guess`` (k, N, 3) if given."""

    @abstractmethod
    def curvature(self, move: np.ndarray) -> np.ndarray:
        """``H v`` (N, 3) on the internal moves."""


class StiffnessModel(ABC):
    """What the Maud step divides the forces by; see the module docstring.

    ``target`` ('minimum', 'stationary' or 'saddle') and ``floor`` (relative
    eigenvalue floor; None: the model's :attr:`default_floor`) are checked
    here. ``prop`` names the calculator property whose request computes, in
    the same calculator call as the energy and forces, what :meth:`at`
    needs (None: nothing beyond the forces).
    """

    name: str = ''
    prop: str | None = None
    default_floor = 1e-2
    #: For ``target='saddle'``: whether the model's solver gives every
    #: eigenpair (else the lowest ones, :class:`ModeSolver`).
    complete_modes = False
    #: Arrays (N, 3) the model keeps in what it has learnt (the run's state,
    #: which a restart file holds, one row each), by name.
    kept_arrays: tuple[str, ...] = ()

    def __init__(self, target: str = 'minimum', floor: float | None = None):
        self.target = check('target', target) or 'minimum'
        floor = check('floor', floor)
        self.floor = self.default_floor if floor is None else floor
        #: Hessian-vector products and Hessians computed for the model
        #: beyond the calculator's calls (counted by its solvers and the optimizer).
        self.work = Work()

    @abstractmethod
    def at(self, atoms: Atoms, learnt: dict[str, Any] | None = None) -> Solver:
        """The model at ``atoms``' current positions, with what it has learnt
        in the run so far (:meth:`observe`)."""

    def of_results(self, atoms: Atoms, results: dict[str, Any],
                   learnt: dict[str, Any] | None = None) -> Solver:
        """:meth:`at`, where ``results`` are the calculator's results at
        ``atoms``' positions, handed over by the loop that computed them
        (:func:`ase_maud.arrays.relax`, a MaudCalculator's): a model that
        needs one of them reads it there instead of asking the calculator
        again (its change detection and copy). This one asks (:meth:`at`)."""
        return self.at(atoms, learnt)

    def todict(self) -> dict[str, Any]:
        """The model's settings, for an optimizer's ``todict``."""
        return {'model': self.name, 'target': self.target, 'floor': self.floor}

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
        floor = np.maximum(self.floor * size.max(axis=-1, keepdims=True), TINY)
        safe = np.maximum(size, floor)
        if self.target == 'stationary':
            safe = np.where(values < 0, -safe, safe)
        return safe


def _free_index(free: np.ndarray) -> np.ndarray:
    """The flat indices into an (N, 3) array of the components a ``free``
    (N, dim) mask frees (taken and put by index: cheaper than the mask on a
    scene of tens of points)."""
    flat = np.flatnonzero(free)
    dim = free.shape[1]
    return flat if dim == 3 else 3 * (flat // dim) + flat % dim


class _DofSolver(Solver):
    """Gathers the free components of the forces into a vector, solves, and
    scatters the move back into an (N, 3) array. ``index`` is
    :func:`_free_index` of ``free``, given by a caller that keeps it with its
    mask (the exact model, with its constraints), else found here."""

    def __init__(self, free: np.ndarray, index: np.ndarray | None = None):
        self.free = free  # (N, dim) mask
        self.dim = free.shape[1]
        #: The free components' flat indices into an (N, 3) array.
        self.index = _free_index(free) if index is None else index
        #: Every component is free: a move's components are its (N, 3) array.
        self.every = self.index.size == 3 * len(free)

    def solve(self, forces: np.ndarray) -> np.ndarray:
        return self._scatter(self._solve(self._gather(forces)))

    def _gather(self, move: np.ndarray) -> np.ndarray:
        """The free components (n,) of a move (N, 3)."""
        return np.asarray(move, dtype=float).reshape(-1).take(self.index)

    def _scatter(self, v: np.ndarray) -> np.ndarray:
        """Free components (n,) or (n, k) as moves (N, 3) or (k, N, 3), zero
        where held; a move (n,) of every component is ``v`` reshaped (each
        solve's ``v`` is its own array)."""
        if self.every and v.ndim == 1:
            return v.reshape(len(self.free), 3)
        out = np.zeros((*v.shape[1:], 3 * len(self.free)))
        out[..., self.index] = v.T
        return out.reshape(*v.shape[1:], len(self.free), 3)

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


class BFGSModel(SecantModel):
    """BFGS's inverse Hessian, learnt from the forces, for calculators that
    give no stiffness (``'bfgs'``): ``K^-1`` is ``I / kappa`` corrected by
    the step rule's L-BFGS memory, whose defaults
    (:data:`ase_maud.strategy.STEP_DEFAULTS`) keep the pairs of the last
    100 accepted steps and no momentum: for a run of fewer steps, or a scene
    of fewer coordinates, that is the BFGS update of ``I / kappa`` by every
    step. ``kappa`` starts at ``kappa0`` (ASE's 70 eV/A**2) and is then the
    geometric mean ``|y| / |s|`` of the two secant (Barzilai-Borwein)
    curvatures ``s.y / s.s`` and ``y.y / s.y`` of the last step with ``s.y
    > 0`` (the smaller one alone, the model's first form, took up to 1.7x
    BFGS's calls on Lennard-Jones clusters: docs/benchmarks.md). Its
    history is the run's state (the pairs of
    :class:`~ase_maud.strategy.MaudState`, in the restart file)."""

    name = 'bfgs'

    def observe(self, step: np.ndarray, force_drop: np.ndarray,
                learnt: dict[str, Any]) -> dict[str, Any]:
        sy, ss = np.vdot(step, force_drop), np.vdot(step, step)
        if not (sy > 0 and ss > 0):
            return learnt
        return {**learnt, 'kappa': float(np.sqrt(np.vdot(force_drop, force_drop) / ss))}


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

    def todict(self) -> dict[str, Any]:
        return {**super().todict(), 'method': self.method}

    def at(self, atoms: Atoms, learnt: dict[str, Any] | None = None) -> Solver:
        blocks = atoms.calc.get_property('stiffness', atoms)
        free = free_dofs(atoms, blocks.shape[1])
        values, vectors = np.linalg.eigh(blocks)
        size = np.abs(values)
        if self.method == 'scalar':
            floor = np.maximum(self.floor * size.max(axis=1), TINY)
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
    (:func:`allowed_basis`, kept while the constraints are the same).

    For ``'minimum'`` it is factorised by Cholesky, shifted by ``floor``
    times its largest absolute row sum (a bound on its largest eigenvalue),
    when that succeeds: the Newton step costs no eigen-decomposition
    (:class:`_CholeskySolver`). Where the shifted Hessian is indefinite, or
    for ``'stationary'``, it is eigen-decomposed and its eigenvalues made
    safe (:meth:`StiffnessModel._absolute`: absolute values for
    ``'minimum'``, saddle-free Newton; signs kept for ``'stationary'``);
    ``floor`` is relative to the largest absolute eigenvalue of the whole
    matrix (default 1e-8: soft collective modes must keep their own
    curvature; rigid-body modes, where the forces have no component, are
    floored). For ``'saddle'`` it gives every eigenpair on the internal
    moves. (A Cholesky-only treatment of the indefinite case, Gershgorin
    shifts or a modified LDL^T, was measured and took more steps:
    docs/optimizer.md.)
    """

    name = 'exact'
    prop = 'hessian'
    default_floor = 1e-8
    complete_modes = True

    def __init__(self, target: str = 'minimum', floor: float | None = None):
        super().__init__(target, floor)
        self._basis: tuple[Any, np.ndarray | None] | None = None
        self._held: np.ndarray | None = None
        self._kept_index = np.empty(0, dtype=np.intp)   # the coordinates not held
        self._free = np.ones((0, 3), dtype=bool)   # the solvers' free mask
        self._free_index = _free_index(self._free)   # ... and its components

    def needs(self, atoms: Atoms) -> str | None:
        return None if self._rows(atoms) is not None else self.prop

    def at(self, atoms: Atoms, learnt: dict[str, Any] | None = None) -> Solver:
        rows = self._rows(atoms)
        if rows is None:
            return self.local(atoms.calc.get_property('hessian', atoms), atoms)
        self.work.hessians += 1
        return self.local(atoms.calc.get_hessian_block(atoms, rows), atoms, rows)

    def _rows(self, atoms: Atoms) -> np.ndarray | None:
        """The atoms whose block of the Hessian the model asks for instead
        of the whole (:func:`~ase_maud.analysis.hessian_rows`: where the
        constraints hold every coordinate of most atoms), or None."""
        if type(atoms.calc) is not MaudCalculator:   # as hessian_rows
            return None
        self.basis(atoms, atoms.calc.dim)
        return None if self._held is None else hessian_rows(atoms, ~self._held)

    def of_results(self, atoms: Atoms, results: dict[str, Any],
                   learnt: dict[str, Any] | None = None) -> Solver:
        """The model of ``results['hessian']``: the loop that computed it
        hands it over rather than having it asked of the calculator
        (:meth:`at`, which does when ``results`` hold none). It is checked
        as any Hessian is (:meth:`local`): a MaudCalculator's own results
        are finite, but a subclass's need not be."""
        hessian = results.get('hessian')
        return self.at(atoms, learnt) if hessian is None else self.local(hessian, atoms)

    def local(self, hessian: np.ndarray, atoms: Atoms, rows: np.ndarray | None = None,
              ) -> Solver:
        """The model of the dense ``hessian`` (dim N, dim N), or its block on
        the atoms ``rows`` (dim n, dim n: every coordinate the constraints
        leave free is theirs), at ``atoms``' positions (its constraints say
        which moves are allowed); a LinAlgError if it is not finite."""
        if not all_finite(hessian):
            raise np.linalg.LinAlgError('the Hessian is not finite')
        dim = hessian.shape[0] // (len(atoms) if rows is None else len(rows))
        allowed = basis = self.basis(atoms, dim)
        free, index = self._free, self._free_index
        if self._held is not None:   # whole coordinates: a selection
            kept = (self._kept_index if rows is None
                    else np.flatnonzero(~self._held[rows].ravel()))
            matrix, basis = hessian.take(kept, axis=0).take(kept, axis=1), None
        else:
            matrix = hessian if basis is None else basis.T @ hessian @ basis
        if self.target == 'saddle':
            return self._internal(matrix.copy() if matrix is hessian else matrix,
                                  allowed_rigid_modes(atoms.positions, dim, allowed), basis)
        if self.target == 'minimum':
            return (_CholeskySolver.of(matrix, basis, free, index, self.floor)
                    or _EigenSolver(matrix, basis, free, index, self._absolute))
        return _EigenSolver(matrix, basis, free, index, self._absolute)

    def _internal(self, matrix: np.ndarray, rigid: np.ndarray,
                  basis: np.ndarray | None) -> _EigenSolver:
        """The saddle's solver of ``matrix`` (the Hessian on the allowed
        moves, changed in place) on the internal moves: projected off the
        allowed ``rigid`` motions (dim N, r) and those lifted above every
        eigenvalue (twice the largest row sum, a bound on the largest, plus
        one for a zero matrix), so the eigen-decomposition leaves them out as
        its top ``r`` pairs."""
        rigid = rigid.take(self._kept_index, axis=0) if self._held is not None else (
            rigid if basis is None else basis.T @ rigid)
        rigid = scipy.linalg.orth(rigid) if rigid.size else rigid
        lift = 2.0 * np.abs(matrix).sum(axis=1).max(initial=0.0) + 1.0
        project_off(matrix, rigid)
        matrix += lift * rigid @ rigid.T
        return _EigenSolver(matrix, basis, self._free, self._free_index, np.asarray,
                            lifted=rigid.shape[1])

    def basis(self, atoms: Atoms, dim: int) -> np.ndarray | None:
        """:func:`allowed_basis`, kept while the constraints are the same;
        None if every move is allowed. Where its columns are coordinates (up
        to sign: the constraints hold whole coordinates, as FixAtoms and
        FixCartesian do), :attr:`_held` marks the held ones (N, dim) and
        :attr:`_kept_index` numbers the others, for a selection of the
        Hessian's rows and columns in place of products; :attr:`_free` is
        the solvers' free mask (N, dim: every coordinate but those held) and
        :attr:`_free_index` its components (:func:`_free_index`)."""
        key = (len(atoms), dim, [(type(c).__name__, repr(c.todict()))
                                 for c in atoms.constraints])
        if self._basis is None or self._basis[0] != key:
            basis = allowed_basis(atoms, dim) if atoms.constraints else None
            self._basis, self._held = (key, basis), None
            if basis is not None and (np.abs(basis).sum(axis=0) == 1).all() and (
                    np.count_nonzero(basis, axis=0) == 1).all():
                self._held = ~np.abs(basis).sum(axis=1).astype(bool).reshape(-1, dim)
                self._kept_index = np.flatnonzero(~self._held)
            self._free = (np.ones((len(atoms), dim), dtype=bool) if self._held is None
                          else ~self._held)
            self._free_index = _free_index(self._free)
        return self._basis[1]


class _DenseSolver(_DofSolver):
    """A dense ``matrix`` on the columns of ``basis`` (None: every
    coordinate): moves in and out of that basis, and ``K v``."""

    def __init__(self, matrix: np.ndarray, basis: np.ndarray | None, free: np.ndarray,
                 index: np.ndarray | None):
        super().__init__(free, index)
        self.matrix, self.basis = matrix, basis

    def _into(self, rhs: np.ndarray) -> np.ndarray:
        return rhs if self.basis is None else self.basis.T @ rhs

    def _out(self, v: np.ndarray) -> np.ndarray:
        return v if self.basis is None else self.basis @ v

    def _moves(self, v: np.ndarray) -> np.ndarray:
        """Components (n,) or (n, k) in the basis as moves (N, 3) or (k, N, 3)."""
        return self._scatter(self._out(v))

    def dot(self, move: np.ndarray) -> np.ndarray:
        return self._moves(self.matrix @ self._into(self._gather(move)))


class _CholeskySolver(_DenseSolver, DampedSolver):
    """``K^-1`` by the Cholesky factor of ``K + s I``, ``s`` = ``floor``
    times the largest absolute row sum (a bound on the size of the
    eigenvalues, :attr:`scale`): no eigen-decomposition. Made by
    :meth:`of` where that shifted matrix is definite."""

    definite = True

    def __init__(self, matrix: np.ndarray, basis: np.ndarray | None, free: np.ndarray,
                 index: np.ndarray | None, scale: float, factor: np.ndarray):
        super().__init__(matrix, basis, free, index)
        self.scale, self.factor = scale, factor

    @classmethod
    def of(cls, matrix: np.ndarray, basis: np.ndarray | None, free: np.ndarray,
           index: np.ndarray | None, floor: float) -> _CholeskySolver | None:
        """The solver of ``matrix``, or None if it is not definite."""
        scale = float(np.abs(matrix).sum(axis=1).max(initial=0.0))
        factor = _cholesky(matrix, floor * scale)
        return None if factor is None else cls(matrix, basis, free, index, scale, factor)

    def _solve(self, rhs):
        return self._out(dpotrs(self.factor, self._into(rhs))[0])

    def damped(self, forces: np.ndarray) -> Callable[[float], np.ndarray | None]:
        rhs = self._into(self._gather(forces))

        def move(mu: float) -> np.ndarray | None:
            factor = _cholesky(self.matrix, mu)
            return None if factor is None else self._moves(dpotrs(factor, rhs)[0])
        return move


def _cholesky(matrix: np.ndarray, shift: float) -> np.ndarray | None:
    """The upper Cholesky factor of ``matrix + shift I`` (LAPACK's potrf, as
    ``scipy.linalg.cho_factor`` calls it, without its checks and batching
    wrapper, which cost as much as the factorisation on tens of unknowns), or
    None if not definite."""
    shifted = matrix + 0.0   # a copy with positive zeros, as matrix + shift I has them
    shifted.flat[::len(matrix) + 1] += shift
    factor, info = dpotrf(shifted, lower=False, clean=False, overwrite_a=True)
    return factor if info == 0 else None


class _EigenSolver(_DenseSolver, DampedSolver, ModeSolver):
    """``K^-1`` from its eigen-decomposition, its eigenvalues made safe by
    ``absolute`` (signed and floored for ``'stationary'``; as they are for
    ``'saddle'``, whose :meth:`eigenpairs` are every one); also the damped
    ``(K + mu I)^-1`` of trust-region steps (each eigenvalue moved ``mu``
    away from zero). The decomposition is made when first needed; its top
    ``lifted`` pairs (rigid motions lifted out of the way:
    :meth:`ExactModel._internal`) are left out."""

    definite = False

    def __init__(self, matrix, basis, free, index, absolute, lifted: int = 0):
        super().__init__(matrix, basis, free, index)
        self.absolute, self.lifted = absolute, lifted
        self._pairs: tuple[np.ndarray, np.ndarray] | None = None

    def _decomposed(self) -> tuple[np.ndarray, np.ndarray]:
        if self._pairs is None:
            # LAPACK's syevd on the lower triangle, as numpy's eigh calls it
            # (the same digits), without its wrapper
            values, vectors, info = dsyevd(self.matrix, lower=True)
            if info:
                raise np.linalg.LinAlgError(f'the eigen-decomposition did not converge '
                                            f'(LAPACK syevd info {info})')
            kept = len(values) - self.lifted
            self._pairs = self.absolute(values[:kept]), vectors[:, :kept]
        return self._pairs

    @property
    def scale(self) -> float:
        return float(np.abs(self._decomposed()[0]).max(initial=0.0))

    def eigenpairs(self, count: int = 0, guess: np.ndarray | None = None):
        values, vectors = self._decomposed()
        return values, self._moves(vectors)

    def curvature(self, move: np.ndarray) -> np.ndarray:
        return self.dot(move)

    def _solve(self, rhs):
        values, vectors = self._decomposed()
        return self._out(vectors @ ((vectors.T @ self._into(rhs)) / values))

    def damped(self, forces: np.ndarray) -> Callable[[float], np.ndarray]:
        values, vectors = self._decomposed()
        coefficients, signs = vectors.T @ self._into(self._gather(forces)), np.sign(values)
        return lambda mu: self._moves(vectors @ (coefficients / (values + signs * mu)))


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
    kept_arrays = ('built',)

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
        """``P`` kept, or built again where it went stale; ``learnt['built']``
        (the run's state) says where it was built, so that a resumed run
        builds it there again and makes the uninterrupted run's steps."""
        learnt = {} if learnt is None else learnt
        built = learnt.get('built')
        if built is not None and (self._kept is None
                                  or not np.array_equal(self._kept[0], built)):
            there = atoms.copy()   # a resumed run: P where the run built it
            there.calc = atoms.calc
            there.set_positions(built, apply_constraint=False)
            self._kept = built, self._solver(there)
        if self._stale(atoms):
            self._kept = atoms.positions.copy(), self._solver(atoms)
        learnt['built'] = self._kept[0]
        return self._kept[1]

    def _solver(self, atoms: Atoms) -> _SparseSolver:
        matrix, free, diagonal = self.assemble(atoms)
        size = matrix.shape[0]
        if size > DENSE_MIN_DOFS and matrix.nnz > DENSE_GRAPH_FRACTION * size**2:
            return _MatrixFreeSolver(matrix, free, diagonal)
        return _FactorSolver(matrix, free)

    def assemble(self, atoms: Atoms) -> tuple[sp.csr_matrix, np.ndarray, np.ndarray]:
        """``P`` on the free degrees of freedom (csr), the (N, dim) mask of
        those, and ``P``'s diagonal blocks (N, dim, dim)."""
        calc = atoms.calc
        blocks = calc.get_property('stiffness', atoms)
        n, dim = blocks.shape[:2]
        springs = calc.potential.spring_hessian(n)
        degree = springs.diagonal()[::dim, None, None] * np.eye(dim)  # Q deg_q(m) I
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
    """The free part of ``P`` inverted by :func:`spd_inverse`."""

    def __init__(self, matrix, free):
        super().__init__(matrix, free)
        self.inverse = spd_inverse(matrix, SOLVE_RTOL)

    def _solve(self, rhs):
        return self.inverse(rhs)


def spd_inverse(matrix: sp.spmatrix, rtol: float) -> Any:
    """``b -> matrix^-1 b`` for a sparse symmetric positive-definite matrix:
    SuperLU in symmetric mode (minimum-degree ordering of ``A + A^T``, no
    pivoting across the diagonal) below :data:`AMG_MIN_DOFS` rows, else
    conjugate gradients preconditioned by smoothed-aggregation multigrid
    (pyamg) to the relative residual ``rtol`` (a factorisation could fill in
    beyond memory). ``b`` is a vector or a (rows, k) array."""
    if matrix.shape[0] < AMG_MIN_DOFS:
        lu = splu(sp.csc_matrix(matrix), permc_spec='MMD_AT_PLUS_A',
                  diag_pivot_thresh=0.0, options={'SymmetricMode': True})
        return lu.solve
    import pyamg
    hierarchy = pyamg.smoothed_aggregation_solver(sp.csr_matrix(matrix))

    def solve(rhs):
        if rhs.ndim == 1:
            return hierarchy.solve(rhs, tol=rtol, accel='cg', maxiter=200)
        return np.column_stack([solve(column) for column in rhs.T])
    return solve


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


# -- springs ------------------------------------------------------------------


class SpringsModel(StiffnessModel):
    """``P = Q L + diag(s)`` for each coordinate: the springs' exact, constant
    Hessian ``Q (L (x) I_dim)`` is block diagonal by coordinate, so one N x N
    matrix (``L`` the spring graph's Laplacian weighted by the force densities
    ``q``, from the calculator's
    :class:`~ase_maud.potential.MaudPotential`) serves every coordinate,
    restricted to the points free in it (FixAtoms, FixCartesian). It is
    factorised once per run (:func:`spd_inverse`), and again only if the
    potential or the constraints change; the calculator is asked for energy
    and forces alone.

    ``s`` makes ``P`` definite where the springs leave it singular: the
    repulsion's stiffness along the line to the nearest neighbour,
    ``2 a**3 Q / r**3`` (``r`` that distance at the start), at a point with no
    spring, and ``floor`` times the largest diagonal entry on the points of a
    spring component that holds no fixed point (it could translate as a
    whole). The repulsion's
    stiffness elsewhere, and its coupling, is left to the L-BFGS memory of
    the step rule (:data:`ase_maud.strategy.STEP_DEFAULTS`).
    """

    name = 'springs'
    default_floor = 1e-3

    def __init__(self, target: str = 'minimum', floor: float | None = None,
                 nearest: NearestDistances | None = None):
        super().__init__(target, floor)
        self.nearest = nearest or NearestDistances()
        self._kept: tuple[Any, np.ndarray, Solver] | None = None

    def at(self, atoms: Atoms, learnt: dict[str, Any] | None = None) -> Solver:
        potential = atoms.calc.potential
        free = free_dofs(atoms, potential.dim)
        kept = self._kept
        if kept is None or kept[0] is not potential or not np.array_equal(kept[1], free):
            self._kept = potential, free, self._solver(atoms, potential, free)
        if self.target == 'saddle':
            frozen = atoms.copy()   # the positions of this step, the same calculator
            frozen.calc = atoms.calc
            return _LowestModes(self._kept[2], frozen, free, self.work)
        return self._kept[2]

    def _solver(self, atoms: Atoms, potential: Any, free: np.ndarray) -> Solver:
        n = len(atoms)
        laplacian = potential.Q * potential.spring_laplacian(n)
        diagonal = np.zeros(n)
        alone = laplacian.diagonal() == 0
        if alone.any() and n > 1:
            distance = self.nearest(atoms.positions)[alone]
            diagonal[alone] = potential.Q * physics.repulsion_stiffness(
                distance / potential.a)
        largest = max(laplacian.diagonal().max(initial=0.0), diagonal.max(initial=0.0))
        matrix = sp.csr_matrix(laplacian + sp.diags(diagonal))
        inverses = {}
        for mask in {column.tobytes(): column for column in free.T}.values():
            keep = np.flatnonzero(mask)
            shift = self.floor * largest * _floating(potential.springs, ~mask)[keep]
            inverses[mask.tobytes()] = keep, spd_inverse(
                matrix[keep][:, keep] + sp.diags(shift), SPRINGS_RTOL), shift
        return _CoordinateSolver([inverses[column.tobytes()] for column in free.T],
                                 free, matrix)


def _floating(springs: np.ndarray, held: np.ndarray) -> np.ndarray:
    """Boolean mask of the points whose spring component holds no point of
    ``held`` (N,): the components free to translate."""
    labels = spring_components(len(held), springs)
    anchored = np.zeros(labels.max(initial=-1) + 1, dtype=bool)
    anchored[labels[held]] = True
    return ~anchored[labels]


#: Relative residual (of the largest diagonal entry of ``P``) to which the
#: lowest modes of a large saddle search are computed (LOBPCG).
MODES_RTOL = 1e-4
#: ... in at most this many LOBPCG iterations: from a random start (a
#: search's first step), and from the last step's modes (every later one).
MODES_MAXITER, MODES_WARM_MAXITER = 100, 20


class _LowestModes(ModeSolver):
    """``P^-1`` of the springs model, the Hessian on the internal moves
    (:meth:`curvature`, Hessian-vector products through
    :func:`ase_maud.analysis.hessian_operator`, rigid-body motions projected
    out) and its lowest eigenpairs (:meth:`eigenpairs`, LOBPCG preconditioned
    by ``P^-1``; a dense eigen-decomposition of the products where the
    scene is too small for LOBPCG): what a large saddle search follows
    (:class:`ase_maud.strategy.Saddle`). Every vector it multiplies by the
    Hessian is counted in ``work``."""

    def __init__(self, inner: Solver, atoms: Atoms, free: np.ndarray, work: Work):
        from .analysis import hessian_operator
        self.inner, self.free = inner, free
        self.rigid = rigid_body_modes(atoms.positions, free, free.shape[1])
        self.operator = hessian_operator(atoms, free, self.rigid, work)

    def solve(self, forces):
        return self.inner.solve(forces)

    def _gather(self, moves: np.ndarray) -> np.ndarray:
        """Moves (k, N, 3) -> their free components (n, k)."""
        return moves[:, :, :self.free.shape[1]][:, self.free].T

    def _spread(self, v: np.ndarray) -> np.ndarray:
        """Free components (n, k) -> moves (k, N, 3), zero where held."""
        out = np.zeros((v.shape[1], len(self.free), 3))
        out[:, :, :self.free.shape[1]][:, self.free] = v.T
        return out

    def curvature(self, move: np.ndarray) -> np.ndarray:
        """``H move`` (N, 3) on the internal moves: zero on held
        coordinates, without rigid-body components."""
        return self._spread(self.operator @ self._gather(move[None]))[0]

    def eigenpairs(self, count: int, guess: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """The ``count`` lowest eigenvalues (ascending) and their modes
        (count, N, 3), started from the moves ``guess`` (k, N, 3) if given."""
        from scipy.sparse.linalg import lobpcg

        size = self.operator.shape[0]
        if size <= 5 * (count + self.rigid.shape[1]):   # too few for LOBPCG
            internal = (scipy.linalg.null_space(self.rigid.T) if self.rigid.size
                        else np.eye(size))
            matrix = internal.T @ (self.operator @ internal)
            values, vectors = scipy.linalg.eigh(0.5 * (matrix + matrix.T))
            return values[:count], self._spread(internal @ vectors[:, :count])

        def precondition(v):
            return self._gather(np.array([self.solve(m) for m in
                                          self._spread(v.reshape(len(v), -1))]))

        start = np.random.default_rng(0).standard_normal((size, count))
        if guess is not None:
            start[:, :len(guess)] = self._gather(guess)
        diagonal = precondition(np.eye(len(start), 1)).max()   # a scale of 1 / P
        with warnings.catch_warnings():
            warnings.simplefilter('ignore', UserWarning)   # LOBPCG's "not reaching tol"
            values, vectors = lobpcg(
                self.operator, start,
                M=LinearOperator(self.operator.shape, matvec=precondition,
                                 matmat=precondition, dtype=float),
                Y=self.rigid if self.rigid.size else None,
                tol=MODES_RTOL / abs(diagonal), largest=False,
                maxiter=MODES_MAXITER if guess is None else MODES_WARM_MAXITER)
        order = np.argsort(values)
        vectors = vectors[:, order] / np.linalg.norm(vectors[:, order], axis=0)
        return values[order], self._spread(vectors)


class _CoordinateSolver(Solver):
    """``P^-1 f`` coordinate by coordinate: column ``c`` of the move is the
    inverse (``keep``, ``inverse``, ``shift``) of coordinate ``c`` applied to
    its free points; coordinates with the same free points share one
    inverse. ``P`` of a coordinate is ``matrix`` (N, N; ``Q L + diag(s)``)
    on its free points plus ``diag(shift)`` (the floor on floating points);
    :meth:`dot` multiplies by it."""

    def __init__(self, columns: list[tuple[np.ndarray, Any, np.ndarray]], free: np.ndarray,
                 matrix: sp.csr_matrix):
        self.columns, self.free, self.matrix = columns, free, matrix

    def dot(self, move: np.ndarray) -> np.ndarray:
        """``P move`` (N, 3), force per length: each coordinate's ``P`` on
        its free points, zero on the held ones and on ``z`` in 2D."""
        v = np.asarray(move, dtype=float).reshape(-1, 3)
        out = np.zeros_like(v)
        for c, (keep, _, shift) in enumerate(self.columns):
            column = np.zeros(len(v))
            column[keep] = v[keep, c]
            out[keep, c] = (self.matrix @ column)[keep] + shift * v[keep, c]
        return out

    def solve(self, forces):
        f = np.asarray(forces, dtype=float).reshape(-1, 3)
        move = np.zeros_like(f)
        groups: dict[int, list[int]] = {}
        for c, (keep, _, _) in enumerate(self.columns):
            groups.setdefault(id(keep), []).append(c)
        for coordinates in groups.values():
            keep, inverse, _ = self.columns[coordinates[0]]
            if keep.size:
                move[np.ix_(keep, coordinates)] = inverse(f[np.ix_(keep, coordinates)])
        return move
