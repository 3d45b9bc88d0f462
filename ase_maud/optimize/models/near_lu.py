"""The factorised near-field model (``near-lu``): the near-field ``P`` of
:mod:`ase_maud.optimize.models.near` factorised by SuperLU instead of solved
by truncated CG.

It is not a ``model=`` name of :class:`ase_maud.Maud` (an instance can be
passed as ``model``): it measured no CPU win over the springs model
(docs/dev/benchmarks.md, "repulsion models"), and it is kept as the reference
that ``benchmarks/repulsion_models.py`` (variants ``near-lu``, ``near-lu-<k>``)
and ``dev/repulsion_spectrum.py`` measure ``model='near'`` against.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp
from ase import Atoms
from scipy.sparse.linalg import splu

from ase_maud.optimize.models.base import DofSolver, Solver
from ase_maud.optimize.models.near import near_pairs
from ase_maud.optimize.models.springs import SpringsModel, _floating
from ase_maud.physics import pair_law as physics
from ase_maud.physics.dofs import free_dofs, rigid_body_modes

__all__ = ['NEAR_RETRY_MAX', 'NearLUModel', 'NearLUSolver']

#: The most steps the near-field model waits before it tries ``P`` again.
NEAR_RETRY_MAX = 4


class NearLUModel(SpringsModel):
    """The springs' Hessian plus the repulsion's pair blocks, signed as they
    are, of the sprung pairs and of the pairs nearer than ``cutoff`` times
    the median nearest-neighbour distance: ``P = Q (L (x) I_dim) + sum_p
    (e_i - e_j)(e_i - e_j)^T (x) Q B(r_i - r_j)``
    (:func:`ase_maud.physics.pair_law.repulsion_block`):
    the Hessian without the far field's couplings, one sparse (dim N, dim N)
    matrix factorised by SuperLU. Near a minimum it holds what the springs
    model misses where the repulsion dominates: a spring under tension
    across its repulsion is soft sideways (the blocks' ``-I / L**3``), which
    ``Q L`` takes as stiff. Far from one ``P`` is indefinite; the factor's
    pivots tell (no pivoting across the diagonal, so their signs are
    ``P``'s inertia) and the springs model steps instead, trying ``P`` again
    after 1, 2, 4 ... (at most :data:`NEAR_RETRY_MAX`) steps. A factor is
    kept for ``reuse`` steps. Points of a spring component that holds no
    fixed point get ``floor`` times the largest diagonal entry (their
    translations), and the move is projected off the rigid motions (``P``,
    short of the far field, is not invariant under rotations). Only
    ``target='minimum'`` uses ``P``; the step rule is the springs model's."""

    name = 'near-lu'

    def __init__(self, target: str = 'minimum', floor: float | None = None,
                 cutoff: float = 1.5, reuse: int = 1):
        super().__init__(target, floor)
        self.cutoff, self.reuse = float(cutoff), int(reuse)
        self._wait, self._waited = 0, 0
        self._near_kept: tuple[Solver, Solver, int] | None = None
        #: Factorisations tried, and those found positive definite.
        self.tried = self.definite = 0

    def at(self, atoms: Atoms, learnt: dict[str, Any] | None = None) -> Solver:
        springs = super().at(atoms, learnt)
        if self.target != 'minimum':
            return springs
        kept = self._near_kept
        if kept is not None and kept[1] is springs and kept[2] < self.reuse:
            self._near_kept = kept[0], springs, kept[2] + 1
            return kept[0]
        self._near_kept = None
        if self._waited < self._wait:
            self._waited += 1
            return springs
        near = self.factor(atoms)
        if near is None:
            self._wait, self._waited = min(NEAR_RETRY_MAX, max(1, 2 * self._wait)), 0
            return springs
        self._wait = self._waited = 0
        self._near_kept = near, springs, 1
        return near

    def matrix(self, atoms: Atoms) -> sp.csc_matrix:
        """``P`` at ``atoms``' positions on the free degrees of freedom (in the
        order of :func:`free_dofs`' mask, point by point), force per length."""
        potential = atoms.calc.potential
        n, dim = len(atoms), potential.dim
        x = potential.reduced(atoms.positions)[:, :dim]
        i, j = near_pairs(x, potential.springs, self.cutoff)
        blocks = potential.Q * physics.repulsion_block(x[i] - x[j])
        matrix = potential.spring_hessian(n) + physics.pair_block_laplacian(i, j, blocks, n)
        free = free_dofs(atoms, dim)
        keep = np.flatnonzero(free.ravel())
        largest = np.abs(matrix.diagonal()).max(initial=0.0)
        floating = np.column_stack([_floating(potential.springs, ~column) for column in free.T])
        return sp.csc_matrix(matrix[keep][:, keep]
                             + sp.diags(self.floor * largest * floating.ravel()[keep]))

    def factor(self, atoms: Atoms) -> Solver | None:
        """``P`` factorised at ``atoms``' positions, None if it is not
        positive definite."""
        self.tried += 1
        lu = splu(self.matrix(atoms), permc_spec='MMD_AT_PLUS_A', diag_pivot_thresh=0.0,
                  options={'SymmetricMode': True})
        if not (np.array_equal(lu.perm_r, lu.perm_c) and (lu.U.diagonal() > 0).all()):
            return None
        self.definite += 1
        free = free_dofs(atoms, atoms.calc.potential.dim)
        return NearLUSolver(lu.solve, free, rigid_body_modes(atoms.positions, free, free.shape[1]))


class NearLUSolver(DofSolver):
    """The free part of the near-field ``P`` inverted by its factor, the
    move projected off the ``rigid`` motions (orthonormal columns on the free
    degrees of freedom)."""

    def __init__(self, inverse: Any, free: np.ndarray, rigid: np.ndarray):
        super().__init__(free)
        self.inverse, self.rigid = inverse, rigid

    def _solve(self, rhs):
        move = self.inverse(rhs)
        return move - self.rigid @ (self.rigid.T @ move)
