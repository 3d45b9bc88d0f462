"""Stiffness models: the ``K`` that the Maud step ``dr = gamma K^-1 f`` divides by.

A model answers one question for the step (:mod:`ase_maud.optimize.strategy`): at
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
- :class:`~ase_maud.optimize.models.near.NearModel` (``'near'``, opt-in, never
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
step rule's defaults for each model are in :data:`ase_maud.optimize.step_rules.STEP_DEFAULTS`.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from typing import Any

import numpy as np
from ase import Atoms

from ase_maud.checks import check
from ase_maud.counting import Work
from ase_maud.physics.dofs import (
    free_dofs,
)

#: The smallest positive float: the floor of eigenvalues made safe to divide by.
TINY = np.finfo(float).tiny


class Solver(ABC):
    """A stiffness ``K`` frozen at one configuration: a local model."""

    @abstractmethod
    def solve(self, forces: np.ndarray) -> np.ndarray:
        """The move ``d`` with ``K d = forces``, shape (N, 3), zero on the
        degrees of freedom FixAtoms and FixCartesian hold and on ``z`` in 2D."""


class DampedSolver(Solver):
    """A local model a trust region can damp (:func:`ase_maud.optimize.step_length.trust_region`):
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
    search (:class:`ase_maud.optimize.strategy.Saddle`)."""

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
        (:func:`ase_maud.optimize.array_loop.relax`, a MaudCalculator's): a model that
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

    def safe_eigenvalues(self, values: np.ndarray) -> np.ndarray:
        """Eigenvalues made safe to divide by: ``|lambda|`` (or signed, for
        ``'stationary'``) floored at ``floor`` times the largest of each row."""
        size = np.abs(values)
        floor = np.maximum(self.floor * size.max(axis=-1, keepdims=True), TINY)
        safe = np.maximum(size, floor)
        if self.target == 'stationary':
            safe = np.where(values < 0, -safe, safe)
        return safe


def free_index(free: np.ndarray) -> np.ndarray:
    """The flat indices into an (N, 3) array of the components a ``free``
    (N, dim) mask frees (taken and put by index: cheaper than the mask on a
    scene of tens of points)."""
    flat = np.flatnonzero(free)
    dim = free.shape[1]
    return flat if dim == 3 else 3 * (flat // dim) + flat % dim


class DofSolver(Solver):
    """Gathers the free components of the forces into a vector, solves, and
    scatters the move back into an (N, 3) array. ``index`` is
    :func:`free_index` of ``free``, given by a caller that keeps it with its
    mask (the exact model, with its constraints), else found here."""

    def __init__(self, free: np.ndarray, index: np.ndarray | None = None):
        self.free = free  # (N, dim) mask
        self.dim = free.shape[1]
        #: The free components' flat indices into an (N, 3) array.
        self.index = free_index(free) if index is None else index
        #: Every component is free: a move's components are its (N, 3) array.
        self.every = self.index.size == 3 * len(free)

    def solve(self, forces: np.ndarray) -> np.ndarray:
        return self._scatter(self._solve(self._gather(forces)))

    def _gather(self, move: np.ndarray) -> np.ndarray:
        """The free components (n,) of a move (N, 3)."""
        flat = np.asarray(move, dtype=float).reshape(-1)
        return flat.copy() if self.every else flat.take(self.index)

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


def held_at_zero(move: np.ndarray, free: np.ndarray | None) -> np.ndarray:
    """``move`` (N, 3) with the components outside ``free`` (N, dim) set to
    zero (``z`` too, for dim 2); unchanged if ``free`` is None (no atoms)."""
    if free is not None:
        move[:, free.shape[1]:] = 0.0
        move[:, :free.shape[1]][~free] = 0.0
    return move


def free_or_none(atoms: Atoms | None) -> np.ndarray | None:
    """The free mask of ``atoms`` (:func:`free_dofs`) in its calculator's
    dimension, or None if there are no atoms to ask (a band of images)."""
    if atoms is None or len(atoms) == 0:
        return None
    return free_dofs(atoms, 2 if getattr(atoms.calc, 'dim', 3) == 2 else 3)
