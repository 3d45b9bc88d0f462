"""The specification's nodal model: each point's block ``K_mm`` with every
other point held (tensor step ``K_mm^-1 f_m``, scalar ``f_m / Tr K_mm``).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from ase import Atoms

from ase_maud.checks import check
from ase_maud.optimize.models.base import TINY, Solver, StiffnessModel, held_at_zero
from ase_maud.physics.dofs import (
    free_dofs,
)


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
        return _BlockSolver(vectors, self.safe_eigenvalues(values), free)


class _TraceSolver(Solver):
    """``d_m = f_m / Tr K_mm``."""

    def __init__(self, trace: np.ndarray, free: np.ndarray):
        self.trace, self.free = trace, free  # (N,), (N, dim)

    def solve(self, forces):
        move = np.asarray(forces, dtype=float).reshape(-1, 3) / self.trace[:, None]
        return held_at_zero(move, self.free)


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
        return held_at_zero(move, self.free)
