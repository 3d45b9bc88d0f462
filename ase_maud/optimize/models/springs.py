"""The springs model: the springs' exact, constant Hessian ``Q L``,
factorised once per run; the lowest modes by LOBPCG for saddles.
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np
import scipy.linalg
import scipy.sparse as sp
from ase import Atoms
from scipy.sparse.linalg import LinearOperator, lobpcg

from ase_maud.analysis.stationary import hessian_operator
from ase_maud.counting import Work
from ase_maud.optimize.models.base import ModeSolver, Solver, StiffnessModel
from ase_maud.optimize.models.sparse import spd_inverse
from ase_maud.physics import pair_law as physics
from ase_maud.physics.dofs import (
    free_dofs,
    rigid_body_modes,
)
from ase_maud.physics.neighbours import NearestDistances
from ase_maud.physics.topology import spring_components

#: Relative residual of the multigrid solves of the springs model, whose
#: solution only starts the L-BFGS recursion.
SPRINGS_RTOL = 1e-6


class SpringsModel(StiffnessModel):
    """``P = Q L + diag(s)`` for each coordinate: the springs' exact, constant
    Hessian ``Q (L (x) I_dim)`` is block diagonal by coordinate, so one N x N
    matrix (``L`` the spring graph's Laplacian weighted by the force densities
    ``q``, from the calculator's
    :class:`~ase_maud.calculator.potential.MaudPotential`) serves every coordinate,
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
    the step rule (:data:`ase_maud.optimize.step_rules.STEP_DEFAULTS`).
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
    :func:`ase_maud.analysis.stationary.hessian_operator`, rigid-body motions projected
    out) and its lowest eigenpairs (:meth:`eigenpairs`, LOBPCG preconditioned
    by ``P^-1``; a dense eigen-decomposition of the products where the
    scene is too small for LOBPCG): what a large saddle search follows
    (:class:`ase_maud.optimize.strategy.Saddle`). Every vector it multiplies by the
    Hessian is counted in ``work``."""

    def __init__(self, inner: Solver, atoms: Atoms, free: np.ndarray, work: Work):
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
