"""How far a step goes: the acceptance test, the line-search cut, the
per-point bounds and one trust-region loop (cf. optimistix's search apart
from its descent).

Moves are (N, 3) arrays of lengths; forces have ASE's sign (``-dE/dr``);
a merit is the energy (``target='minimum'``) or ``|f|**2``.

- :func:`merit_change`: the merit's change over a step, judged by the
  forces where the energies cannot tell: two energies that differ by less
  than their errors summed (rounding, or an approximate calculator's
  tolerance, each energy with its own) are told apart by the trapezoid
  estimate ``-(f_old + f) . dx / 2``, a directional-derivative test that
  needs forces only; the step raised the merit where the change exceeds
  the slack.
- :func:`work_change`: that trapezoid estimate alone, for forces that are
  the gradient of no merit (a band of images, ASE's NEB): a step is judged
  by the work the forces did over it, by the forces alone as FIRE's and
  MDMin's power test judges it.
- :func:`cubic_cut`: the fraction of a step taken back at the minimum of
  the cubic through both ends' slopes and the merit's change (a safe
  line-search cut; the change judged by the forces within the noise).
- :class:`Limits`: the longest move of each point, as a fraction of its
  distance to its nearest other point, in length units, or as a fraction
  of the scene's size (none where the energy is quadratic: a net without
  repulsion); :func:`bound` scales a move within them (each point
  on its own, or the whole move by one factor) and :func:`reach` says how
  far along a move the first point meets its limit (:func:`reaches`: each
  point).
- :func:`trust_region`: a Newton move cut to the limits by the dogleg path
  (a definite model) or damped to ``(K + mu I)^-1 f`` with the smallest
  ``mu`` that keeps every point within its limit (Levenberg-Marquardt,
  :func:`damping`).
- :func:`trust_fraction`: a trust fraction grown or cut by the ratio of the
  energy change to the change a quadratic model predicted.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numba
import numpy as np

from ase_maud.optimize.models.base import TINY, DampedSolver
from ase_maud.physics.neighbours import NearestDistances

#: How far from 1 the ratio of an energy change to its prediction may be
#: for a trust fraction to grow (by half), and beyond which it halves.
TRUST_GOOD, TRUST_BAD = 0.25, 0.75

#: The damped move is taken once its longest point is within this fraction
#: of its limit, or the bracket of ``mu`` this narrow (in log), and
#: :data:`DAMPING_TRIALS` damped solves at most once the bracket is found
#: (the secant, then false position, in log mu; 14 bisections pinned ``mu`` to 0.2 %;
#: a coarser ``mu`` took more steps: docs/optimizer.md).
DAMPING_TOLERANCE = 2e-3
DAMPING_TRIALS = 14


@numba.njit(cache=True)
def lengths(rows: np.ndarray) -> np.ndarray:
    """Each row's length (N,) of an (N, 3) array: the formula of
    ``np.linalg.norm(rows, axis=1)`` (the squares summed in order, then the
    root), the same digits, compiled (several calls a step, each three
    array calls in numpy)."""
    out = np.empty(rows.shape[0])
    for i in range(rows.shape[0]):
        square = 0.0
        for k in range(rows.shape[1]):
            square += rows[i, k] * rows[i, k]
        out[i] = np.sqrt(square)
    return out


@numba.njit(cache=True)
def largest_length(rows: np.ndarray, origin: np.ndarray) -> float:
    """The largest length of a row of ``rows`` (N, 3) less ``origin`` (3,):
    ``lengths(rows - origin).max()``, the same digits, compiled; 0 if there
    are no rows, NaN if a row's length is."""
    largest = 0.0
    for i in range(rows.shape[0]):
        square = 0.0
        for k in range(3):
            square += (rows[i, k] - origin[k]) * (rows[i, k] - origin[k])
        length = np.sqrt(square)
        if length > largest or length != length:   # a NaN is kept: nothing is larger
            largest = length
    return largest


def merit_tolerance(merit: float, noise: float = 1e-12) -> float:
    """Slack when comparing merits: ``noise`` (relative; 1e-12 is the
    rounding of energies that sum N**2 terms) times ``|merit|``."""
    return max(noise, 1e-12) * max(abs(merit), 1e-300)


def merit_change(last_merit: float, last_noise: float, last_forces: np.ndarray,
                 move: np.ndarray, merit: float, forces: np.ndarray, noise: float,
                 energy: bool) -> tuple[float, float]:
    """The change of the merit over the step ``move`` from a point of merit
    ``last_merit`` (forces ``last_forces``, relative error ``last_noise``) to
    one of ``merit`` and ``forces`` (error ``noise``), and the slack within
    which it is no rise (the step raised the merit where ``change >
    slack``): ``(merit - last_merit, their errors)``; for an
    ``energy`` merit whose change is within the errors of both energies
    summed (each may be off by its own, so their difference by the sum),
    ``(-(last_forces + forces) . move / 2, 0)``: the trapezoid estimate from
    the forces, exact for a quadratic energy, where it is positive exactly
    when the move went beyond twice the distance to the minimum along it
    (the directional-derivative test ``g_new . p > |g_old . p|``)."""
    change = merit - last_merit
    tol = merit_tolerance(last_merit, noise + last_noise)
    if not energy or abs(change) > tol:
        return change, tol
    return work_change(last_forces, move, forces)


def work_change(last_forces: np.ndarray, move: np.ndarray,
                forces: np.ndarray) -> tuple[float, float]:
    """``(-(last_forces + forces) . move / 2, 0)``: minus the work the
    forces did over ``move`` (the trapezoid rule), and no slack. It is
    positive (an overshoot) where the forces at the end oppose the move more
    than those at its start drove it: beyond twice the distance to where
    the forces along the move balance. For forces that are the gradient of
    no merit (a band of images: the spring and tangent projections make
    ``|f|**2`` rise along ``f`` itself, so no step along the model's
    direction lowers it and a run judged by it stagnates) this is the test
    that needs the forces only."""
    return -0.5 * np.vdot(last_forces + forces, move), 0.0


def cubic_cut(last_forces: np.ndarray, move: np.ndarray, change: float,
              forces: np.ndarray) -> float:
    """The fraction of ``move`` (from a point of forces ``last_forces`` to
    one of ``forces``, over which the merit changed by ``change``:
    :func:`merit_change`) at the minimum of the cubic through both ends'
    slopes along it and that change, clipped to [0.1, 0.5] (a safe
    line-search cut)."""
    g0, g1 = -np.vdot(last_forces, move), -np.vdot(forces, move)
    d1 = g0 + g1 - 3.0 * change
    radicand = d1 * d1 - g0 * g1
    if radicand < 0 or not np.isfinite(radicand):
        return 0.5
    d2 = np.sqrt(radicand)
    denominator = g1 - g0 + 2.0 * d2
    if denominator == 0:
        return 0.5
    t = 1.0 - (g1 + d2 - d1) / denominator
    return float(np.clip(t, 0.1, 0.5)) if np.isfinite(t) else 0.5


@dataclass(frozen=True)
class Limits:
    """The longest move allowed to each point (length units): ``maxstep_nn``
    times its distance to its nearest other point (``nearest``), at most
    ``maxstep``, at most ``maxstep_size`` times the scene's size (the
    largest distance from the centroid); None: no such bound."""

    nearest: NearestDistances
    maxstep_nn: float | None = None
    maxstep: float | None = None
    maxstep_size: float | None = None
    #: Whether the energy is (now) quadratic, so that no bound applies: a
    #: net without repulsion (a = 0), whose Newton move is its minimum.
    quadratic: Callable[[], bool] | None = None

    def __call__(self, x: np.ndarray) -> np.ndarray:
        if self.quadratic is not None and self.quadratic():
            return np.full(len(x), np.inf)
        limit = (np.full(len(x), np.inf) if self.maxstep_nn is None
                 else self.maxstep_nn * self.nearest(x))
        if self.maxstep is not None:
            limit = np.minimum(limit, self.maxstep)
        if self.maxstep_size is not None and len(x) > 1:
            size = lengths(x - x.mean(axis=0)).max()
            limit = np.minimum(limit, self.maxstep_size * size)
        return limit


@numba.njit(cache=True)
def reach(start: np.ndarray, step: np.ndarray, limit: np.ndarray) -> float:
    """The largest ``t`` in [0, inf] with every point's ``|start_i + t
    step_i| <= limit_i`` (``start`` within its limits): the smallest of
    :func:`reaches` (compiled: both steps share it)."""
    return reaches(start, step, limit).min() if start.shape[0] else np.inf


@numba.njit(cache=True)
def reaches(start: np.ndarray, step: np.ndarray, limit: np.ndarray) -> np.ndarray:
    """Each point's largest ``t`` in [0, inf] with ``|start_i + t step_i| <=
    limit_i`` (``start`` within its limits; (N,)): the positive root of
    ``|start_i + t step_i|**2 = limit_i**2``, inf for a point that does not
    move, and 0 (not a negative rounding) for one on its limit moving out
    (compiled: the Python step and :mod:`.compiled_step` share it)."""
    roots = np.full(start.shape[0], np.inf)
    for i in range(start.shape[0]):
        a = b = c = 0.0
        for k in range(start.shape[1]):
            a += step[i, k] * step[i, k]
            b += start[i, k] * step[i, k]
            c += start[i, k] * start[i, k]
        c -= limit[i] ** 2
        if a > 0:
            roots[i] = max((-b + np.sqrt(max(b * b - a * c, 0.0))) / a, 0.0)
    return roots


def bound(step: np.ndarray, limit: np.ndarray, whole: bool = False) -> np.ndarray:
    """Scale each point's move down to its allowed length, or (``whole``)
    the whole move by the one factor that brings every point within its
    length (a descent direction stays one)."""
    scale = bound_factors(step, limit)
    if whole:
        return step * scale.min(initial=1.0)
    return step * scale[:, None]


@numba.njit(cache=True)
def bound_factors(step: np.ndarray, limit: np.ndarray) -> np.ndarray:
    """Each point's factor within its limit: ``limit / length`` where its
    move is longer, else 1 (:func:`bound`; compiled, the same digits)."""
    scale = lengths(step)
    for i in range(scale.shape[0]):
        scale[i] = limit[i] / scale[i] if scale[i] > limit[i] else 1.0
    return scale


@numba.njit(cache=True)
def longest(move: np.ndarray, limit: np.ndarray) -> float:
    """The largest ratio of a point's move to its limit (compiled: both
    steps share it)."""
    return (lengths(move) / limit).max() if move.shape[0] else 0.0


def trust_region(model: DampedSolver, forces: np.ndarray, newton: np.ndarray, gamma: float,
                 limit: np.ndarray) -> np.ndarray:
    """The move whose ``gamma`` times keeps every point within ``limit``:
    ``newton`` (the model's move, or its L-BFGS correction) if it does; else,
    for a definite model, the longest such move along the dogleg path (from 0
    to the Cauchy point ``(f.f / f.K f) f``, then to ``newton``); else the
    damped move ``(K + mu I)^-1 f`` with the smallest such ``mu``
    (:func:`damping`; far from a minimum this turns the step towards the
    forces instead of shortening it)."""
    if gamma * longest(newton, limit) <= 1:
        return newton
    if model.definite:
        return _dogleg(model, forces, newton, gamma, limit)
    return damping(model.damped(forces), gamma, limit, model.scale)


def _dogleg(model: DampedSolver, forces: np.ndarray, newton: np.ndarray, gamma: float,
            limit: np.ndarray) -> np.ndarray:
    curvature = np.vdot(forces, model.dot(forces))
    cauchy = forces * (np.vdot(forces, forces) / curvature) if curvature > 0 else None
    for start, end in ((np.zeros_like(forces), cauchy), (cauchy, newton)):
        if end is None:
            return forces * reach(np.zeros_like(forces), gamma * forces, limit)
        t = reach(gamma * start, gamma * (end - start), limit)
        if t < 1:
            return start + t * (end - start)
    return newton


def damping(moves: Callable[[float], np.ndarray | None], gamma: float,
            limit: np.ndarray, scale: float) -> np.ndarray:
    """The move ``moves(mu)`` (None where the damped model is not definite)
    of the smallest damping ``mu`` whose ``gamma`` times keeps every point
    within ``limit``: ``mu`` grows tenfold from ``scale`` until it does, then
    the bracket from ``1e-12`` of that is narrowed in ``log mu`` on the log
    of the longest point's ratio to its limit to :data:`DAMPING_TOLERANCE`:
    while no lower end has a move, by the secant through the last two moves
    that fit (at first the slope -1 of a move ``f / mu``; never below the
    bracket's geometric middle), then by false position (Illinois)."""
    def excess(move: np.ndarray | None) -> float:
        return np.inf if move is None else float(np.log(max(gamma * longest(move, limit), TINY)))

    high = max(scale, TINY)
    best = moves(high)
    while (f_high := excess(best)) > 0:
        high *= 10.0
        best = moves(high)
    bracket = damping_bracket(high, f_high)
    for _ in range(DAMPING_TRIALS):
        if not (mid := damping_trial(bracket)):
            break
        move = moves(mid)
        bracket = narrowed(bracket, mid, f := excess(move))
        if f <= 0:
            best = move
    return best


#: :func:`damping`'s bracket: ``(high, low, f_high, g_high, g_low, slope,
#: kept)``, the damping whose move fits and one whose move does not, the log
#: ratio of the fitting move to its limit, what false position weighs at each
#: end, the secant's slope and which end stayed at the last trial (0 none
#: yet, 1 the high end, 2 the low end).
Bracket = tuple[float, float, float, float, float, float, float]


@numba.njit(cache=True)
def damping_bracket(high: float, f_high: float) -> Bracket:
    """The bracket from ``1e-12`` of the damping ``high`` whose move fits
    (``f_high``: its log ratio to the limit, <= 0); the secant's first slope is
    that of a move ``f / mu``."""
    return high, high * 1e-12, f_high, f_high, np.inf, -1.0, 0.0


@numba.njit(cache=True)
def damping_trial(bracket: Bracket) -> float:
    """The next damping to try (0: the fitting end is within
    :data:`DAMPING_TOLERANCE` of its limit, or the bracket that narrow):
    while no lower end has a move, the secant through the last two moves
    that fit (never below the bracket's geometric middle), then false
    position (Illinois), in ``log mu``."""
    high, low, f_high, g_high, g_low, slope, _ = bracket
    if f_high >= -DAMPING_TOLERANCE or np.log(high / low) <= DAMPING_TOLERANCE:
        return 0.0
    if np.isinf(g_low):
        return max(high * np.exp(-f_high / slope), np.sqrt(low * high))
    return high * (low / high) ** (g_high / (g_high - g_low))


@numba.njit(cache=True)
def narrowed(bracket: Bracket, mid: float, f: float) -> Bracket:
    """The bracket after the trial ``mid`` whose move's log ratio is ``f``:
    its new low end if the move does not fit (``f > 0``), else its new high
    end (Illinois halves the weight of an end kept twice)."""
    high, low, f_high, g_high, g_low, slope, kept = bracket
    if f > 0:
        return high, mid, f_high, g_high * (0.5 if kept == 1.0 else 1.0), f, slope, 1.0
    if f > f_high:   # the secant of the moves that fit
        slope = (f - f_high) / np.log(mid / high)
    return mid, low, f, f, g_low * (0.5 if kept == 2.0 else 1.0), slope, 2.0


def trust_fraction(gamma: float, actual: float, predicted: float, gamma_max: float,
                   slack: float) -> float:
    """``gamma`` grown by half (at most ``gamma_max``) when the energy change
    ``actual`` is within :data:`TRUST_GOOD` of the ``predicted`` one, halved
    beyond :data:`TRUST_BAD`; unchanged when the prediction is within
    ``slack`` of zero (no ratio to judge by)."""
    if abs(predicted) <= slack:
        return gamma
    ratio = actual / predicted
    if abs(ratio - 1) <= TRUST_GOOD:
        return min(1.5 * gamma, gamma_max)
    if abs(ratio - 1) > TRUST_BAD:
        return 0.5 * gamma
    return gamma
