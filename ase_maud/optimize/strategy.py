"""The Maud step as two strategies composed from a local model
(:mod:`ase_maud.optimize.models.base`), a direction (:mod:`ase_maud.optimize.directions`) and a
search (:mod:`ase_maud.optimize.step_length`); apart from ASE's plumbing (cf. ASE's
``LBFGSMethod``).

:class:`Minimise` (``target='minimum'`` or ``'stationary'``), the
specification's step with the whole scene's stiffness ``K``::

    d = K^-1 f                       (with memory > 0: L-BFGS over K^-1)
    v <- beta v + gamma d;  x <- x + bound(v)

- ``memory`` > 0: the L-BFGS correction over the secant pairs of the last
  ``memory`` accepted steps (:func:`~ase_maud.optimize.directions.lbfgs`); a direction
  that is not downhill is replaced by ``K^-1 f`` and the memory cleared.
- Momentum (Day's dynamic relaxation): the previous move carried over with
  :func:`~ase_maud.optimize.directions.momentum_weight`; ``beta_max = 0`` switches it
  off. A move that points against the new direction (an overshoot) is
  dropped and gamma shrinks by ``overshoot_shrink`` (a kinetic-damping
  restart, as in FIRE and Barnes's form finding).
- A band of images (ASE's NEB) seeking ``'stationary'`` has forces that
  are the gradient of no merit (``|f|**2`` rises along ``f`` itself) and
  that jump where its tangents switch: a step the forces did negative work
  over (:func:`~ase_maud.optimize.step_length.work_change`, an overshoot) is kept, as
  FIRE keeps it, with gamma halved and the momentum dropped; no step is
  taken back.
- Otherwise a step that raised the merit (the energy for ``'minimum'``,
  ``|f|**2`` for ``'stationary'``;
  :func:`~ase_maud.optimize.step_length.merit_change`) is taken back at no
  extra calculator call: the strategy returns to where the step began
  (whose forces and local model it kept), cuts gamma (halved, or with
  ``interpolate`` by :func:`~ase_maud.optimize.step_length.cubic_cut` through the merit's
  change as judged, gamma then scaling
  the move after its bound, as a line search) and drops the momentum.
  With ``learn_rises`` (the bfgs model) the step taken back is learnt
  from instead: its secant pair joins the L-BFGS memory (the curvature
  along it is the one thing the rise measured) and the next move is the
  model's new move from where the step began, no longer than the cubic
  cut of the step taken back (a trust radius, so the curvature learnt and
  the cut do not shorten the move twice), each point's move cut on its own
  so that its jump from where it is (the rejected end) stays within its
  limit.
  Gamma grows by ``gamma_growth`` after each accepted step, up to
  ``gamma_max``.
- No point moves further than its limit (:class:`~ase_maud.optimize.step_length.Limits`);
  each point's move is scaled on its own, or (``bound='whole'``) the whole
  move by one factor; with ``trust_region`` (a model that can be damped,
  the exact one) the move is cut by :func:`~ase_maud.optimize.step_length.trust_region`.

:class:`Saddle` (``target='saddle'``), eigenvector following: in the local
model's eigenbasis (curvatures ``b_i``, gradient components ``g_i``), uphill
along the ``order`` followed modes and downhill along the rest, each mode
on its own (:func:`~ase_maud.optimize.directions.mode_steps`). With every eigenpair
(the exact model) that is the whole move; with the lowest ones only (the
springs model of a large scene, from Hessian-vector products, the followed
modes and :data:`LOWEST_MODES` more) the rest of the move is the truncated
Newton move on the forces off them. No step is taken back; the whole move
is scaled to within ``gamma`` times each point's limit, ``gamma`` being a
trust fraction (:func:`~ase_maud.optimize.step_length.trust_fraction`) judged by the
energy change the quadratic model predicted for the move.

The state of a run is a :class:`MaudState` (what a restart file holds); the
settings are a frozen :class:`StepRule`, made by :func:`step_rule` from
:data:`STEP_DEFAULTS` (the one table of every model's defaults) and the
user's keywords; :func:`compose` picks the strategy for a model's target.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from ase import Atoms

from ase_maud.analysis.stationary import RTOL, classify
from ase_maud.errors import WrongIndexError
from ase_maud.optimize.directions import (
    ModeFollowing,
    keeps_pair,
    lbfgs,
    mode_steps,
    momentum_weight,
    off,
    truncated_newton,
    within_reach,
)
from ase_maud.optimize.models.base import Solver, StiffnessModel
from ase_maud.optimize.state import LocalAt, MaudState, Point
from ase_maud.optimize.step_length import (
    Limits,
    bound,
    cubic_cut,
    merit_change,
    merit_tolerance,
    reaches,
    trust_fraction,
    trust_region,
    work_change,
)
from ase_maud.optimize.step_rules import CLIMB_SIDE, LOWEST_MODES, StepRule
from ase_maud.physics.neighbours import NearestDistances

#: Steps whose energy rose while the forces drove the points at both ends
#: after which a calculator's energy is taken to be noisy (Minimum._change).
DISAGREEMENTS = 2

#: The largest rise, relative to the energy, taken for noise (Minimum._change).
NOISE_MAX = 0.1


@dataclass(frozen=True)
class Strategy:
    """What both strategies are: a local ``model``, the step ``rule`` and the
    per-point ``limits``. Per step the optimizer calls ``step`` (which
    returns the move from ``state.last``, built with the local model that
    ``local_at(x)`` gives), then :meth:`moved` with the positions the
    constraints allowed."""

    model: StiffnessModel
    rule: StepRule
    limits: Limits

    @property
    def band(self) -> bool:
        """Whether this is a band of images seeking a stationary point (ASE's
        NEB): its forces are the gradient of no merit, so a step is judged by
        the work they did over it, and an overshoot is kept, as FIRE keeps it."""
        return self.rule.image_size is not None and self.model.target == 'stationary'

    def start(self) -> MaudState:
        """The state before the first step."""
        return MaudState(gamma=self.rule.gamma)

    def moved(self, state: MaudState, x_new: np.ndarray) -> None:
        """Record the move the constraints allowed, from ``state.last``."""
        state.v = x_new - state.last.x

    def learn(self, state: MaudState, s: np.ndarray, y: np.ndarray) -> None:
        """Learn from a step ``s`` (N, 3) that changed the forces by ``-y``:
        the model's state and, with a memory, the L-BFGS pairs."""
        state.model = self.model.observe(s, y, state.model)
        self.remember(state, s, y)

    def remember(self, state: MaudState, s: np.ndarray, y: np.ndarray) -> None:
        """Keep the secant pair ``(s, y)`` in the L-BFGS memory (if the rule
        has one and :func:`keeps_pair`), the oldest dropped beyond its size
        and, with a ``memory_reach``, beyond it (:func:`within_reach`); the
        pairs are views of ``state.rows``, one copy of each."""
        if self.rule.memory and keeps_pair(s, y):
            pairs = [*state.pairs, (s, y)][-self.rule.memory:]
            if self.rule.memory_reach is not None:
                pairs = within_reach(pairs, self.rule.memory_reach)
            state.pairs = state.rows.store(pairs, self.rule.memory)


@dataclass(frozen=True)
class Minimise(Strategy):
    """Newton-like descent with a search; see the module docstring. The
    step decides whether the last step raised the merit, learns from it or
    takes it back."""

    #: Rows of :attr:`MaudState.modes` a restart file keeps: None (no modes).
    kept_modes = None
    #: Whether the energy may carry noise its calculator does not declare, to be
    #: learnt from the steps (:meth:`_change`): a calculator that declares its
    #: accuracy (:class:`~ase_maud.calculator.accuracy.ToleranceAware`, a
    #: MaudCalculator) is taken at its word.
    learns_noise: bool = False

    def step(self, state: MaudState, x: np.ndarray, merit: float, forces: np.ndarray,
             noise: float, local_at: LocalAt) -> np.ndarray:
        """The move (N, 3) from ``state.last`` after an evaluation at ``x``
        (merit, forces and the merit's relative error ``noise``); ``state.last``
        becomes where the move starts (``x``, or the last point if the step
        to ``x`` is taken back)."""
        last = state.last
        change, slack = (0.0, 0.0) if last is None else self._change(last, x, merit, forces,
                                                                     noise, state)
        if change > slack and not self.band:   # the step raised the merit
            if state.solver is None:   # resumed: the model where the step began
                state.solver = local_at(last.x)
            if self.rule.learn_rises and state.v is not None:
                return self._retake(state, x, change, forces)
            self._revert(state, change, forces)
        else:
            self._accept(state, x, forces)
            if change > slack:   # a band's overshoot: kept, as FIRE keeps it
                state.gamma *= 0.5
                state.v = None
                state.k = 0
            state.last = Point(x.copy(), merit, forces.copy(), noise)
            state.solver = local_at(x)
        return self._move(state)

    def index_reached(self, state: MaudState, local: Callable[[], Solver]) -> bool:
        """A minimiser converges wherever the forces vanish."""
        return True

    def _change(self, last: Point, x: np.ndarray, merit: float, forces: np.ndarray,
                noise: float, state: MaudState) -> tuple[float, float]:
        """The merit's change over the step from ``last`` to ``x`` and the slack
        within which it is no rise (:func:`merit_change`; a band's
        :func:`work_change`).

        An energy that rose over a step along which the forces drive the
        points at both ends (descent at the start and at the end: a smooth
        energy consistent with its forces cannot rise there but over a bump),
        by more than the forces say it fell (the trapezoid estimate: a bump,
        two points passing each other, rises less than the fall around it)
        and by less than :data:`NOISE_MAX` of the energy, disagrees with its
        forces; from the second such step on (where :attr:`learns_noise`),
        the calculator's energy is taken to carry noise of the largest such rise
        (``state.noise_seen``, relative), and changes within it are judged
        by the forces, as a declared noise is."""
        move = x - last.x
        if self.band:
            return work_change(last.forces, move, forces)
        energy = self.model.target == 'minimum'
        seen = state.noise_seen
        change, slack = merit_change(last.merit, max(last.noise, seen), last.forces, move,
                                     merit, forces, max(noise, seen), energy)
        if (self.learns_noise and energy and change > slack and np.vdot(last.forces, move) > 0
                and np.vdot(forces, move) > 0
                and change > -work_change(last.forces, move, forces)[0]   # < 0: a fall
                and change < NOISE_MAX * abs(last.merit)):
            state.disagreements += 1
            rise = change / max(abs(last.merit), 1e-300)
            state.noise_suspected = max(state.noise_suspected, rise)
            if state.disagreements >= DISAGREEMENTS:
                state.noise_seen = state.noise_suspected
                return work_change(last.forces, move, forces)
        return change, slack

    def _revert(self, state: MaudState, change: float, forces: np.ndarray) -> None:
        """Go back to where the last step (which changed the merit by
        ``change``, as judged, and ended at ``forces``) began, with a smaller
        gamma."""
        factor = 0.5
        if self.rule.interpolate and state.v is not None:
            factor = cubic_cut(state.last.forces, state.v, change, forces)
        state.gamma *= factor
        state.v = None
        state.k = 0

    def _retake(self, state: MaudState, x: np.ndarray, change: float,
                forces: np.ndarray) -> np.ndarray:
        """The move from where the last step (to ``x``, which changed the
        merit by ``change``, as judged, and ended at ``forces``) began, with
        that step's secant pair in the L-BFGS memory (if :func:`keeps_pair`;
        the model's own state, e.g. the bfgs model's ``kappa``, is not
        changed by a step taken back), no point moving further than the
        longest point move of that step times its :func:`cubic_cut`, nor
        further from ``x`` (where the points are) than its limit: each
        point's move is cut on its own (:func:`reaches`) so that its jump
        from ``x`` stays within its limit (one point at its limit does not
        hold the others back)."""
        last, rejected = state.last, state.v
        radius = cubic_cut(last.forces, rejected, change, forces) * float(
            np.linalg.norm(rejected, axis=1).max())
        self.remember(state, x - last.x, last.forces - forces)
        state.v = None
        state.k = 0
        move = self._move(state)
        length = float(np.linalg.norm(move, axis=1).max())
        if length > radius:
            move = move * (radius / length)
        # from x, the points jump by move - rejected: within their limits too
        return move * np.minimum(reaches(-rejected, move, self.limits(last.x)), 1.0)[:, None]

    def _accept(self, state: MaudState, x: np.ndarray, forces: np.ndarray) -> None:
        """Learn from the accepted step that ended at ``x``."""
        if state.last is None:
            return
        self.learn(state, x - state.last.x, state.last.forces - forces)
        state.gamma = min(state.gamma * self.rule.gamma_growth, self.rule.gamma_max)

    def _move(self, state: MaudState) -> np.ndarray:
        """The bounded move from ``state.last`` (with ``state.solver``)."""
        here, rule, solver = state.last, self.rule, state.solver
        direction = lbfgs(solver.solve, here.forces, state.pairs, state.rows)
        if (state.pairs and self.model.target != 'stationary'
                and not np.vdot(direction, here.forces) > 0):
            state.pairs = []
            direction = solver.solve(here.forces)
        limit = self.limits(here.x)
        if rule.trust_region:
            direction = trust_region(solver, here.forces, direction, state.gamma, limit)
        if (rule.beta_max > 0 and state.v is not None
                and np.vdot(state.v, direction) < 0):
            state.gamma *= rule.overshoot_shrink  # overshoot: restart
            state.v = None
            state.k = 0
        whole = rule.bound == 'whole'
        if rule.interpolate:   # a line search: gamma cuts the bounded move
            direction = bound(direction, limit, whole)
        direction = direction * state.gamma
        if state.v is not None and rule.beta_max > 0:
            direction += momentum_weight(state.k, rule.beta_max) * state.v
        state.k += 1
        return bound(direction, limit, whole)


@dataclass(frozen=True)
class Saddle(Strategy):
    """Eigenvector following to a stationary point with ``rule.order``
    negative curvatures; see the module docstring. The local model gives
    every eigenpair (``complete``: the exact model) or the lowest ones
    (:meth:`~ase_maud.optimize.models.base.ModeSolver.eigenpairs`)."""

    following: ModeFollowing

    @property
    def complete(self) -> bool:
        """Whether the local model gives every eigenpair."""
        return self.model.complete_modes

    @property
    def kept_modes(self) -> int:
        """Rows of :attr:`MaudState.modes` a restart file keeps: ``order``,
        and with the lowest modes only :data:`LOWEST_MODES` more."""
        return self.rule.order + (0 if self.complete else LOWEST_MODES)

    def step(self, state: MaudState, x: np.ndarray, merit: float, forces: np.ndarray,
             noise: float, local_at: LocalAt) -> np.ndarray:
        """The move (N, 3) from ``x`` (every step is accepted: no merit
        decides a climb); the trust fraction learns from the last one."""
        last = state.last
        if last is not None:
            s, y = x - last.x, last.forces - forces
            state.model = self.model.observe(s, y, state.model)
            if state.predicted is not None:
                actual = -np.vdot(last.forces - 0.5 * y, s)   # the trapezoid rule
                slack = merit_tolerance(np.vdot(last.forces, last.forces) ** 0.5
                                        * np.linalg.norm(s))
                state.gamma = trust_fraction(state.gamma, actual, state.predicted,
                                             self.rule.gamma_max, slack)
        state.last = Point(x.copy(), merit, forces.copy(), noise)
        state.solver = local_at(x)
        return self._move(state)

    def index_reached(self, state: MaudState, local: Callable[[], Solver]) -> bool:
        """Whether the local model (built by ``local()``) at a point where the
        forces vanish has exactly ``order`` negative curvatures (beyond
        :data:`ase_maud.analysis.stationary.RTOL` of the largest): the minimum a search
        starts from is left, not reported. The eigensolver starts from the
        modes followed, before the first step from the move given as ``mode``
        (:meth:`~ase_maud.optimize.directions.ModeFollowing.guess`; cold if none)."""
        order = self.rule.order
        guess = self.following.guess() if state.modes is None else state.modes[:order + 1]
        values = local().eigenpairs(order + 1, guess)[0]
        return int(np.sum(values < -RTOL * np.abs(values).max(initial=0.0))) == order

    def verify(self, atoms: Atoms, ftol: float, step: int, work: Any = None,
               guess: np.ndarray | None = None) -> tuple[Any, WrongIndexError | None]:
        """The converged point of ``atoms`` classified from the analytic
        Hessian (:func:`ase_maud.analysis.stationary.classify`, forces below ``ftol``,
        its products or Hessian counted in ``work`` if given, unless the
        model had the calculator compute the Hessian with the forces, counted
        already), and a WrongIndexError
        (else None) if its index is not ``order`` or a zero curvature leaves
        it unknown (``step``: where it converged). An iterative
        classification starts from the modes ``guess`` (those followed)."""
        work = None if self.model.needs(atoms) == 'hessian' else work
        point, order = classify(atoms, ftol=ftol, work=work, guess=guess), self.rule.order
        if point.index == order and not point.n_zero:
            return point, None
        zero = f' and {point.n_zero} zero curvatures' if point.n_zero else ''
        return point, WrongIndexError(
            f'converged at step {step} on a {point.verdict} of index {point.index}{zero}, '
            f'not of index {order}: lowest curvatures '
            f'{np.array2string(point.eigenvalues[:order + 2], precision=4)}; '
            'try another mode= or start')

    def _move(self, state: MaudState) -> np.ndarray:
        solver, forces = state.solver, state.last.forces
        guess = state.modes if state.modes is not None else self.following.guess()
        values, modes = solver.eigenpairs(self.kept_modes, guess)
        up, followed = self.following.pick(state.modes, values, modes)
        modes = modes.copy()
        modes[up] = followed
        down = np.setdiff1d(np.arange(len(values)), up)
        gradient = -np.einsum('kij,ij->k', modes, forces)
        limit = state.gamma * self.limits(state.last.x)
        # within CLIMB_SIDE of the trust length of a followed mode's minimum,
        # either side is uphill: climb along the mode as followed
        b, climb = values[up], gradient[up]
        side = (b > 0) & (np.abs(climb) < CLIMB_SIDE * b * limit.min())
        climb = np.where(side, np.maximum(np.abs(climb), np.finfo(float).eps * b), climb)
        reach = (limit / np.maximum(np.linalg.norm(modes, axis=2), 1e-300)).min(axis=1)
        steps = np.zeros(len(values))
        steps[up] = mode_steps(b, climb, reach[up], uphill=True)
        steps[down] = mode_steps(values[down], gradient[down], reach[down], uphill=False)
        move = np.einsum('k,kij->ij', steps, modes)
        if self.complete:
            state.modes = modes[up]
            bounded = bound(move, limit, whole=True)
            along = np.einsum('kij,ij->k', modes, bounded)
            state.predicted = float(-np.vdot(forces, bounded)
                                    + 0.5 * np.dot(values, along**2))
            return bounded
        state.modes = modes[np.concatenate([up, down])]   # the next LOBPCG's start
        rest = off(forces, modes)
        descent, curved = truncated_newton(lambda d: off(solver.curvature(d), modes),
                                           lambda r: off(solver.solve(r), modes),
                                           rest, limit)
        bounded = bound(move + descent, limit, whole=True)
        t = np.linalg.norm(bounded) / max(np.linalg.norm(move + descent), 1e-300)
        # the quadratic model's energy change: the lowest modes' curvatures,
        # and the Hessian off them (curved = H descent)
        state.predicted = float(t * np.dot(gradient, steps)
                                + 0.5 * t * t * np.dot(values, steps**2)
                                - t * np.vdot(rest, descent)
                                + 0.5 * t * t * np.vdot(descent, curved))
        return bounded


def compose(model: StiffnessModel, rule: StepRule, nearest: NearestDistances,
            mode: int | np.ndarray | None = None,
            quadratic: Callable[[], bool] | None = None,
            learns_noise: bool = False) -> Strategy:
    """The strategy for ``model``'s target: :class:`Saddle` for ``'saddle'``
    (following ``mode``, see :class:`~ase_maud.optimize.directions.ModeFollowing`), else
    :class:`Minimise` (``learns_noise``: :attr:`Minimise.learns_noise`);
    ``nearest`` gives the limits' neighbour distances, ``quadratic`` whether
    the energy is quadratic (no limits for a minimum)."""
    limits = Limits(nearest, rule.maxstep_nn, rule.maxstep, rule.maxstep_size,
                    quadratic if model.target == 'minimum' else None)
    if model.target == 'saddle':
        return Saddle(model, rule, limits, ModeFollowing(rule.order, mode))
    return Minimise(model, rule, limits, learns_noise)
