"""The global model: the springs' exact Hessian plus the repulsion's
nodal blocks, sparse, for the whole scene.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp
from ase import Atoms

from ase_maud.checks import check
from ase_maud.optimize.models.base import Solver, StiffnessModel
from ase_maud.optimize.models.sparse import FactorSolver, MatrixFreeSolver, SparseSolver
from ase_maud.physics.dofs import (
    free_dofs,
)
from ase_maud.physics.neighbours import NearestDistances

#: The global model goes matrix-free when the spring graph holds more than
#: this fraction of all pairs (a factorisation would be dense).
DENSE_GRAPH_FRACTION = 0.25


#: ... and has more free DOFs than this (a small dense LU is cheap).
DENSE_MIN_DOFS = 300


class GlobalModel(StiffnessModel):
    """``P = Q (L (x) I_dim) + blockdiag(|K_mm - Q deg(m) I|)``, sparse.

    Needs a calculator with the nodal blocks (property ``stiffness``) and a
    :class:`~ase_maud.calculator.potential.MaudPotential` (``calc.potential``: the
    constant ``Q (L (x) I_dim)``), as :class:`~ase_maud.MaudCalculator` has.
    The repulsion part of each nodal block is made positive (``'minimum'``)
    block by block.

    ``P`` and its factorisation are kept while no point has moved more than
    ``refresh`` times its nearest-neighbour distance (``nearest``, shared
    with the step bound) since they were built (the springs' part is exact
    everywhere; only the repulsion blocks age): the calculator is then asked
    for energy and forces alone (see :meth:`needs`). ``refresh=0`` rebuilds
    at every step. The test needs no neighbour search while every point's
    move is within ``refresh`` times a lower bound of its distance, the
    distance where ``P`` was built less twice the longest move
    (:func:`_kept_by_bound`). The Maud step with this model takes an L-BFGS correction
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
        #: Where ``P`` was built, its solver, and the nearest-neighbour distances there.
        self._kept: tuple[np.ndarray, SparseSolver, np.ndarray] | None = None

    def needs(self, atoms: Atoms) -> str | None:
        return self.prop if self._stale(atoms) else None

    def _stale(self, atoms: Atoms) -> bool:
        if self._kept is None or len(self._kept[0]) != len(atoms):
            return True
        positions = atoms.positions
        moved = np.linalg.norm(positions - self._kept[0], axis=1)
        if len(positions) < 2 or self.refresh == 0:
            return bool(moved.max() > 0)
        if _kept_by_bound(moved, self._kept[2], self.refresh):
            return False
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
            self._kept = built, self._solver(there), self.nearest(built)
        if self._stale(atoms):
            positions = atoms.positions.copy()
            self._kept = positions, self._solver(atoms), self.nearest(positions)
        learnt['built'] = self._kept[0]
        return self._kept[1]

    def _solver(self, atoms: Atoms) -> SparseSolver:
        matrix, free, diagonal = self.assemble(atoms)
        size = matrix.shape[0]
        if size > DENSE_MIN_DOFS and matrix.nnz > DENSE_GRAPH_FRACTION * size**2:
            return MatrixFreeSolver(matrix, free, diagonal)
        return FactorSolver(matrix, free)

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
                              self.safe_eigenvalues(values), vectors)
        free = free_dofs(atoms, dim)
        keep = np.flatnonzero(free.ravel())
        diagonal = sp.bsr_matrix((repulsion, np.arange(n), np.arange(n + 1)),
                                 shape=(n * dim, n * dim))
        matrix = (springs + diagonal).tocsr()
        return matrix[keep][:, keep], free, repulsion + degree


#: The bound of :func:`_kept_by_bound` is trusted to this relative margin
#: (the neighbour search rounds distances as the bound does not).
BOUND_RTOL = 1e-9


def _kept_by_bound(moved: np.ndarray, built_distances: np.ndarray, refresh: float) -> bool:
    """Whether every point's move ``moved`` (N,) is within ``refresh`` times a
    lower bound of its nearest-neighbour distance now: its distance where
    the model was built, ``built_distances`` (N,), less its own move and the
    longest (the neighbour's), so at most twice the longest. True only where
    the exact test (distances now) keeps the model too."""
    bound = built_distances - 2.0 * moved.max()
    return bool(np.all(moved <= refresh * bound * (1.0 - BOUND_RTOL)))
