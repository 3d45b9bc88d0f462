"""The exact model: the dense analytic Hessian, factorised or
eigen-decomposed (saddle-free Newton, eigenvector following).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import scipy.linalg
from ase import Atoms
from ase.constraints import FixAtoms, FixCartesian
from scipy.linalg.lapack import dpotrf, dpotrs, dsyevd

from ase_maud.calculator.maud_calculator import MaudCalculator
from ase_maud.checks import all_finite
from ase_maud.optimize.models.base import (
    DampedSolver,
    DofSolver,
    ModeSolver,
    Solver,
    StiffnessModel,
    free_index,
)
from ase_maud.physics.dofs import (
    allowed_basis,
    allowed_rigid_modes,
    free_dofs,
    project_off,
)

#: ``model='auto'`` takes the exact model up to this many free degrees of
#: freedom (dense eigen-decomposition cost against a calculator call; see
#: docs/optimizer.md for the measurement), the global model above.
EXACT_MAX_DOFS = 150


class ExactModel(StiffnessModel):
    """The dense analytic Hessian (calculator property ``hessian``,
    (dim N, dim N)) on the moves the constraints allow
    (:func:`allowed_basis`, kept while the constraints are the same).

    For ``'minimum'`` it is factorised by Cholesky, shifted by ``floor``
    times its largest absolute row sum (a bound on its largest eigenvalue),
    when that succeeds: the Newton step costs no eigen-decomposition
    (:class:`_CholeskySolver`). Where the shifted Hessian is indefinite, or
    for ``'stationary'``, it is eigen-decomposed and its eigenvalues made
    safe (:meth:`StiffnessModel.safe_eigenvalues`: absolute values for
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
        self._free_index = free_index(self._free)   # ... and its components

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
        of the whole (:meth:`.MaudCalculator.hessian_rows`: where the
        constraints hold every coordinate of most atoms), or None."""
        if not isinstance(atoms.calc, MaudCalculator):
            return None
        self.basis(atoms, atoms.calc.dim)
        return None if self._held is None else atoms.calc.hessian_rows(atoms, ~self._held)

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
            # a quadratic energy (a net without repulsion, a = 0): its own
            # Hessian, unshifted where definite, whose Newton move is the minimum
            quadratic = isinstance(atoms.calc, MaudCalculator) and atoms.calc.potential.a == 0
            return ((quadratic and _CholeskySolver.of(matrix, basis, free, index, 0.0))
                    or _CholeskySolver.of(matrix, basis, free, index, self.floor)
                    or _EigenSolver(matrix, basis, free, index, self.safe_eigenvalues))
        return _EigenSolver(matrix, basis, free, index, self.safe_eigenvalues)

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
        :attr:`free_index` its components (:func:`free_index`)."""
        key = (len(atoms), dim, [_constraint_key(c) for c in atoms.constraints])
        if self._basis is None or self._basis[0] != key:
            if not atoms.constraints:
                basis = held = None
            elif all(isinstance(c, (FixAtoms, FixCartesian)) for c in atoms.constraints):
                free = free_dofs(atoms, dim)
                basis, held = _selection(free), ~free
            else:
                basis = allowed_basis(atoms, dim)
                held = None if basis is None else _held_coordinates(basis, dim)
            self._basis, self._held = (key, basis), held
            if held is not None:
                self._kept_index = np.flatnonzero(~held)
            self._free = (np.ones((len(atoms), dim), dtype=bool) if self._held is None
                          else ~self._held)
            self._free_index = free_index(self._free)
        return self._basis[1]


def _selection(free: np.ndarray) -> np.ndarray:
    """:func:`allowed_basis` where the constraints hold whole coordinates
    (FixAtoms, FixCartesian): the unit columns (dim N, m) of the ``free``
    (N, dim) coordinates, in order, without its eigen-decompositions."""
    kept = np.flatnonzero(free)
    basis = np.zeros((free.size, kept.size))
    basis[kept, np.arange(kept.size)] = 1.0
    return basis


def _held_coordinates(basis: np.ndarray, dim: int) -> np.ndarray | None:
    """The coordinates (N, dim) an :func:`allowed_basis` holds if its
    columns are coordinates (up to sign), else None."""
    if not ((np.abs(basis).sum(axis=0) == 1).all()
            and (np.count_nonzero(basis, axis=0) == 1).all()):
        return None
    return ~np.abs(basis).sum(axis=1).astype(bool).reshape(-1, dim)


def _constraint_key(constraint: Any) -> tuple:
    """What tells a constraint from another: FixAtoms' and FixCartesian's
    index and mask arrays as bytes (their ``todict``'s lists cost a step's
    work at each call), any other's ``todict``."""
    if isinstance(constraint, (FixAtoms, FixCartesian)):
        arrays = (constraint.index, getattr(constraint, 'mask', None))
        return type(constraint).__name__, *((a.dtype.str, a.shape, a.tobytes())
                                             for a in arrays if a is not None)
    return type(constraint).__name__, repr(constraint.todict())


class _DenseSolver(DofSolver):
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
    shifted.reshape(-1)[::len(matrix) + 1] += shift   # its diagonal, a view (.flat is slower)
    factor, info = dpotrf(shifted, lower=False, clean=False, overwrite_a=True)
    return factor if info == 0 else None


def eigenpairs_of(matrix: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The eigenvalues (ascending) and eigenvectors (columns) of the
    symmetric ``matrix``: LAPACK's syevd on its lower triangle, as numpy's
    eigh calls it (the same digits), without its wrapper; a LinAlgError if
    it did not converge."""
    values, vectors, info = dsyevd(matrix, lower=True)
    if info:
        raise np.linalg.LinAlgError(f'the eigen-decomposition did not converge '
                                    f'(LAPACK syevd info {info})')
    return values, vectors


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
            values, vectors = eigenpairs_of(self.matrix)
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
