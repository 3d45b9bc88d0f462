"""The Maud step rule, apart from ASE's plumbing (cf. ASE's ``LBFGSMethod``).

One step from positions ``x`` (N, 3) with forces ``f`` (ASE sign) and a
stiffness solver ``K^-1`` (:mod:`ase_maud.stiffness`)::

    d = K^-1 f                       (with memory > 0: L-BFGS over K^-1)
    v <- beta v + gamma d;  x <- x + bound(v)

- ``memory`` > 0: the direction is the L-BFGS two-loop recursion with
  ``K^-1`` as its initial inverse Hessian, over the secant pairs
  ``s = x_new - x_old``, ``y = f_old - f_new`` of the last ``memory``
  accepted steps (pairs with ``s.y <= 0`` are skipped, so the recursion stays
  positive definite).
- Momentum (Day's dynamic relaxation): the previous move is carried over with
  the weight ``beta_k = min(k / (k + 3), beta_max)`` (Nesterov's schedule,
  ``k`` steps since the last restart); ``beta_max = 0`` switches it off. With
  momentum on, a move ``v`` that points against the new direction
  (``v . d < 0``: an overshoot) is dropped and gamma shrinks by
  ``overshoot_shrink`` (a kinetic-damping restart, as in FIRE and Barnes's form
  finding).
- A step that raised the merit (the energy for ``target='minimum'``,
  ``|f|**2`` for ``'stationary'``) is taken back at no extra calculator call:
  the rule returns to where the step began (whose forces and solver it kept),
  halves gamma and drops the momentum. Gamma grows by ``gamma_growth`` after
  each accepted step, up to ``gamma_max``. Energies that agree within their
  error (rounding, or an approximate calculator's tolerance: :attr:`noise`)
  are told apart by the trapezoid estimate ``-(f_old + f) . dx / 2``, which
  needs forces only.
- No point moves further in one step than ``maxstep_nn`` (< 1/2) times its
  distance to its nearest other point, nor than ``maxstep`` if given (length
  units): two points stepping towards each other keep at least
  ``1 - 2 maxstep_nn`` of their distance. For a chain of images (ASE's NEB)
  the nearest point is sought within each image (``image_size``). Each point's move is scaled down
  on its own; or (``trust_region``, for a model that can damp itself, the
  exact one) the move becomes ``gamma (K + mu I)^-1 f`` with the smallest
  ``mu >= 0`` that keeps every point within its bound (Levenberg-Marquardt):
  far from a minimum this turns the step towards the forces instead of
  shortening the Newton step as a whole.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from .stiffness import Solver, StiffnessModel


@dataclass
class StepRule:
    """The step rule's settings (keywords of :class:`ase_maud.Maud`)."""

    target: str = 'minimum'
    gamma: float = 1.0
    gamma_max: float = 1.5
    gamma_growth: float = 1.1
    overshoot_shrink: float = 0.6
    beta_max: float = 0.98
    memory: int = 0
    maxstep_nn: float = 0.45
    maxstep: float | None = None
    trust_region: bool = False
    #: Points per image when the positions are a chain of images (ASE's NEB):
    #: the nearest other point is sought within the same image only (the same
    #: atom in the next image is not a neighbour). None: one scene.
    image_size: int | None = None


@dataclass
class _Point:
    """Where a step began: positions, merit, forces, the solver there (None
    after a restart from file: recomputed if needed) and the merit's
    relative error (the calculator's tolerance when it was computed)."""

    x: np.ndarray
    merit: float
    forces: np.ndarray
    solver: Solver | None = None
    noise: float = 0.0


@dataclass
class MaudMethod:
    """The step rule's numerics and state; see the module docstring.

    The optimizer calls, per step: :meth:`uphill` (was the last step a
    rise?), then either :meth:`revert` or :meth:`accept`, then :meth:`move`,
    and :meth:`moved` with the positions the constraints allowed.
    """

    model: StiffnessModel
    rule: StepRule
    gamma: float = field(init=False)
    v: np.ndarray | None = field(init=False, default=None)
    k: int = field(init=False, default=0)
    last: _Point | None = field(init=False, default=None)
    pairs: list[tuple[np.ndarray, np.ndarray]] = field(init=False, default_factory=list)
    #: Relative error of the merit just computed (1e-12: rounding; an
    #: approximate calculator's tolerance, set by the optimizer); the larger
    #: of it and :attr:`last`'s counts when the two are compared.
    noise: float = field(init=False, default=1e-12)

    def __post_init__(self):
        self.gamma = self.rule.gamma

    # -- the step --------------------------------------------------------------

    def uphill(self, x: np.ndarray, merit: float, forces: np.ndarray) -> bool:
        """Whether the step from :attr:`last` to ``x`` raised the merit."""
        last = self.last
        if last is None:
            return False
        change = merit - last.merit
        tol = merit_tolerance(last.merit, max(self.noise, last.noise))
        if self.rule.target != 'minimum' or abs(change) > tol:
            return change > tol
        return -0.5 * np.vdot(last.forces + forces, x - last.x) > 0

    def revert(self) -> _Point:
        """Go back to where the last step began, with half the gamma."""
        self.gamma *= 0.5
        self.v = None
        self.k = 0
        return self.last

    def accept(self, x: np.ndarray, forces: np.ndarray) -> None:
        """Learn from the accepted step that ended at ``x``."""
        if self.last is None:
            return
        s, y = x - self.last.x, self.last.forces - forces
        self.model.observe(s, y)
        if self.rule.memory and np.vdot(s, y) > 1e-12 * np.vdot(s, s) ** 0.5 * (
                np.vdot(y, y) ** 0.5):
            self.pairs = [*self.pairs, (s, y)][-self.rule.memory:]
        self.gamma = min(self.gamma * self.rule.gamma_growth, self.rule.gamma_max)

    def move(self, here: _Point) -> np.ndarray:
        """The bounded move from ``here``; ``here`` becomes :attr:`last`."""
        direction = self._direction(here)
        limit = self._limits(here.x)
        if self.rule.trust_region and hasattr(here.solver, 'shifted_solve'):
            direction = self._trust_region(here, direction, limit)
        if (self.rule.beta_max > 0 and self.v is not None
                and np.vdot(self.v, direction) < 0):
            self.gamma *= self.rule.overshoot_shrink  # overshoot: restart
            self.v = None
            self.k = 0
        direction *= self.gamma
        if self.v is not None and self.rule.beta_max > 0:
            direction += min(self.k / (self.k + 3.0), self.rule.beta_max) * self.v
        self.k += 1
        self.last = here
        return self._bound(direction, limit)

    def moved(self, x_new: np.ndarray) -> None:
        """Record the move the constraints allowed, from :attr:`last`."""
        self.v = x_new - self.last.x

    def _direction(self, here: _Point) -> np.ndarray:
        """``K^-1 f``, or its L-BFGS correction over the stored pairs."""
        solve = here.solver.solve
        if not self.pairs:
            return solve(here.forces)
        q = here.forces.copy()
        alphas = []
        for s, y in reversed(self.pairs):
            alpha = np.vdot(s, q) / np.vdot(s, y)
            q -= alpha * y
            alphas.append(alpha)
        z = solve(q)
        for (s, y), alpha in zip(self.pairs, reversed(alphas), strict=True):
            z += s * (alpha - np.vdot(y, z) / np.vdot(s, y))
        return z

    def _limits(self, x: np.ndarray) -> np.ndarray:
        """The longest move allowed to each point (length units)."""
        size = self.rule.image_size or len(x)
        limit = np.full(len(x), np.inf)
        if size > 1:
            limit = self.rule.maxstep_nn * np.concatenate(
                [cKDTree(image).query(image, k=2)[0][:, 1]
                 for image in x.reshape(-1, size, x.shape[1])])
        if self.rule.maxstep is not None:
            limit = np.minimum(limit, self.rule.maxstep)
        return limit

    def _trust_region(self, here: _Point, direction: np.ndarray,
                      limit: np.ndarray) -> np.ndarray:
        """``K^-1 f`` damped to ``(K + mu I)^-1 f`` with the smallest ``mu``
        (to 1 %, by bisection in log mu) at which ``gamma`` times it keeps
        every point within ``limit``."""
        solver, forces = here.solver, here.forces

        def outside(mu):
            move = solver.shifted_solve(forces, [mu])[0]
            return (self.gamma * np.linalg.norm(move, axis=1) / limit).max() > 1

        if (self.gamma * np.linalg.norm(direction, axis=1) / limit).max() <= 1:
            return direction
        low, high = 0.0, np.abs(solver.values).max()
        while outside(high):
            low, high = high, 10.0 * high
        while high > 1.01 * max(low, high / 1e12):
            middle = np.sqrt(max(low, high / 1e12) * high)
            if outside(middle):
                low = middle
            else:
                high = middle
        return solver.shifted_solve(forces, [high])[0]

    def _bound(self, step: np.ndarray, limit: np.ndarray) -> np.ndarray:
        """Scale each point's move down to its allowed length."""
        length = np.linalg.norm(step, axis=1)
        scale = np.divide(limit, length, out=np.ones_like(length),
                          where=length > limit)
        return step * scale[:, None]

    # -- restart files -----------------------------------------------------------

    def state(self) -> dict[str, Any]:
        """What a restart file holds (the solver is recomputed on demand)."""
        last = None if self.last is None else {
            'x': self.last.x, 'merit': self.last.merit, 'forces': self.last.forces,
            'noise': self.last.noise}
        return {'gamma': self.gamma, 'k': self.k, 'v': self.v, 'last': last,
                'pairs': [list(pair) for pair in self.pairs],
                'model': self.model.state()}

    def load(self, state: dict[str, Any]) -> None:
        """Take the state :meth:`state` wrote."""
        self.gamma, self.k = float(state['gamma']), int(state['k'])
        self.v = None if state['v'] is None else np.asarray(state['v'], float)
        last = state['last']
        self.last = None if last is None else _Point(
            np.asarray(last['x'], float), float(last['merit']),
            np.asarray(last['forces'], float), noise=float(last['noise']))
        self.pairs = [(np.asarray(s, float), np.asarray(y, float))
                      for s, y in state['pairs']]
        self.model.load(state['model'])


def merit_tolerance(merit: float, noise: float = 1e-12) -> float:
    """Slack when comparing merits: ``noise`` (relative; 1e-12 is the
    rounding of energies that sum N**2 terms) times ``|merit|``."""
    return max(noise, 1e-12) * max(abs(merit), 1e-300)
