"""The Maud step rule, apart from ASE's plumbing (cf. ASE's ``LBFGSMethod``).

One step from positions ``x`` (N, 3) with forces ``f`` (ASE sign) and a
stiffness solver ``K^-1`` (:mod:`ase_maud.stiffness`)::

    d = K^-1 f                       (with memory > 0: L-BFGS over K^-1)
    v <- beta v + gamma d;  x <- x + bound(v)

- ``memory`` > 0: the direction is the L-BFGS two-loop recursion with
  ``K^-1`` as its initial inverse Hessian, over the secant pairs
  ``s = x_new - x_old``, ``y = f_old - f_new`` of the last ``memory``
  accepted steps. A pair is kept only if its curvature is clearly positive,
  ``s.y > MIN_PAIR_COSINE |s| |y|``, so that a nearly degenerate pair cannot
  blow the recursion up; a direction that is not downhill all the same is
  replaced by ``K^-1 f`` and the memory is cleared.
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
  cuts gamma and drops the momentum. Gamma is halved, or, with
  ``interpolate``, set to the minimum of the cubic through both ends' merits
  and slopes (clipped to [0.1, 0.5] of itself, as a line search does). Gamma
  grows by ``gamma_growth`` after each accepted step, up to ``gamma_max``.
  Energies that agree within their error (rounding, or an approximate
  calculator's tolerance: ``noise``) are told apart by the trapezoid estimate
  ``-(f_old + f) . dx / 2``, which needs forces only.
- No point moves further in one step than ``maxstep_nn`` (< 1/2) times its
  distance to its nearest other point (None: no such bound), nor than
  ``maxstep`` if given (length units): two points stepping towards each other
  keep at least ``1 - 2 maxstep_nn`` of their distance. For a chain of images
  (ASE's NEB) the nearest point is sought within each image
  (``image_size``). Each point's move is scaled down on its own; or
  (``trust_region``, for a model that can damp itself, the exact one) the
  move is taken along the dogleg path from the Cauchy point to the Newton
  move (a definite model with ``dot``), or becomes ``gamma (K + mu I)^-1 f``
  with the smallest ``mu >= 0`` that keeps every point within its bound
  (Levenberg-Marquardt, a model with ``shifted_solve``): far from a minimum
  this turns the step towards the forces instead of shortening the Newton
  step as a whole. With ``bound='whole'`` the whole move is scaled
  by one factor instead, so that a descent direction stays one; and
  ``maxstep_size`` bounds every point's move by that fraction of the scene's
  size (the largest distance from the centroid), a bound that needs no
  neighbour search.

The state of a run is a :class:`MaudState` (what a restart file holds); the
settings are a frozen :class:`StepRule`, made by :func:`step_rule` from the
defaults of :data:`STEP_DEFAULTS`, the model's row, and the user's keywords.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .neighbours import NearestDistances
from .stiffness import Solver, StiffnessModel

#: The step rule's defaults: ``'common'`` for every model, then each model's
#: own (by :attr:`StiffnessModel.name`; a model not listed takes
#: ``'nodal'``'s), chosen by measurement (docs/optimizer.md). The Newton-like
#: models take gamma = 1 with no momentum: the exact one with no memory and a
#: trust-region bound; the global and springs ones with an L-BFGS memory over
#: their ``P`` and the whole move scaled by one factor (the springs one by the
#: scene's size only, gamma back to 1 after every accepted step and a cubic
#: cut on a rise, as a line search). The nodal and secant models keep Day's
#: momentum, as the specification has it.
STEP_DEFAULTS: dict[str, dict[str, Any]] = {
    'common': {'gamma': 1.0, 'gamma_growth': 1.1, 'overshoot_shrink': 0.6,
               'maxstep_nn': 0.45, 'maxstep': None, 'maxstep_size': None,
               'trust_region': False, 'interpolate': False, 'bound': 'each'},
    'exact': {'gamma_max': 1.0, 'beta_max': 0.0, 'memory': 0, 'trust_region': True},
    'global': {'gamma_max': 1.0, 'beta_max': 0.0, 'memory': 30, 'bound': 'whole'},
    'nodal': {'gamma_max': 1.5, 'beta_max': 0.98, 'memory': 0},
    'secant': {'gamma_max': 1.5, 'beta_max': 0.98, 'memory': 0},
    'springs': {'gamma_max': 1.0, 'beta_max': 0.0, 'memory': 20, 'maxstep_nn': None,
                'maxstep_size': 1.0, 'bound': 'whole', 'gamma_growth': 1e3,
                'interpolate': True},
}

#: Shifts per grid of the trust-region search (:meth:`MaudMethod._trust_region`).
TRUST_GRID = 24

#: Smallest ``s.y / (|s| |y|)`` of a secant pair the L-BFGS memory keeps: the
#: cosine between ``s`` and ``H s`` for a positive-definite ``H`` is at least
#: ``2 / sqrt(cond H)``, so this keeps every pair of a Hessian conditioned up
#: to 4e10 and drops the nearly degenerate pairs of flat or non-convex
#: regions, whose ``1 / s.y`` would blow the recursion up.
MIN_PAIR_COSINE = 1e-5


@dataclass(frozen=True)
class StepRule:
    """The step rule's settings (see the module docstring); made by
    :func:`step_rule`."""

    gamma: float
    gamma_max: float
    gamma_growth: float
    overshoot_shrink: float
    beta_max: float
    memory: int
    maxstep_nn: float | None
    maxstep: float | None
    maxstep_size: float | None
    trust_region: bool
    interpolate: bool
    bound: str
    #: Points per image when the positions are a chain of images (ASE's NEB):
    #: the nearest other point is sought within the same image only (the same
    #: atom in the next image is not a neighbour). None: one scene.
    image_size: int | None = None


def step_rule(model: str, target: str = 'minimum', image_size: int | None = None,
              **keywords: Any) -> StepRule:
    """The step rule for a model named ``model``: :data:`STEP_DEFAULTS`'
    common row, then the model's, then the ``keywords`` that are not None
    (the user's; already checked). For ``target='stationary'`` the memory is
    0 (L-BFGS assumes a positive-definite model)."""
    settings = {**STEP_DEFAULTS['common'],
                **STEP_DEFAULTS.get(model, STEP_DEFAULTS['nodal'])}
    settings.update({name: value for name, value in keywords.items()
                     if value is not None})
    if target == 'stationary':
        settings['memory'] = 0
    return StepRule(image_size=image_size, **settings)


@dataclass
class Point:
    """Where a step began: positions and forces (N, 3), the merit and its
    relative error (the calculator's tolerance when it was computed)."""

    x: np.ndarray
    merit: float
    forces: np.ndarray
    noise: float = 0.0

    def todict(self) -> dict[str, Any]:
        return {'x': self.x, 'merit': self.merit, 'forces': self.forces,
                'noise': self.noise}

    @classmethod
    def fromdict(cls, d: dict[str, Any]) -> Point:
        return cls(np.asarray(d['x'], float), float(d['merit']),
                   np.asarray(d['forces'], float), float(d['noise']))


@dataclass
class MaudState:
    """What the step rule has learnt in a run; a restart file holds
    :meth:`todict`.

    ``gamma``: the step factor now; ``k``: steps since the last momentum
    restart; ``v``: the last move (after constraints), or None; ``last``:
    where the last step began; ``pairs``: the L-BFGS memory ``(s, y)``;
    ``model``: what the stiffness model has learnt (:meth:`StiffnessModel.state`).
    ``solver``, the model at ``last.x``, is not saved: after a restart it is
    computed again if a step goes back there.
    """

    gamma: float
    k: int = 0
    v: np.ndarray | None = None
    last: Point | None = None
    pairs: list[tuple[np.ndarray, np.ndarray]] = field(default_factory=list)
    model: dict[str, Any] = field(default_factory=dict)
    solver: Solver | None = None

    def todict(self) -> dict[str, Any]:
        return {'gamma': self.gamma, 'k': self.k, 'v': self.v,
                'last': None if self.last is None else self.last.todict(),
                'pairs': [list(pair) for pair in self.pairs], 'model': self.model}

    @classmethod
    def fromdict(cls, d: dict[str, Any]) -> MaudState:
        return cls(gamma=float(d['gamma']), k=int(d['k']),
                   v=None if d['v'] is None else np.asarray(d['v'], float),
                   last=None if d['last'] is None else Point.fromdict(d['last']),
                   pairs=[(np.asarray(s, float), np.asarray(y, float))
                          for s, y in d['pairs']],
                   model=dict(d['model']))


#: ``solver_at(x)``: the stiffness model's solver at positions ``x`` (the
#: optimizer moves the atoms there first if they are elsewhere).
SolverAt = Callable[[np.ndarray], Solver]


@dataclass(frozen=True)
class MaudMethod:
    """The step rule's numerics; the state of a run is a :class:`MaudState`.

    Per step the optimizer calls :meth:`step` (which decides whether the last
    step raised the merit, learns from it or takes it back, and returns the
    move from :attr:`MaudState.last`), then :meth:`moved` with the positions
    the constraints allowed.
    """

    model: StiffnessModel
    rule: StepRule
    nearest: NearestDistances

    def start(self) -> MaudState:
        """The state before the first step."""
        return MaudState(gamma=self.rule.gamma)

    def step(self, state: MaudState, x: np.ndarray, merit: float,
             forces: np.ndarray, noise: float, solver_at: SolverAt) -> np.ndarray:
        """The move (N, 3) from ``state.last`` after an evaluation at ``x``
        (merit, forces and the merit's relative error ``noise``); ``state.last``
        becomes where the move starts (``x``, or the last point if the step
        to ``x`` is taken back)."""
        if self.uphill(state, x, merit, forces, noise):
            self._revert(state, x, merit, forces)
            if state.solver is None:   # resumed from a restart file
                state.solver = solver_at(state.last.x)
        else:
            self._accept(state, x, forces)
            state.last = Point(x.copy(), merit, forces.copy(), noise)
            state.solver = solver_at(x)
        return self._move(state)

    def moved(self, state: MaudState, x_new: np.ndarray) -> None:
        """Record the move the constraints allowed, from ``state.last``."""
        state.v = x_new - state.last.x

    def uphill(self, state: MaudState, x: np.ndarray, merit: float,
               forces: np.ndarray, noise: float) -> bool:
        """Whether the step from ``state.last`` to ``x`` raised the merit."""
        last = state.last
        if last is None:
            return False
        change = merit - last.merit
        tol = merit_tolerance(last.merit, max(noise, last.noise))
        if self.model.target != 'minimum' or abs(change) > tol:
            return change > tol
        return -0.5 * np.vdot(last.forces + forces, x - last.x) > 0

    def _revert(self, state: MaudState, x: np.ndarray, merit: float,
                forces: np.ndarray) -> None:
        """Go back to where the last step began, with a smaller gamma."""
        factor = 0.5
        if self.rule.interpolate and state.v is not None:
            factor = _cubic_minimum(state.last, state.v, merit, forces)
        state.gamma *= factor
        state.v = None
        state.k = 0

    def _accept(self, state: MaudState, x: np.ndarray, forces: np.ndarray) -> None:
        """Learn from the accepted step that ended at ``x``."""
        if state.last is None:
            return
        s, y = x - state.last.x, state.last.forces - forces
        state.model = self.model.observe(s, y, state.model)
        if self.rule.memory and np.vdot(s, y) > MIN_PAIR_COSINE * np.vdot(
                s, s) ** 0.5 * np.vdot(y, y) ** 0.5:
            state.pairs = [*state.pairs, (s, y)][-self.rule.memory:]
        state.gamma = min(state.gamma * self.rule.gamma_growth, self.rule.gamma_max)

    def _move(self, state: MaudState) -> np.ndarray:
        """The bounded move from ``state.last`` (with ``state.solver``)."""
        here, rule = state.last, self.rule
        direction = self._direction(state)
        limit = self._limits(here.x)
        if rule.trust_region and hasattr(state.solver, 'dot'):
            direction = self._dogleg(state, direction, limit)
        elif rule.trust_region and hasattr(state.solver, 'shifted_solve'):
            direction = self._trust_region(state, direction, limit)
        if (rule.beta_max > 0 and state.v is not None
                and np.vdot(state.v, direction) < 0):
            state.gamma *= rule.overshoot_shrink  # overshoot: restart
            state.v = None
            state.k = 0
        direction = direction * state.gamma
        if state.v is not None and rule.beta_max > 0:
            direction += min(state.k / (state.k + 3.0), rule.beta_max) * state.v
        state.k += 1
        return _bound(direction, limit, whole=rule.bound == 'whole')

    def _direction(self, state: MaudState) -> np.ndarray:
        """``K^-1 f``, or its L-BFGS correction over the stored pairs; if that
        is not downhill, ``K^-1 f`` and the memory is cleared."""
        solve, forces = state.solver.solve, state.last.forces
        if not state.pairs:
            return solve(forces)
        q = forces.copy()
        alphas = []
        for s, y in reversed(state.pairs):
            alpha = np.vdot(s, q) / np.vdot(s, y)
            q -= alpha * y
            alphas.append(alpha)
        z = solve(q)
        for (s, y), alpha in zip(state.pairs, reversed(alphas), strict=True):
            z += s * (alpha - np.vdot(y, z) / np.vdot(s, y))
        if self.model.target == 'minimum' and not np.vdot(z, forces) > 0:
            state.pairs = []
            return solve(forces)
        return z

    def _limits(self, x: np.ndarray) -> np.ndarray:
        """The longest move allowed to each point (length units)."""
        rule = self.rule
        limit = np.full(len(x), np.inf)
        if rule.maxstep_nn is not None:
            limit = rule.maxstep_nn * self.nearest(x)
        if rule.maxstep is not None:
            limit = np.minimum(limit, rule.maxstep)
        if rule.maxstep_size is not None and len(x) > 1:
            size = np.linalg.norm(x - x.mean(axis=0), axis=1).max()
            limit = np.minimum(limit, rule.maxstep_size * size)
        return limit

    def _dogleg(self, state: MaudState, newton: np.ndarray,
                limit: np.ndarray) -> np.ndarray:
        """The longest move along the dogleg path (from 0 to the Cauchy point
        ``(f.f / f.K f) f``, then to the Newton move ``K^-1 f``) whose
        ``gamma`` times keeps every point within ``limit``."""
        gamma, forces = state.gamma, state.last.forces
        if (gamma * np.linalg.norm(newton, axis=1) / limit).max() <= 1:
            return newton
        curvature = np.vdot(forces, state.solver.dot(forces))
        cauchy = forces * (np.vdot(forces, forces) / curvature) if curvature > 0 else None
        for start, end in ((np.zeros_like(forces), cauchy), (cauchy, newton)):
            if end is None:
                return forces * _reach(gamma * np.zeros_like(forces), gamma * forces, limit)
            t = _reach(gamma * start, gamma * (end - start), limit)
            if t < 1:
                return start + t * (end - start)
        return newton

    def _trust_region(self, state: MaudState, direction: np.ndarray,
                      limit: np.ndarray) -> np.ndarray:
        """``K^-1 f`` damped to ``(K + mu I)^-1 f`` with the smallest ``mu``
        (to about 0.2 %) at which ``gamma`` times it keeps every point within
        ``limit``: the longest move, relative to its limit, falls as ``mu``
        grows, so three log-spaced grids of :data:`TRUST_GRID` values, each
        within the bracket the last one found, pin it down (each grid is one
        batch of shifted solves)."""
        solver, gamma = state.solver, state.gamma
        moves_at = solver.shifted_solve(state.last.forces)

        def longest(mus):
            moves = moves_at(mus)
            lengths = np.sqrt(np.einsum('sij,sij->si', moves, moves))
            return (gamma * lengths / limit).max(axis=1), moves

        if (gamma * np.linalg.norm(direction, axis=1) / limit).max() <= 1:
            return direction
        high = np.abs(solver.values).max()
        while longest(np.array([high]))[0][0] > 1:
            high *= 10.0
        low = high * 1e-12
        for _ in range(3):
            mus = np.exp(np.linspace(np.log(low), np.log(high), TRUST_GRID))
            ratio, moves = longest(mus)
            first = int(np.argmax(ratio <= 1)) if (ratio <= 1).any() else len(mus) - 1
            low, high, best = mus[max(first - 1, 0)], mus[first], moves[first]
        return best


def _reach(start: np.ndarray, step: np.ndarray, limit: np.ndarray) -> float:
    """The largest ``t`` in [0, inf] with every point's ``|start_i + t
    step_i| <= limit_i`` (``start`` within its limits): the smallest positive
    root over points of ``|start_i + t step_i|**2 = limit_i**2``."""
    a = np.einsum('ij,ij->i', step, step)
    b = np.einsum('ij,ij->i', start, step)
    c = np.einsum('ij,ij->i', start, start) - limit**2
    moving = a > 0
    roots = (-b[moving] + np.sqrt(np.maximum(b[moving]**2 - a[moving] * c[moving], 0.0))
             ) / a[moving]
    return float(roots.min(initial=np.inf))


def _bound(step: np.ndarray, limit: np.ndarray, whole: bool = False) -> np.ndarray:
    """Scale each point's move down to its allowed length, or (``whole``)
    the whole move by the one factor that brings every point within its
    length (a descent direction stays one)."""
    length = np.linalg.norm(step, axis=1)
    scale = np.divide(limit, length, out=np.ones_like(length),
                      where=length > limit)
    if whole:
        return step * scale.min(initial=1.0)
    return step * scale[:, None]


def _cubic_minimum(last: Point, move: np.ndarray, merit: float,
                   forces: np.ndarray) -> float:
    """The fraction of ``move`` (from ``last``, which ended at ``merit`` and
    ``forces``) at the minimum of the cubic through both ends' merits and
    slopes along it, clipped to [0.1, 0.5] (a safe line-search cut)."""
    f0, f1 = last.merit, merit
    g0, g1 = -np.vdot(last.forces, move), -np.vdot(forces, move)
    d1 = g0 + g1 - 3.0 * (f1 - f0)
    radicand = d1 * d1 - g0 * g1
    if radicand < 0 or not np.isfinite(radicand):
        return 0.5
    d2 = np.sqrt(radicand)
    denominator = g1 - g0 + 2.0 * d2
    if denominator == 0:
        return 0.5
    t = 1.0 - (g1 + d2 - d1) / denominator
    return float(np.clip(t, 0.1, 0.5)) if np.isfinite(t) else 0.5


def merit_tolerance(merit: float, noise: float = 1e-12) -> float:
    """Slack when comparing merits: ``noise`` (relative; 1e-12 is the
    rounding of energies that sum N**2 terms) times ``|merit|``."""
    return max(noise, 1e-12) * max(abs(merit), 1e-300)
