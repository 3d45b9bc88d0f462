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
  and slopes (clipped to [0.1, 0.5] of itself, as a line search does; gamma
  then scales the move after its bound, so that the next move is that
  fraction of the one taken back even where the bound had clipped it). Gamma
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

``target='saddle'`` (the exact model, whose solver gives the Hessian's
eigenpairs on the internal moves) takes a step of eigenvector following
instead: in the eigenbasis (eigenvalues ``b_i``, gradient components
``g_i``), uphill along the ``order`` followed modes and downhill along the
rest, each mode on its own (:func:`_mode_steps`):

    s_i = -g_i / b_i         where b_i has the sign sought (negative along
                             a followed mode, positive along the rest),
                             at most reach_i long;
    s_i = +-reach_i          else: the whole reach, uphill along a
                             followed mode, downhill along the rest,

``reach_i`` the step at which mode ``i`` alone brings a point to its bound
(where the curvature has the wrong sign the quadratic has no stationary
point to aim at: a convex climb goes as far as it is trusted). The
followed modes are those of the start (the lowest ``order``, or the one
``mode`` names or points along, with the next lowest), then at each step
the eigenvectors that overlap most with the last ones: the climb follows
one mode as it softens and turns negative, rather than switching to
whichever is lowest. No step is taken back; the whole move is scaled so
that no point moves further than ``gamma`` times its bound, and gamma (a
trust fraction, up to ``gamma_max``) grows by half when the quadratic model
predicted the energy change well (their ratio within ``TRUST_GOOD`` of 1)
and halves when it did not (beyond ``TRUST_BAD``).

With the lowest eigenpairs only (the springs model of a large scene, from
Hessian-vector products; the followed modes and :data:`LOWEST_MODES` more,
each step's LOBPCG started from the last step's), the same holds along
those modes, and the rest of the move is the truncated
Newton move on the forces without their components along them
(:func:`_truncated_newton`: conjugate gradients on the Hessian off those
modes, preconditioned by ``P^-1``, within the same bounds); the trust ratio
compares the energy change with the quadratic model of both parts.

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

#: How far from 1 the ratio of the energy change to its prediction may be
#: for the saddle step's trust fraction to grow, and beyond which it halves.
TRUST_GOOD, TRUST_BAD = 0.25, 0.75

#: A saddle search at less than this fraction of its trust length from the
#: minimum along a followed mode climbs that mode the way it is followed.
CLIMB_SIDE = 1e-3

#: Relative residual of the Newton move off the lowest modes of a large
#: saddle search (:func:`_truncated_newton`), and its most Hessian-vector
#: products per step.
NEWTON_RTOL, NEWTON_MAXITER = 0.1, 100

#: Eigenpairs beyond the followed modes that a large saddle search computes
#: (LOBPCG) and steps along one by one: the next lowest, negative or soft,
#: which the truncated Newton move off them would otherwise meet (chosen by
#: measurement, docs/optimizer.md).
LOWEST_MODES = 3

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
    #: ``target='saddle'``: the negative curvatures sought (modes followed uphill).
    order: int = 0


def step_rule(model: str, target: str = 'minimum', image_size: int | None = None,
              **keywords: Any) -> StepRule:
    """The step rule for a model named ``model``: :data:`STEP_DEFAULTS`'
    common row, then the model's, then the ``keywords`` that are not None
    (the user's; already checked). For ``target='stationary'`` and
    ``'saddle'`` the memory is 0 (L-BFGS assumes a positive-definite model)."""
    settings = {**STEP_DEFAULTS['common'],
                **STEP_DEFAULTS.get(model, STEP_DEFAULTS['nodal'])}
    settings.update({name: value for name, value in keywords.items()
                     if value is not None})
    if target in ('stationary', 'saddle'):
        settings['memory'] = 0
    if target == 'saddle' and settings['maxstep_nn'] is None:
        settings['maxstep_nn'] = STEP_DEFAULTS['common']['maxstep_nn']
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
    ``model``: what the stiffness model has learnt (:meth:`StiffnessModel.state`);
    ``modes``: a saddle search's modes, (:meth:`MaudMethod.kept_modes`, N, 3):
    the ``order`` it follows uphill, signed as followed, then (lowest modes
    only) the other lowest modes of its last step, from which the next
    step's LOBPCG starts; None before its first step (and for other
    targets); ``predicted``: the energy change its last move's model
    predicted (lowest modes only; else None). A restart file keeps them, so
    a resumed search follows the same modes.
    ``solver``, the model at ``last.x``, is not saved: after a restart it is
    computed there again when the next step needs it (a step taken back, or
    a saddle step's trust ratio).
    """

    gamma: float
    k: int = 0
    v: np.ndarray | None = None
    last: Point | None = None
    pairs: list[tuple[np.ndarray, np.ndarray]] = field(default_factory=list)
    model: dict[str, Any] = field(default_factory=dict)
    solver: Solver | None = None
    modes: np.ndarray | None = None
    predicted: float | None = None

    def todict(self) -> dict[str, Any]:
        return {'gamma': self.gamma, 'k': self.k, 'v': self.v,
                'last': None if self.last is None else self.last.todict(),
                'pairs': [list(pair) for pair in self.pairs], 'model': self.model,
                'modes': self.modes, 'predicted': self.predicted}

    @classmethod
    def fromdict(cls, d: dict[str, Any]) -> MaudState:
        return cls(gamma=float(d['gamma']), k=int(d['k']),
                   v=None if d['v'] is None else np.asarray(d['v'], float),
                   last=None if d['last'] is None else Point.fromdict(d['last']),
                   pairs=[(np.asarray(s, float), np.asarray(y, float))
                          for s, y in d['pairs']],
                   model=dict(d['model']),
                   modes=None if d.get('modes') is None else np.asarray(d['modes'], float),
                   predicted=d.get('predicted'))


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
    #: Which way a saddle search starts to climb: an index of the Hessian's
    #: modes at the start (ascending), a move (N, 3) (the mode that overlaps
    #: it most), or None (the lowest ``order`` modes).
    mode: int | np.ndarray | None = None

    def kept_modes(self) -> int | None:
        """Rows of :attr:`MaudState.modes` (None unless a saddle search): its
        ``order``, and with the lowest modes only (every model but the exact
        one) :data:`LOWEST_MODES` more."""
        if self.model.target != 'saddle':
            return None
        return self.rule.order + (0 if self.model.name == 'exact' else LOWEST_MODES)

    def start(self) -> MaudState:
        """The state before the first step."""
        return MaudState(gamma=self.rule.gamma)

    def step(self, state: MaudState, x: np.ndarray, merit: float,
             forces: np.ndarray, noise: float, solver_at: SolverAt) -> np.ndarray:
        """The move (N, 3) from ``state.last`` after an evaluation at ``x``
        (merit, forces and the merit's relative error ``noise``); ``state.last``
        becomes where the move starts (``x``, or the last point if the step
        to ``x`` is taken back)."""
        uphill = self.uphill(state, x, merit, forces, noise)
        if state.solver is None and state.last is not None and (
                uphill or self.model.target == 'saddle'):
            # resumed from a restart file: the model where the last step began,
            # for the step taken back or the saddle step's trust ratio
            state.solver = solver_at(state.last.x)
        if uphill:
            self._revert(state, x, merit, forces)
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
        if last is None or self.model.target == 'saddle':
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
        if self.model.target == 'saddle':   # gamma is the trust fraction
            self._trust(state, s, y)
        else:
            state.gamma = min(state.gamma * self.rule.gamma_growth, self.rule.gamma_max)
        if self.rule.memory and np.vdot(s, y) > MIN_PAIR_COSINE * np.vdot(
                s, s) ** 0.5 * np.vdot(y, y) ** 0.5:
            state.pairs = [*state.pairs, (s, y)][-self.rule.memory:]

    def _move(self, state: MaudState) -> np.ndarray:
        """The bounded move from ``state.last`` (with ``state.solver``)."""
        here, rule = state.last, self.rule
        if self.model.target == 'saddle':
            return self._saddle_move(state)
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
        if rule.interpolate:   # a line search: gamma cuts the bounded move
            direction = _bound(direction, limit, whole=rule.bound == 'whole')
        direction = direction * state.gamma
        if state.v is not None and rule.beta_max > 0:
            direction += min(state.k / (state.k + 3.0), rule.beta_max) * state.v
        state.k += 1
        return _bound(direction, limit, whole=rule.bound == 'whole')

    def _saddle_move(self, state: MaudState) -> np.ndarray:
        """The move of eigenvector following (module docstring), the whole
        of it scaled to within ``gamma`` times each point's bound. With the
        lowest modes only (a large scene), minimum-mode following: the same
        on the followed and :data:`LOWEST_MODES` more, the truncated Newton
        move on the rest of the forces (:func:`_truncated_newton`)."""
        solver, forces = state.solver, state.last.forces
        if hasattr(solver, 'modes'):
            values, modes = solver.modes()
        else:
            values, modes = solver.lowest(self.rule.order + LOWEST_MODES, state.modes)
        up = self._followed(state, values, modes)
        modes = modes.copy()
        modes[up] = state.modes   # signed as followed
        down = np.setdiff1d(np.arange(len(values)), up)
        gradient = -np.einsum('kij,ij->k', modes, forces)
        limit = state.gamma * self._limits(state.last.x)
        # within CLIMB_SIDE of the trust length of a followed mode's minimum,
        # either side is uphill: climb along the mode as followed (``mode``)
        b, climb = values[up], gradient[up]
        side = (b > 0) & (np.abs(climb) < CLIMB_SIDE * b * limit.min())
        climb = np.where(side, np.maximum(np.abs(climb), np.finfo(float).eps * b), climb)
        reach = (limit / np.maximum(np.linalg.norm(modes, axis=2), 1e-300)).min(axis=1)
        steps = np.zeros(len(values))
        steps[up] = _mode_steps(b, climb, reach[up], uphill=True)
        steps[down] = _mode_steps(values[down], gradient[down], reach[down], uphill=False)
        move = np.einsum('k,kij->ij', steps, modes)
        if hasattr(solver, 'modes'):
            return _bound(move, limit, whole=True)
        state.modes = modes[np.concatenate([up, down])]   # the next LOBPCG's start
        rest = _off(forces, modes)
        descent, curved = _truncated_newton(lambda d: _off(solver.curvature(d), modes),
                                            lambda r: _off(solver.solve(r), modes),
                                            rest, limit)
        bounded = _bound(move + descent, limit, whole=True)
        t = np.linalg.norm(bounded) / max(np.linalg.norm(move + descent), 1e-300)
        # the quadratic model's energy change: the lowest modes' curvatures,
        # and the Hessian off them (curved = H descent)
        state.predicted = float(t * np.dot(gradient, steps)
                                + 0.5 * t * t * np.dot(values, steps**2)
                                - t * np.vdot(rest, descent)
                                + 0.5 * t * t * np.vdot(descent, curved))
        return bounded

    def _followed(self, state: MaudState, values: np.ndarray,
                  modes: np.ndarray) -> np.ndarray:
        """The indices of the ``order`` modes followed uphill: those that
        overlap most with the modes followed so far (the start's, see
        :attr:`mode`); ``state.modes`` becomes them, signs kept."""
        order = self.rule.order
        if order > len(values):
            raise ValueError(f'order={order} exceeds the {len(values)} internal '
                             'modes of the scene (free moves less rigid-body ones)')
        reference = (state.modes[:order] if state.modes is not None
                     else self._start(modes))
        overlap = np.abs(np.einsum('kij,mij->km', reference, modes))
        picked = np.zeros(len(reference), dtype=int)
        taken = np.zeros(len(modes), dtype=bool)
        for row in np.argsort(-overlap.max(axis=1, initial=0.0)):
            picked[row] = int(np.argmax(np.where(taken, -1.0, overlap[row])))
            taken[picked[row]] = True
        for row in np.argsort(-values[picked]):   # no negative mode left downhill
            lower = np.flatnonzero(~taken & (values < min(values[picked[row]], 0.0)))
            if lower.size:
                taken[picked[row]], taken[lower[0]] = False, True
                picked[row] = lower[0]
        signs = np.sign(np.einsum('kij,kij->k', reference, modes[picked]))
        state.modes = modes[picked] * np.where(signs == 0, 1.0, signs)[:, None, None]
        return picked

    def _start(self, modes: np.ndarray) -> np.ndarray:
        """The modes a saddle search starts to follow (see :attr:`mode`)."""
        order, mode = self.rule.order, self.mode
        if mode is None or order == 0:
            return modes[:order]
        if isinstance(mode, (int, np.integer)):
            if not 0 <= mode < len(modes):
                raise ValueError(f'mode={mode} is not one of the {len(modes)} internal '
                                 'modes of the scene (0 is the lowest)')
            first = int(mode)
        else:
            overlap = np.abs(np.einsum('ij,mij->m', mode, modes))
            if not overlap.max(initial=0.0) > 0:
                raise ValueError('mode: the move given has no internal component '
                                 '(it is held by the constraints, or rigid)')
            first = int(np.argmax(overlap))
            sign = np.sign(np.vdot(mode, modes[first])) or 1.0
            modes = modes.copy()
            modes[first] *= sign
        rest = [m for m in range(len(modes)) if m != first][:order - 1]
        return modes[[first, *rest]]

    def _trust(self, state: MaudState, s: np.ndarray, y: np.ndarray) -> None:
        """Grow or cut the saddle step's trust fraction ``gamma`` by the ratio
        of the energy change over the step ``s`` (the trapezoid rule, from
        the forces at both ends: ``y`` is their drop) to the change the
        quadratic model at its start predicted (module docstring)."""
        forces = state.last.forces
        if hasattr(state.solver, 'modes'):
            values, modes = state.solver.modes()
            along = np.einsum('kij,ij->k', modes, s)
            predicted = -np.vdot(forces, s) + 0.5 * np.dot(values, along**2)
        elif state.predicted is None:
            return
        else:   # the lowest modes only: what the move's model predicted
            predicted = state.predicted
        actual = -np.vdot(forces - 0.5 * y, s)
        if abs(predicted) <= merit_tolerance(np.vdot(forces, forces) ** 0.5
                                             * np.linalg.norm(s)):
            return
        ratio = actual / predicted
        if abs(ratio - 1) <= TRUST_GOOD:
            state.gamma = min(1.5 * state.gamma, self.rule.gamma_max)
        elif abs(ratio - 1) > TRUST_BAD:
            state.gamma *= 0.5

    def _direction(self, state: MaudState) -> np.ndarray:
        """``K^-1 f`` (``f`` the forces at ``state.last``), or its L-BFGS
        correction over the stored pairs; if that is not downhill, ``K^-1 f``
        and the memory is cleared."""
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
        if self.model.target != 'stationary' and not np.vdot(z, forces) > 0:
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


def _off(move: np.ndarray, modes: np.ndarray) -> np.ndarray:
    """``move`` (N, 3) without its components along the orthonormal ``modes``
    (k, N, 3)."""
    return move - np.einsum('k,kij->ij', np.einsum('kij,ij->k', modes, move), modes)


def _truncated_newton(hessian: Callable[[np.ndarray], np.ndarray],
                      precondition: Callable[[np.ndarray], np.ndarray],
                      forces: np.ndarray, limit: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The Newton move ``d`` with ``H d = forces`` within the trust region
    ``|d_i| <= limit_i`` (every point), by Steihaug's truncated conjugate
    gradients preconditioned by ``precondition`` (``P^-1``): to the relative
    residual :data:`NEWTON_RTOL` in at most :data:`NEWTON_MAXITER` products,
    or stopped where the iterates leave the region or a direction of
    negative curvature appears, which is then followed to the region's edge.
    The first iterate is along ``P^-1 f``, so a cut move still descends.
    Returns ``d`` and ``H d`` (N, 3)."""
    move, curved = np.zeros_like(forces), np.zeros_like(forces)
    residual = forces.copy()
    z = precondition(residual)
    direction, rz = z, np.vdot(residual, z)
    goal = NEWTON_RTOL * np.linalg.norm(forces)
    for _ in range(NEWTON_MAXITER):
        h = hessian(direction)
        c = np.vdot(direction, h)
        step, curved_step = (direction * (rz / c), h * (rz / c)) if c > 0 else (direction, h)
        t = _reach(move, step, limit)
        if not (c > 0 and t >= 1):   # to the edge of the region, and stop
            return move + t * step, curved + t * curved_step
        move += step
        curved += curved_step
        residual -= curved_step
        if np.linalg.norm(residual) <= goal:
            break
        z = precondition(residual)
        rz, last = np.vdot(residual, z), rz
        direction = z + (rz / last) * direction
    return move, curved


def _mode_steps(values: np.ndarray, gradient: np.ndarray, reach: np.ndarray,
                uphill: bool) -> np.ndarray:
    """Steps along modes of curvatures ``values`` and gradient components
    ``gradient``: the Newton step ``-g_i / b_i`` where the curvature has the
    sign sought (negative ``uphill``, positive downhill), else the whole
    ``reach_i`` uphill or downhill (no model of where the slope turns);
    each at most ``reach_i`` long (the step at which the mode alone brings a
    point to its bound)."""
    climb = np.sign(gradient) if uphill else -np.sign(gradient)
    right = values < 0 if uphill else values > 0
    newton = -gradient / np.where(right, values, 1.0)
    return np.where(right, np.clip(newton, -reach, reach), climb * reach)


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
