"""Saddles around a minimum at any size: whole-scene climbs along its lowest
modes, then local activation (in the manner of ART nouveau), each attempt
bounded by a budget of force-call equivalents.

:func:`search_saddles` is the saddle search the landscape
(:func:`ase_maud.landscape.landscape`) and ``ase-maud saddles`` use. From a
minimum it makes, in order:

1. **Mode climbs**: ``Maud(target='saddle', mode=...)`` along each of the
   minimum's ``modes`` lowest Hessian modes, both ways (what the landscape
   did before local activation), first within :data:`CLIMB_SHARE` of the
   budget each, continued with the rest after the local attempts.
2. **Local activations** from ``local`` points drawn (seeded) among the
   free ones. The point and its neighbourhood (the free points within
   :data:`RADIUS` times the point's nearest-neighbour distance) are climbed
   along their lowest curvature with the rest of the scene held
   (``Maud(Filter(atoms, indices=region), target='saddle')``: eigenvector
   following on the Hessian's block on the region, computed alone
   (:meth:`~ase_maud.calculator.MaudCalculator.get_hessian_block`), the
   trust length a fraction of the neighbour distance per step), until that
   curvature has turned
   negative and the region's forces vanish: a saddle of the region in its
   held surroundings (within :data:`REGION_STEPS` steps, else the region
   has none). The region then grows (twice, four times the radius,
   while it has at most :data:`~ase_maud.stiffness.EXACT_MAX_DOFS` free
   coordinates), each time climbed again from where the last left off along
   its negative mode. The whole scene is then released from there along
   that mode (``Maud(target='saddle', mode=...)``) and converged on a
   verified index-1 saddle: with the exact model (eigenvector following on
   the whole scene's dense Hessian: one call and one Hessian a step) while
   the scene has at most :data:`RELEASE_EXACT_MAX_DOFS` free coordinates
   (above :data:`RELEASE_CAP_DOFS`, at most :data:`RELEASE_CAP_STEPS` steps).
   Above that, the rest of the scene is first relaxed with the region
   held, and the region climbed again, in turn, while that converges: to a
   saddle of the whole scene (verified: ``classify``), or else, where it
   stops converging, released with the springs model (minimum-mode
   following, its lowest modes from LOBPCG on Hessian-vector products,
   started from the region's negative mode).

With an energy ``window`` these two make a round, and the search goes on
in rounds (the next ``modes`` modes, ``local`` more points) until
``empty_rounds`` rounds in a row find no new saddle whose barrier above the
minimum is below the window (and that passes a test given, ``connected``:
the landscape's asks whether it joins the minimum): until new searches stop
finding new saddles. The saddles missed lie along higher modes or where
only a local activation reaches, so a round that finds nothing is no sign
that the next will not.

3. **A path**, if none of these found a saddle and a second minimum of the
   scene is given (``partner``), or asked for as the minimum's mirror image
   (``mirror``: through the plane of its fixed points,
   :func:`ase_maud.transition.reflection`, relaxed, its calls counted): a
   band of images between the two, its highest image refined to a verified
   index-1 saddle (:func:`ase_maud.transition.saddle_between`): a dome's
   snap-through, a whole-scene path no local push reaches. Where the
   refinement reached a verified saddle that is not the band's (another
   barrier), that saddle is the attempt's.

An attempt is rejected, and said so, when the region's saddle lies along the
direction of a saddle already found (the cosine between the two moves from
the minimum above :data:`SAME_DIRECTION`), or when its end point is a saddle
already found (:func:`ase_maud.analysis.same_point`). Each attempt stops
once its calls, Hessian-vector product vectors and Hessians
(:class:`~ase_maud.analysis.Work`) reach ``budget``; every attempt is
reported (:class:`Attempt`), and a search that found nothing says what it
tried (:meth:`SaddleSearch.report`). The mode climbs, and the local
activations, are independent tasks: with a ``dask.distributed`` client they
run on its workers (the direction of a saddle found by another task of the
same batch is then not known to an attempt: the point it reaches still is).
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from ase import Atoms
from ase.filters import Filter
from scipy.spatial import cKDTree

from .analysis import StationaryPoint, Work, classify, same_point
from .bench.runner import CallRecorder, fresh_copy
from .checks import check, check_all
from .dofs import free_dofs
from .monitor import MaudError
from .optimizer import Maud
from .stiffness import EXACT_MAX_DOFS
from .transition import check_same_scene, reflection, saddle_between

#: A local region: the free points within this many times the centre
#: point's nearest-neighbour distance.
RADIUS = 2.0
#: The region grows by these factors of :data:`RADIUS` (while the exact
#: model takes it) before the whole scene is released.
GROWTH = (2.0, 4.0)
#: Steps of a region's climb (each a call and a Hessian of the region): one
#: that has not converged by then has no local saddle (a tighter bound, tried:
#: docs/bench/saddles.md, "A region's first climb bounded, tried").
REGION_STEPS = 60
#: The surroundings of a region's saddle are relaxed with the region held (to
#: this fraction of the largest force before), and the region climbed again,
#: in turn (at most this many times, each run at most this many steps),
#: while each turn cuts the largest force by this factor at least.
SETTLE_RATIO, SETTLE_CYCLES, SETTLE_STEPS, SETTLE_GAIN = 0.1, 40, 20, 0.8
#: The whole scene is released from a region's saddle with the exact model
#: (a dense Hessian and its eigen-decomposition a step) up to this many free
#: coordinates, above it with the springs model after settling the
#: surroundings (the measurements that set it: docs/bench/saddles.md,
#: "Released with the exact model" and "Above 1500 free coordinates").
RELEASE_EXACT_MAX_DOFS = 3000
#: Above this many free coordinates the exact release stops (outcome 'exact
#: release steps') after this many steps: a step costs seconds there, so one
#: that wanders would take hundreds within the budget (docs/bench/saddles.md,
#: "The exact release capped").
RELEASE_CAP_DOFS, RELEASE_CAP_STEPS = 1500, 60
#: An attempt whose region's saddle lies this close in direction (cosine of
#: the moves from the minimum) to a saddle found is rejected.
SAME_DIRECTION = 0.9
#: Default budget of one attempt, force-call equivalents (calls, Hessians,
#: Hessian-vector product vectors).
BUDGET = 500
#: A mode climb's first part: this share of the budget (docs/bench/saddles.md,
#: "Whole-scene climbs bounded").
CLIMB_SHARE = 0.2


@dataclass
class Attempt:
    """One attempt of a :func:`search_saddles`: its ``kind`` ('mode': a
    whole-scene climb along mode ``where`` of the minimum, ``sign`` +1 or
    -1; 'local': an activation around point ``where``; 'path': a band to
    the second minimum given, :func:`~ase_maud.transition.saddle_between`), how it ended
    (``outcome``: 'saddle', 'known saddle', 'known direction', 'budget', 'no
    local saddle', 'steps', 'exact release steps' (:data:`RELEASE_CAP_STEPS`),
    or the error that stopped it), the points of its last region
    (``region``, local ones), what it computed (``calls``, ``hvp_vectors``,
    ``hessians``) and its CPU seconds, and the energy it ended at (a
    saddle's, or where it stopped)."""

    kind: str
    where: int
    sign: float = 1.0
    outcome: str = ''
    region: int = 0
    calls: int = 0
    hvp_vectors: int = 0
    hessians: int = 0
    cpu_s: float = 0.0
    energy: float = float('nan')
    #: the index in :attr:`SaddleSearch.saddles` of the saddle it reached
    #: ('saddle' or 'known saddle'; None otherwise)
    saddle: int | None = None

    @property
    def cost(self) -> int:
        """Calls, Hessian-vector product vectors and Hessians: force-call
        equivalents."""
        return self.calls + self.hvp_vectors + self.hessians

    def describe(self) -> str:
        """One line: what was tried, how it ended and what it cost."""
        what = {'mode': f"mode {self.where} {'+' if self.sign > 0 else '-'}",
                'path': 'path to the second minimum'}.get(
                    self.kind, f'local at point {self.where} ({self.region} points)')
        return (f'{what}: {self.outcome}, {self.calls} calls + {self.hvp_vectors} HVP '
                f'vectors + {self.hessians} Hessians = {self.cost}, {self.cpu_s:.2f} CPU s')


@dataclass
class SaddleSearch:
    """What :func:`search_saddles` found: the distinct verified index-1
    ``saddles`` (Atoms with their own calculators, in the order found), each
    :class:`Attempt` in the order made, the minimum's classification
    (``work``: what it computed, beside the attempts') and the ``rounds``
    made."""

    saddles: list[Atoms] = field(default_factory=list)
    attempts: list[Attempt] = field(default_factory=list)
    work: Work = field(default_factory=Work)
    #: rounds of attempts made (one without a window)
    rounds: int = 0

    @property
    def cost(self) -> int:
        """Force-call equivalents of every attempt and of the minimum's modes."""
        return sum(a.cost for a in self.attempts) + self.work.total

    @property
    def cpu_s(self) -> float:
        """CPU seconds of the attempts."""
        return sum(a.cpu_s for a in self.attempts)

    @property
    def coverage(self) -> float | None:
        """The estimated share of the saddles this search's attempts reach
        that it found: Good and Turing's ``1 - f1 / n`` over the ``n``
        attempts that reached a saddle, ``f1`` of the saddles reached by one
        attempt only (a saddle met once suggests others not met yet); None
        before any attempt reached one. An estimate for attempts drawn alike:
        saddles no kind of attempt made here can reach are not in it."""
        reached = np.bincount([a.saddle for a in self.attempts if a.saddle is not None],
                              minlength=len(self.saddles))
        if not reached.sum():
            return None
        return 1.0 - float((reached == 1).sum()) / float(reached.sum())

    def report(self) -> str:
        """What was found and tried, one attempt a line; a search that found
        no saddle says so first."""
        head = (f'{len(self.saddles)} index-1 saddles' if self.saddles
                else 'no index-1 saddle found')
        estimate = self.coverage
        coverage = ('' if estimate is None else
                    f' (estimated {estimate:.0%} of those its attempts reach)')
        lines = [f'{head}{coverage} in {len(self.attempts)} attempts ({self.rounds} '
                 f"round{'s' if self.rounds != 1 else ''}), {self.cost} force-call "
                 f'equivalents ({self.work.total} for the minimum\'s modes), '
                 f'{self.cpu_s:.2f} CPU s:']
        return '\n'.join(lines + ['  ' + a.describe() for a in self.attempts])


def search_saddles(minimum: Atoms, modes: int = 1, local: int = 8, wanted: int | None = None,
                   budget: int | None = BUDGET, fmax: float = 1e-6, steps: int = 1000,
                   seed: int = 0, energy_rtol: float = 1e-8, distance_atol: float = 1e-4,
                   client: Any = None, point: StationaryPoint | None = None,
                   partner: Atoms | None = None, mirror: bool = False,
                   window: float | None = None, empty_rounds: int = 1,
                   connected: Callable[[Atoms], bool] | None = None) -> SaddleSearch:
    """The :class:`SaddleSearch` from the minimum ``minimum`` (a MaudCalculator
    scene relaxed to ``fmax``; see the module docstring): climbs along its
    ``modes`` lowest modes both ways, then ``local`` activations at points
    drawn with ``seed``, each attempt to ``fmax`` within ``steps`` steps
    and ``budget`` force-call equivalents (None: no bound but the steps); it
    stops once ``wanted`` distinct saddles are found (None: every attempt
    is made). Saddles are compared by
    :func:`~ase_maud.analysis.same_point` with ``energy_rtol`` and
    ``distance_atol``. ``point``: the minimum's classification if known
    (else computed here, its work counted in :attr:`SaddleSearch.work`).
    ``client``: a ``dask.distributed`` client whose workers run the
    attempts. ``partner``: a second minimum of the scene (a dome's mirror
    image, :func:`~ase_maud.transition.mirrored`, say); if the attempts
    found no saddle, a last one joins the two by a band of images
    (:func:`~ase_maud.transition.saddle_between`; no budget but its own
    steps; a partner that is not a configuration of the same scene is a
    ValueError before any attempt, :func:`~ase_maud.transition.check_same_scene`).
    ``mirror``: the second minimum is ``minimum``'s mirror image through
    the plane of its fixed points (a ValueError before any attempt if they
    span none, or with a ``partner`` too), relaxed to ``fmax`` within
    ``steps`` only if the attempts found no saddle (the path's attempt
    counts its calls; if it relaxes back to ``minimum`` there is no path).
    ``window``: a barrier (energy units, above the minimum): the
    search goes on in rounds like the first (the next ``modes`` modes both
    ways, ``local`` more points) until ``empty_rounds`` rounds in a row find
    no new saddle whose barrier is below it, or the modes (those of
    ``point``) and the free points are used up (None: the first round
    only); ``connected``: a test
    a new saddle must pass too, asked once a saddle (the landscape's: one
    side of it relaxes into ``minimum``; None: every saddle passes).
    Arguments are checked first (a ValueError names a bad one)."""
    checked = check_all(local=local, budget=budget, fmax=fmax, steps=steps, seed=seed,
                        energy_rtol=energy_rtol, distance_atol=distance_atol, window=window,
                        empty_rounds=empty_rounds)
    modes = check('modes', modes)
    local, budget, fmax, steps, window, empty_rounds = (
        checked[k] for k in ('local', 'budget', 'fmax', 'steps', 'window', 'empty_rounds'))
    if wanted is not None:
        wanted = check('wanted', wanted, 'count')
    if partner is not None:
        check_same_scene(minimum, partner)
    if mirror:
        if partner is not None:
            raise ValueError('give a partner or mirror=True, not both')
        partner = reflection(minimum)   # relaxed only if the attempts find nothing
    found = SaddleSearch()
    if point is None:
        point = classify(minimum, ftol=np.inf, work=found.work)

    def enough() -> bool:
        return wanted is not None and len(found.saddles) >= wanted

    def merge(results: list[tuple[Atoms | None, Attempt]]) -> None:
        for saddle, attempt in results:
            if saddle is not None:
                known = next((i for i, s in enumerate(found.saddles)
                              if same_point(s, saddle, energy_rtol, distance_atol)), None)
                if known is not None:
                    attempt.outcome, attempt.saddle = 'known saddle', known
                elif not enough():
                    attempt.saddle = len(found.saddles)
                    found.saddles.append(saddle)
            found.attempts.append(attempt)

    free = np.flatnonzero(free_dofs(minimum, minimum.calc.potential.dim).any(axis=1))
    order = np.random.default_rng(seed).permutation(free)
    energy = minimum.get_potential_energy()

    judged: list[bool] = []   # for each saddle found, whether it counts

    def below() -> int:   # the saddles found that count: below the window, connected
        for saddle in found.saddles[len(judged):]:
            judged.append(bool(saddle.get_potential_energy() - energy < window
                               and (connected is None or connected(saddle))))
        return sum(judged)

    empty = 0   # rounds in a row that found no new saddle that counts
    for turn in itertools.count():   # rounds: modes [turn modes, (turn + 1) modes), ...
        before = 0 if window is None else below()
        share = None if budget is None else max(1, round(CLIMB_SHARE * budget))
        climbs = [(minimum, sign * point.modes[k], Attempt('mode', k, sign), fmax, steps,
                   share, budget)
                  for k in range(turn * modes, min((turn + 1) * modes, len(point.modes)))
                  for sign in (1.0, -1.0)]
        stopped = []   # the continuations of climbs stopped at their share
        for batch in _batches(climbs, client, enough):
            results = run_tasks(client, _climb, batch)
            merge([(saddle, attempt) for saddle, attempt, _ in results])
            stopped += [rest for _, _, rest in results if rest is not None]
        for batch in _batches(list(order[turn * local:(turn + 1) * local]), client, enough):
            known = [s.positions - minimum.positions for s in found.saddles]
            merge(run_tasks(client, _activate, [(minimum, int(c), known, fmax, steps, budget)
                                                for c in batch]))
        for batch in _batches(stopped, client, enough):
            merge([(saddle, attempt) for saddle, attempt, _ in run_tasks(client, _climb, batch)])
        found.rounds = turn + 1
        used_up = (turn + 1) * modes >= len(point.modes) and (turn + 1) * local >= len(free)
        empty = 0 if window is None or below() > before else empty + 1
        if window is None or enough() or used_up or empty >= empty_rounds:
            break
    if partner is not None and not found.saddles:
        merge([_path(minimum, partner, fmax, steps if mirror else None, distance_atol)])
    return found


def _batches(tasks: list, client: Any, enough: Callable[[], bool]):
    """``tasks`` in batches, one task each in this process, as many as the
    workers of ``client`` otherwise, until ``enough()``."""
    size = 1 if client is None else max(len(client.scheduler_info()['workers']), 1)
    for start in range(0, len(tasks), size):
        if enough():
            return
        yield tasks[start:start + size]


def run_tasks(client: Any, task: Callable, arguments: list[tuple]) -> list:
    """``task(*a)`` for each ``a`` of ``arguments``, in their order: on the
    workers of ``client`` if given, else here."""
    if client is None:
        return [task(*a) for a in arguments]
    return client.gather([client.submit(task, *a, pure=False) for a in arguments])


class _Tally:
    """The calls, products, Hessians and CPU seconds of one attempt, and
    whether it is over its budget."""

    def __init__(self, attempt: Attempt, budget: int | None):
        self.attempt = attempt
        #: the negative mode the attempt follows (N, 3), once it has one
        self.mode: np.ndarray | None = None
        self.budget = np.inf if budget is None else budget
        self.cpu = time.process_time()

    def run(self, opt: Maud, atoms: Atoms, fmax: float, steps: int) -> str:
        """Run ``opt`` to ``fmax`` in at most ``steps`` steps within the
        budget; '' if it converged on the index sought, else why not."""
        attempt, why = self.attempt, 'steps'
        with CallRecorder(atoms.calc) as calls:
            try:
                for converged in opt.irun(fmax=fmax, steps=steps):
                    if converged:
                        why = ''
                        break
                    if attempt.cost + len(calls.samples) + opt.work.total >= self.budget:
                        why = 'budget'
                        break
            except MaudError as error:
                why = f'{type(error).__name__}: {str(error).splitlines()[0][:100]}'
        attempt.calls += len(calls.samples)
        attempt.hvp_vectors += opt.work.hvp_vectors
        attempt.hessians += opt.work.hessians
        return why

    def end(self, outcome: str, atoms: Atoms) -> Attempt:
        attempt = self.attempt
        attempt.outcome = outcome
        attempt.cpu_s = time.process_time() - self.cpu
        attempt.energy = atoms.get_potential_energy()
        return attempt


def _climb(start: Atoms, direction: np.ndarray, attempt: Attempt, fmax: float,
           steps: int, budget: int | None, whole: int | None = None,
           ) -> tuple[Atoms | None, Attempt, tuple | None]:
    """A whole-scene climb from ``start`` along ``direction`` within
    ``budget``: the saddle (else None), the attempt, and if it stopped on
    ``budget`` short of ``whole``, its continuation's arguments (else None)."""
    atoms = fresh_copy(start)
    tally = _Tally(attempt, budget)
    opt = Maud(atoms, target='saddle', mode=direction, logfile=None)
    why = tally.run(opt, atoms, fmax, steps)
    attempt = tally.end(why or 'saddle', atoms)
    rest = None
    if why == 'budget' and whole is not None and whole > attempt.cost:
        along = direction if opt.state.modes is None else opt.state.modes[0].copy()
        rest = (atoms, along, Attempt('mode', attempt.where, attempt.sign), fmax, steps,
                whole - attempt.cost)
    return (None if why else atoms), attempt, rest


def _activate(minimum: Atoms, centre: int, known: list[np.ndarray], fmax: float,
              steps: int, budget: int | None) -> tuple[Atoms | None, Attempt]:
    """A local activation around point ``centre`` of ``minimum`` (module
    docstring); ``known``: the moves from the minimum to the saddles found."""
    atoms = fresh_copy(minimum)
    tally = _Tally(Attempt('local', centre), budget)
    x = minimum.positions
    free = free_dofs(atoms, atoms.calc.potential.dim)
    movable = free.any(axis=1)
    tree = cKDTree(x)
    reach = tree.query(x[centre], k=2)[0][1]
    mode = None
    for factor in (1.0, *GROWTH):
        region = np.array(sorted(tree.query_ball_point(x[centre], factor * RADIUS * reach)))
        region = region[movable[region]]
        if free[region].sum() > EXACT_MAX_DOFS or region.size == movable.sum():
            break
        opt = Maud(Filter(atoms, indices=region), target='saddle', logfile=None,
                   mode=None if mode is None else mode[region])
        tally.attempt.region = int(region.size)
        why = tally.run(opt, atoms, fmax, REGION_STEPS)
        if why:
            return None, tally.end('no local saddle' if why == 'steps' else why, atoms)
        mode, held = opt.found.modes[0], region
        if factor == 1.0 and _along(atoms.positions - x, known):
            return None, tally.end('known direction', atoms)
    exact = free.sum() <= RELEASE_EXACT_MAX_DOFS
    if mode is not None and not exact:
        saddle = _settle(atoms, tally, held, np.setdiff1d(np.flatnonzero(movable), held),
                         mode, fmax)
        if isinstance(saddle, str):
            return None, tally.end(saddle, atoms)
        if saddle is not None:
            return atoms, tally.end('saddle', atoms)
        mode = tally.mode
    opt = Maud(atoms, target='saddle', mode=mode, logfile=None,
               model='exact' if exact else 'auto')
    cap = min(steps, RELEASE_CAP_STEPS) if exact and free.sum() > RELEASE_CAP_DOFS else steps
    why = tally.run(opt, atoms, fmax, cap)
    if why == 'steps' and cap < steps:
        why = 'exact release steps'
    return (None if why else atoms), tally.end(why or 'saddle', atoms)


def _settle(atoms: Atoms, tally: _Tally, held: np.ndarray, rest: np.ndarray,
            mode: np.ndarray, fmax: float) -> Atoms | str | None:
    """From the saddle of the region ``held`` (its negative mode ``mode``),
    the ``rest`` relaxed with the region held and the region climbed again,
    in turn, at most :data:`SETTLE_CYCLES` times: ``atoms`` if that
    converges (largest force below ``fmax``) on a verified index-1 saddle,
    why not if it fails (the budget spent, the region's saddle lost), else
    None (the whole scene is then released from there along
    ``tally.mode``)."""
    largest = np.linalg.norm(atoms.get_forces(), axis=1).max()
    tally.mode = mode
    for _ in range(SETTLE_CYCLES):
        if tally.run(Maud(Filter(atoms, indices=rest), logfile=None), atoms,
                     max(fmax, SETTLE_RATIO * largest), SETTLE_STEPS) == 'budget':
            return 'budget'
        opt = Maud(Filter(atoms, indices=held), target='saddle', mode=tally.mode[held],
                   logfile=None)
        why = tally.run(opt, atoms, fmax, SETTLE_STEPS)
        if why:
            return f'region lost while settling ({why})'
        tally.mode = opt.found.modes[0]
        settled = np.linalg.norm(atoms.get_forces(), axis=1).max()
        if settled < fmax:
            work = Work()
            point = classify(atoms, ftol=fmax, work=work)
            tally.attempt.hvp_vectors += work.hvp_vectors
            tally.attempt.hessians += work.hessians
            return atoms if point.index == 1 and not point.n_zero else None
        if settled > SETTLE_GAIN * largest:   # no longer converging: release
            return None
        largest = settled
    return None


def _path(minimum: Atoms, partner: Atoms, fmax: float, relax: int | None = None,
          distance_atol: float = 0.0) -> tuple[Atoms | None, Attempt]:
    """The saddle between ``minimum`` and ``partner`` by a band of images (or,
    if none, the first verified saddle a refinement from the band reached
    elsewhere: :attr:`~ase_maud.transition.Transition.elsewhere`);
    ``partner`` first relaxed in at most ``relax`` steps if given (a mirror
    image: its calls and CPU seconds counted in the attempt), no path if no
    point then lies further than ``distance_atol`` from its place in
    ``minimum`` (a mirror image has the pair distances of its original, so
    :func:`~ase_maud.analysis.same_point` cannot tell them apart)."""
    attempt = Attempt('path', 0)
    if relax is not None:
        cpu = time.process_time()
        with CallRecorder(partner.calc) as calls:
            relaxed = Maud(partner, logfile=None).run(fmax=fmax, steps=relax)
        attempt.calls, attempt.cpu_s = len(calls.samples), time.process_time() - cpu
        if not relaxed:
            attempt.outcome = f'the mirror image did not relax to fmax {fmax:g} in {relax} steps'
            return None, attempt
        if np.abs(partner.positions - minimum.positions).max() <= distance_atol:
            attempt.outcome = 'the mirror image relaxed back to the minimum'
            return None, attempt
    found = saddle_between(minimum, partner, fmax=fmax)
    saddle = found.saddle if found.saddle is not None else next(iter(found.elsewhere), None)
    attempt.outcome = 'saddle' if saddle is not None else found.outcome
    attempt.calls += found.calls
    attempt.hvp_vectors, attempt.hessians = found.work.hvp_vectors, found.work.hessians
    attempt.cpu_s += found.cpu_s
    if saddle is not None:
        attempt.energy = saddle.get_potential_energy()
    return saddle, attempt


def _along(move: np.ndarray, known: list[np.ndarray]) -> bool:
    """Whether ``move`` points (cosine above :data:`SAME_DIRECTION`) along one
    of the ``known`` moves."""
    size = np.linalg.norm(move)
    return any(np.vdot(move, k) > SAME_DIRECTION * size * np.linalg.norm(k) for k in known)

