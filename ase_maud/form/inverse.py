"""Inverse form finding: the force densities that make the ``a = 0`` net
meet a target, by the adjoint of the force-density solve and SciPy's
L-BFGS-B (bounds on ``q``), as jax_fdm does by automatic differentiation.

The forward solve (:mod:`ase_maud.form.force_density`) is, with ``C`` the
members' incidence matrix (``+1`` at ``i``, ``-1`` at ``j`` of member
``s = (i, j)``) split into its free and supported columns ``C_f``, ``C_s``::

    A(q) X_f = P_f / Q - C_f^T diag(q) C_s X_s,   A(q) = C_f^T diag(q) C_f,

so that ``R(X_f, q) = C_f^T diag(q) U - P_f / Q = 0``, ``U = C X`` the
members' vectors. For a loss ``J(X, q)``, the adjoint ``A Lambda = dJ/dX_f``
(``A`` is symmetric: the forward factors serve it, one more solve) gives::

    dJ/dq_s = partial J / partial q_s - (Lambda_i - Lambda_j) . u_s

(``Lambda`` zero at the supports). One evaluation of the loss and its
gradient costs one factorisation and two solves with it: the count of
forward solves is the count of evaluations.

Targets (each term divided by a scale so that the loss is dimensionless):

- ``heights``: ``{point: z}``; ``1/2 sum (z_i - z*_i)**2 / d**2``, ``d`` the
  diagonal of the starting net's bounding box; met when every ``|z_i -
  z*_i| <= tol d``.
- ``forces``: ``(low, high)`` bounds on each member's force ``Q q_s L_s``
  (numbers, or (K,) arrays; ``None`` for no bound on a side); ``1/2 sum
  v_s**2 / f**2`` with ``v_s`` how far force ``s`` lies outside, ``f`` the
  largest finite bound's size; met when every ``v_s <= tol f``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from ase import Atoms
from scipy.optimize import minimize

from ase_maud.form.force_density import free_factors, supported_net

__all__ = ['InverseResult', 'ForceDensityProblem', 'find_force_densities']


@dataclass(frozen=True)
class InverseResult:
    """What :func:`find_force_densities` found.

    Attributes
    ----------
    q : (K,) the force density multipliers found (of ``Q``).
    positions : (N, 3) the net's ``a = 0`` equilibrium with them.
    met : whether every target is met within ``tol``.
    forward_solves : force-density solves made (one per evaluation).
    height_error : the largest ``|z - z*|`` at the target points, over the
        diagonal (0 without height targets).
    force_excess : the largest amount by which a member force lies outside
        its bounds, over the bounds' scale (0 without force bounds).
    message : L-BFGS-B's message, or why the search stopped.
    """

    q: np.ndarray
    positions: np.ndarray
    met: bool
    forward_solves: int
    height_error: float
    force_excess: float
    message: str


class _Met(Exception):
    """Raised inside the loss when the targets are met: the search stops."""


class ForceDensityProblem:
    """The ``a = 0`` equilibrium of the net ``atoms`` as a function of its
    force densities ``q``, and a target loss with its adjoint gradient
    (module docstring). ``atoms`` is read, never changed."""

    def __init__(self, atoms: Atoms, heights: dict[int, float] | None = None,
                 forces: tuple | None = None):
        potential, held = supported_net(atoms, 'inverse form finding')
        if not heights and forces is None:
            raise ValueError('give a target: heights={point: z} and/or forces=(low, high)')
        natoms = len(atoms)
        self.springs, self.Q, self.dim = potential.springs, potential.Q, potential.dim
        self.free, self.fixed = np.flatnonzero(~held), np.flatnonzero(held)
        count = len(self.springs)
        rows = np.repeat(np.arange(count), 2)
        incidence = sp.csr_matrix((np.tile([1.0, -1.0], count), (rows, self.springs.ravel())),
                                  shape=(count, natoms))
        self.c_free = incidence[:, self.free].tocsc()
        self.c_fixed = incidence[:, self.fixed].tocsc()
        self.start = atoms.get_positions()
        loads = np.zeros((natoms, 3)) if potential.loads is None else potential.loads
        self.loads_free = loads[self.free] / self.Q
        self.diagonal = float(np.linalg.norm(np.ptp(self.start, axis=0))) or 1.0
        self._heights(heights or {}, natoms)
        self._forces(forces, count)
        self.solves = 0

    def _heights(self, heights, natoms):
        points = np.array(sorted(heights), dtype=int)
        if len(points) and (points.min() < 0 or points.max() >= natoms):
            wrong = points.min() if points.min() < 0 else points.max()
            raise ValueError(f'heights names point {wrong}: the net has points 0 to '
                             f'{natoms - 1}')
        if len(points) and self.dim == 2:
            raise ValueError('heights are targets of a 3D net; this one is dim=2 (flat)')
        self.height_points = points
        self.height_targets = np.array([float(heights[p]) for p in points])
        slot = np.full(natoms, -1)
        slot[self.free] = np.arange(len(self.free))
        self.height_slots = slot[points]   # -1: a support (its height is what it is)

    def _forces(self, forces, count):
        if forces is None:
            self.low = self.high = None
            self.force_scale = 1.0
            return
        low, high = forces
        self.low = None if low is None else np.broadcast_to(np.asarray(low, float), (count,))
        self.high = None if high is None else np.broadcast_to(np.asarray(high, float), (count,))
        bounds = [np.abs(b).max() for b in (self.low, self.high) if b is not None and len(b)]
        self.force_scale = float(max(bounds, default=1.0)) or 1.0

    def positions(self, q: np.ndarray, factors=None) -> np.ndarray:
        """The net's ``a = 0`` equilibrium (N, 3) with force densities ``q``."""
        q = np.asarray(q, dtype=float)
        factors = factors or self._factors(q)
        x = self.start.copy()
        right = (self.loads_free
                 - self.c_free.T @ (q[:, None] * (self.c_fixed @ x[self.fixed])))
        x[self.free, :self.dim] = factors.solve(np.ascontiguousarray(right[:, :self.dim]))
        return x

    def _factors(self, q):
        self.solves += 1
        matrix = self.c_free.T @ sp.diags(q) @ self.c_free
        return free_factors(matrix, bool((q < 0).any()))

    def errors(self, x: np.ndarray, q: np.ndarray) -> tuple[float, float]:
        """The largest height error (over the diagonal) and force excess
        (over the force scale) of the form ``x`` with ``q``."""
        height = (np.abs(x[self.height_points, 2] - self.height_targets).max() / self.diagonal
                  if len(self.height_points) else 0.0)
        excess = self._excess(x, q)
        return float(height), float(np.abs(excess).max(initial=0.0) / self.force_scale)

    def _excess(self, x, q):
        """Each member force's distance outside its bounds (signed: + above)."""
        if self.low is None and self.high is None:
            return np.zeros(0)
        lengths = np.linalg.norm(x[self.springs[:, 0]] - x[self.springs[:, 1]], axis=1)
        force = self.Q * q * lengths
        excess = np.zeros_like(force)
        if self.high is not None:
            excess += np.maximum(force - self.high, 0.0)
        if self.low is not None:
            excess -= np.maximum(self.low - force, 0.0)
        return excess

    def loss_and_gradient(self, q: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
        """The loss at ``q``, its gradient (K,) by the adjoint, and the form."""
        q = np.asarray(q, dtype=float)
        factors = self._factors(q)
        x = self.positions(q, factors)
        u = x[self.springs[:, 0]] - x[self.springs[:, 1]]
        grad_x = np.zeros((len(x), 3))
        grad_q = np.zeros(len(q))
        loss = 0.0
        if len(self.height_points):
            miss = (x[self.height_points, 2] - self.height_targets) / self.diagonal
            loss += 0.5 * float(miss @ miss)
            np.add.at(grad_x[:, 2], self.height_points, miss / self.diagonal)
        excess = self._excess(x, q)
        if len(excess):
            lengths = np.linalg.norm(u, axis=1)
            scaled = excess / self.force_scale
            loss += 0.5 * float(scaled @ scaled)
            weight = scaled / self.force_scale * self.Q   # dJ/dforce_s times Q
            grad_q += weight * lengths
            with np.errstate(invalid='ignore', divide='ignore'):
                pull = np.where(lengths[:, None] > 0, u / lengths[:, None], 0.0)
            pull *= (weight * q)[:, None]
            np.add.at(grad_x, self.springs[:, 0], pull)
            np.add.at(grad_x, self.springs[:, 1], -pull)
        adjoint = np.zeros((len(x), 3))
        adjoint[self.free, :self.dim] = factors.solve(
            np.ascontiguousarray(grad_x[self.free, :self.dim]))
        grad_q -= np.einsum('kd,kd->k', adjoint[self.springs[:, 0]]
                            - adjoint[self.springs[:, 1]], u)
        return loss, grad_q, x


def find_force_densities(atoms: Atoms, heights: dict[int, float] | None = None,
                         forces: tuple | None = None, bounds: tuple = (0.01, 100.0),
                         q0: np.ndarray | None = None, tol: float = 1e-6,
                         max_solves: int = 200) -> InverseResult:
    """Force densities for which the ``a = 0`` net ``atoms`` meets the
    targets, found by L-BFGS-B on the adjoint gradient (module docstring).

    Parameters
    ----------
    atoms : Atoms
        A net with a MaudCalculator and supports that hold it (the
        force-density equilibrium is unique); set on return to the best form
        found: its calculator's ``q`` and its positions (``a`` untouched).
    heights : dict of int to float, optional
        Target heights ``z`` (length units) of chosen points.
    forces : tuple, optional
        ``(low, high)`` bounds on each member's force ``Q q L`` (``Q a``),
        numbers or (K,) arrays, None for no bound on a side.
    bounds : tuple, default (0.01, 100.0)
        ``(low, high)`` on each ``q`` (multiples of ``Q``), numbers or (K,)
        arrays, on one side of 0 (negative: members in compression).
    q0 : ndarray of shape (K,), optional
        The start (default: the calculator's ``q`` with the bounds' sign,
        clipped into them).
    tol : float, default 1e-6
        A target is met within ``tol`` of its scale (the diagonal for
        heights, the largest bound for forces).
    max_solves : int, default 200
        Forward solves (one per evaluation of the loss and its gradient).

    Returns
    -------
    InverseResult
        ``q``, the positions, whether every target is met, the solves made
        and the remaining errors.

    Raises
    ------
    ValueError
        No target, a height of a point the net lacks or of a flat net,
        bounds that straddle 0, or supports that leave the equilibrium
        non-unique (each named).
    """
    problem = ForceDensityProblem(atoms, heights, forces)
    count = len(problem.springs)
    low, high = (np.broadcast_to(np.asarray(b, float), (count,)) for b in bounds)
    if (low > high).any() or ((low <= 0) & (high >= 0)).any():
        raise ValueError('bounds must be (low, high) with low <= high on one side of 0 '
                         '(q = 0 is no member; negative: compression)')
    if q0 is None:   # the calculator's, with the bounds' sign (a shell's q are negative)
        q0 = np.sign(low) * np.abs(atoms.calc.potential.stiffnesses)
    q0 = np.clip(np.broadcast_to(np.asarray(q0, float), (count,)), low, high)
    best: dict = {}

    def fun(q):
        loss, grad, x = problem.loss_and_gradient(q)
        height, excess = problem.errors(x, q)
        if not best or loss < best['loss']:
            best.update(loss=loss, q=np.array(q), x=x, height=height, excess=excess)
        if max(height, excess) <= tol:
            raise _Met
        return loss, grad

    try:
        answer = minimize(fun, q0, jac=True, method='L-BFGS-B',
                          bounds=list(zip(low, high, strict=True)),
                          options={'maxfun': max_solves, 'maxiter': max_solves,
                                   'ftol': 0.0, 'gtol': 0.0, 'maxcor': 20})
        message = str(answer.message)
    except _Met:
        message = f'every target met within {tol:g}'
    met = max(best['height'], best['excess']) <= tol
    atoms.calc.set(q=best['q'])
    atoms.set_positions(best['x'], apply_constraint=False)
    return InverseResult(q=best['q'], positions=best['x'], met=met,
                         forward_solves=problem.solves, height_error=best['height'],
                         force_excess=best['excess'], message=message)
