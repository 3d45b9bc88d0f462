"""Sparse symmetric positive-definite solves shared by the global and
springs models: LU, algebraic multigrid, or matrix-free CG.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import LinearOperator, cg, splu

from ase_maud.optimize.models.base import DofSolver

#: Sparse symmetric positive-definite matrices of this many rows or more are
#: solved by algebraic multigrid, smaller ones are factorised
#: (:func:`spd_inverse`; docs/dev/benchmarks.md has the measurement).
AMG_MIN_DOFS = 200_000


#: Relative residual of the iterative solves (CG, multigrid).
SOLVE_RTOL = 1e-10


class SparseSolver(DofSolver):
    """A solver that also holds ``P`` on the free DOFs (:attr:`matrix`)."""

    def __init__(self, matrix: sp.csr_matrix, free: np.ndarray):
        super().__init__(free)
        self.matrix = matrix

    def dot(self, move: np.ndarray) -> np.ndarray:
        """``P move`` (N, 3), force per length, zero on held coordinates."""
        return self._scatter(self.matrix @ self._gather(move))


class FactorSolver(SparseSolver):
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
    import pyamg  # here: multigrid only for the largest factors
    hierarchy = pyamg.smoothed_aggregation_solver(sp.csr_matrix(matrix))

    def solve(rhs):
        if rhs.ndim == 1:
            return hierarchy.solve(rhs, tol=rtol, accel='cg', maxiter=200)
        return np.column_stack([solve(column) for column in rhs.T])
    return solve


class MatrixFreeSolver(SparseSolver):
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
