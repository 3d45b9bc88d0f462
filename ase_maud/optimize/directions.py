"""Which way a step goes: the directions of the strategies
(:mod:`ase_maud.optimize.strategy`), apart from how far they go
(:mod:`ase_maud.optimize.step_length`).

Moves and forces are (N, 3) arrays (forces with ASE's sign, ``-dE/dr``);
``solve`` is a local model's ``K^-1`` (:mod:`ase_maud.optimize.models.base`).

- :func:`lbfgs`: the L-BFGS two-loop recursion over secant pairs
  ``s = x_new - x_old``, ``y = f_old - f_new`` with ``K^-1`` as its initial
  inverse Hessian; with no pairs, the Newton move ``K^-1 f``;
  :func:`keeps_pair` says which pairs are safe to keep, :class:`PairRows`
  holds them as rows from step to step.
- :func:`momentum_weight`: Day's dynamic relaxation carries the last move
  over with the weight ``min(k / (k + 3), beta_max)``.
- :func:`mode_steps`, :func:`truncated_newton`, :func:`off`: eigenvector
  following along a local model's eigenpairs, and the truncated Newton
  move (Steihaug's CG) on the rest of the forces.
- :class:`ModeFollowing`: which modes a saddle search follows uphill, from
  step to step.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numba
import numpy as np

from ase_maud.optimize.step_length import lengths, reach

#: Smallest ``s.y / (|s| |y|)`` of a secant pair the L-BFGS memory keeps: the
#: cosine between ``s`` and ``H s`` for a positive-definite ``H`` is at least
#: ``2 / sqrt(cond H)``, so this keeps every pair of a Hessian conditioned up
#: to 4e10 and drops the nearly degenerate pairs of flat or non-convex
#: regions, whose ``1 / s.y`` would blow the recursion up.
MIN_PAIR_COSINE = 1e-5

#: Relative residual of the truncated Newton move (:func:`truncated_newton`),
#: and its most Hessian-vector products per step: a loose inexact Newton
#: move (0.5 rather than 0.1 took 0.6-0.7x the products of a large saddle
#: search and no more steps: docs/dev/bench/saddles.md).
NEWTON_RTOL, NEWTON_MAXITER = 0.5, 100

Pair = tuple[np.ndarray, np.ndarray]


def keeps_pair(s: np.ndarray, y: np.ndarray) -> bool:
    """Whether the secant pair ``(s, y)`` has clearly positive curvature
    (:data:`MIN_PAIR_COSINE`)."""
    return bool(np.vdot(s, y) > MIN_PAIR_COSINE * np.vdot(s, s) ** 0.5
                * np.vdot(y, y) ** 0.5)


def within_reach(pairs: Sequence[Pair], memory_reach: float) -> list[Pair]:
    """The newest of ``pairs`` (oldest first) taken near where the points are
    now: a pair is kept while the steps of the pairs after it have moved the
    points by at most ``memory_reach`` (a length) in all, each step counted by
    its longest point move (a bound on any point's travel since). The newest
    pair is always kept. A pair holds the curvature where it was taken; a
    repulsion's curvature changes over moves of its range, so a pair taken
    further back would teach the recursion the curvature of another shape."""
    kept: list[Pair] = []
    travelled = 0.0
    for s, y in reversed(pairs):
        if travelled > memory_reach:
            break
        kept.append((s, y))
        travelled += float(lengths(np.asarray(s).reshape(-1, 3)).max(initial=0.0))
    return kept[::-1]


class PairRows:
    """The L-BFGS pairs as rows of two arrays that outlive a step: each pair
    is copied in once, when it joins the memory, into a row a dropped pair
    left, where stacking the memory at every step would copy it all
    (docs/performance.md). ``rows(pairs)`` gives the
    rows of ``pairs`` (oldest first), for the pairs as they are now;
    ``store(pairs, capacity)`` gives the pairs as views of their rows, the
    memory's only copy (a run's state, which a restart file holds, keeps
    those views). A row knows its pair by the pair's ``s`` itself (held, so
    never mistaken for a new array at a freed address)."""

    def __init__(self) -> None:
        self.s = self.y = np.empty((0, 0))
        self.held: list[np.ndarray | None] = []   # the s of the pair in each row

    def rows(self, pairs: Sequence[Pair]) -> np.ndarray:
        """The row of each of ``pairs`` (oldest first), new ones copied in."""
        size = np.asarray(pairs[0][0]).size
        if self.s.shape[1] != size or len(self.held) < len(pairs):
            self.s = np.empty((len(pairs), size))
            self.y = np.empty((len(pairs), size))
            self.held = [None] * len(pairs)
        kept = [next((r for r, h in enumerate(self.held) if h is s), -1) for s, _ in pairs]
        self.held = [h if r in kept else None for r, h in enumerate(self.held)]
        for p, (s, y) in enumerate(pairs):
            if kept[p] < 0:
                kept[p] = next(r for r, h in enumerate(self.held) if h is None)
                self.s[kept[p]], self.y[kept[p]] = np.ravel(s), np.ravel(y)
                self.held[kept[p]] = s
        return np.array(kept)

    def store(self, pairs: Sequence[Pair], capacity: int) -> list[Pair]:
        """``pairs`` (oldest first, at most ``capacity``) as views of their
        rows, a pair that is not yet one copied in (the arrays given are then
        free to go): rows for ``capacity`` pairs are made at once, so that a
        view is never left on rows given up for larger ones."""
        size = np.asarray(pairs[0][0]).size
        if self.s.shape != (capacity, size):
            self.s, self.y = np.empty((capacity, size)), np.empty((capacity, size))
            self.held = [None] * capacity
        stored = []
        for row, (s, y) in zip(self.rows(pairs), pairs, strict=True):
            if s.base is not self.s:   # not yet a view of its row
                s, y = self.s[row].reshape(np.shape(s)), self.y[row].reshape(np.shape(y))
                self.held[row] = s
            stored.append((s, y))
        return stored


def lbfgs(solve: Callable[[np.ndarray], np.ndarray], forces: np.ndarray,
          pairs: Sequence[Pair], memory: PairRows | None = None) -> np.ndarray:
    """The L-BFGS direction over ``pairs`` (oldest first) with ``solve``
    (``K^-1``) as the initial inverse Hessian; ``K^-1 f`` with no pairs.
    ``memory`` keeps the pairs' rows from call to call (None: fresh rows).
    The two loops are compiled (:func:`_newest_first`, :func:`_oldest_first`):
    in numpy each pair would cost four calls."""
    if not pairs:
        return solve(forces)
    memory = PairRows() if memory is None else memory
    rows = memory.rows(pairs)
    q, alphas = _newest_first(memory.s, memory.y, rows,
                              np.asarray(forces, dtype=float).ravel())
    z = np.asarray(solve(q.reshape(forces.shape)), dtype=float).ravel()
    return _oldest_first(memory.s, memory.y, rows, alphas, z).reshape(forces.shape)


@numba.njit(cache=True)
def _newest_first(s: np.ndarray, y: np.ndarray, rows: np.ndarray,
                  forces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The two-loop recursion's first loop, pairs (rows ``rows`` of ``s``
    and ``y``, oldest first) newest first: ``alpha_i = s_i.q / s_i.y_i``,
    ``q -= alpha_i y_i``; returns ``q`` and the ``alpha``s (in ``rows``' order)."""
    q = forces.copy()
    alphas = np.empty(rows.size)
    for i in range(rows.size - 1, -1, -1):
        r = rows[i]
        sq = sy = 0.0
        for k in range(s.shape[1]):
            sq += s[r, k] * q[k]
            sy += s[r, k] * y[r, k]
        alphas[i] = sq / sy
        for k in range(s.shape[1]):
            q[k] -= alphas[i] * y[r, k]
    return q, alphas


@numba.njit(cache=True)
def _oldest_first(s: np.ndarray, y: np.ndarray, rows: np.ndarray, alphas: np.ndarray,
                  z: np.ndarray) -> np.ndarray:
    """The second loop, oldest first, from ``z = K^-1 q``: ``z += s_i
    (alpha_i - y_i.z / s_i.y_i)``; returns ``z`` (a new array)."""
    z = z.copy()
    for i in range(rows.size):
        r = rows[i]
        yz = sy = 0.0
        for k in range(s.shape[1]):
            yz += y[r, k] * z[k]
            sy += s[r, k] * y[r, k]
        beta = alphas[i] - yz / sy
        for k in range(s.shape[1]):
            z[k] += beta * s[r, k]
    return z


def momentum_weight(k: int, beta_max: float) -> float:
    """Day's momentum weight ``min(k / (k + 3), beta_max)`` (Nesterov's
    schedule; ``k`` steps since the last restart)."""
    return min(k / (k + 3.0), beta_max)


def off(move: np.ndarray, modes: np.ndarray) -> np.ndarray:
    """``move`` (N, 3) without its components along the orthonormal ``modes``
    (k, N, 3)."""
    return move - np.einsum('k,kij->ij', np.einsum('kij,ij->k', modes, move), modes)


def truncated_newton(hessian: Callable[[np.ndarray], np.ndarray],
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
        t = reach(move, step, limit)
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


def mode_steps(values: np.ndarray, gradient: np.ndarray, reach_: np.ndarray,
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
    return np.where(right, np.clip(newton, -reach_, reach_), climb * reach_)


class ModeFollowing:
    """Which ``order`` modes a saddle search follows uphill.

    At the first step: the lowest ``order`` modes, or (``mode``) the one of
    that index (ascending), or the one that overlaps most with a move (N, 3),
    with the next lowest. At every later step: the eigenvectors that overlap
    most with the modes followed so far, so the climb follows one mode as it
    softens and turns negative rather than switching to whichever is lowest;
    no negative mode is left downhill below a followed one.
    """

    def __init__(self, order: int, mode: int | np.ndarray | None = None):
        self.order, self.mode = order, mode

    def pick(self, followed: np.ndarray | None, values: np.ndarray,
             modes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The indices into ``values``/``modes`` (k, N, 3) of the modes to
        follow now, and those modes signed as followed (``followed``: the
        last step's, or None at the first)."""
        order = self.order
        if order > len(values):
            raise ValueError(f'order={order} exceeds the {len(values)} internal '
                             'modes of the scene (free moves less rigid-body ones)')
        reference = followed[:order] if followed is not None else self._start(modes)
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
        return picked, modes[picked] * np.where(signs == 0, 1.0, signs)[:, None, None]

    def guess(self) -> np.ndarray | None:
        """The move given as ``mode`` (1, N, 3), unit length, from which the
        first step's lowest modes are sought (None: an index or no mode
        given, a cold start)."""
        if self.mode is None or isinstance(self.mode, (int, np.integer)):
            return None
        norm = np.linalg.norm(self.mode)
        return self.mode[None] / norm if norm > 0 else None

    def _start(self, modes: np.ndarray) -> np.ndarray:
        order, mode = self.order, self.mode
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
