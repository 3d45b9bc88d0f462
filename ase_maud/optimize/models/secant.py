"""The secant models: ``K = kappa I`` from the last step's curvature
(:class:`SecantModel`), and a BFGS memory over it (:class:`BFGSModel`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from ase import Atoms

from ase_maud.checks import check
from ase_maud.optimize.models.base import Solver, StiffnessModel, free_or_none, held_at_zero


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
        return _ScaledSolver(float(kappa), free_or_none(atoms))

    def observe(self, step: np.ndarray, force_drop: np.ndarray,
                learnt: dict[str, Any]) -> dict[str, Any]:
        sy, ss = np.vdot(step, force_drop), np.vdot(step, step)
        return {**learnt, 'kappa': sy / ss} if sy > 0 and ss > 0 else learnt


class BFGSModel(SecantModel):
    """BFGS's inverse Hessian, learnt from the forces, for calculators that
    give no stiffness (``'bfgs'``): ``K^-1`` is ``I / kappa`` corrected by
    the step rule's L-BFGS memory, whose defaults
    (:data:`ase_maud.optimize.step_rules.STEP_DEFAULTS`) keep the pairs of the last
    100 accepted steps and no momentum: for a run of fewer steps, or a scene
    of fewer coordinates, that is the BFGS update of ``I / kappa`` by every
    step. ``kappa`` starts at ``kappa0`` (ASE's 70 eV/A**2) and is then the
    geometric mean ``|y| / |s|`` of the two secant (Barzilai-Borwein)
    curvatures ``s.y / s.s`` and ``y.y / s.y`` of the last step with ``s.y
    > 0`` (the smaller one alone, the model's first form, took up to 1.7x
    BFGS's calls on Lennard-Jones clusters: docs/dev/benchmarks.md). Its
    history is the run's state (the pairs of
    :class:`~ase_maud.optimize.state.MaudState`, in the restart file)."""

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
        return held_at_zero(np.asarray(forces, dtype=float).reshape(-1, 3)
                             / self.kappa, self.free)
