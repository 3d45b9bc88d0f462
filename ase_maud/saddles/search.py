"""Saddles around a minimum at any size: whole-scene climbs along its lowest
modes, then local activation (in the manner of ART nouveau), each attempt
bounded by a budget of force-call equivalents.

:func:`search_saddles` is the saddle search the landscape
(:func:`ase_maud.saddles.landscape.landscape`) and ``ase-maud saddles`` use. From a
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
   (:meth:`~ase_maud.calculator.maud_calculator.MaudCalculator.get_hessian_block`), the
   trust length a fraction of the neighbour distance per step), until that
   curvature has turned
   negative and the region's forces vanish: a saddle of the region in its
   held surroundings (within :data:`REGION_STEPS` steps, else the region
   has none). The region then grows (twice, four times the radius,
   while it has at most :data:`~ase_maud.optimize.models.exact.EXACT_MAX_DOFS` free
   coordinates), each time climbed again from where the last left off along
   its negative mode. The whole scene is then released from there along
   that mode (``Maud(target='saddle', mode=...)`` with its default model:
   above :data:`~ase_maud.optimize.models.exact.EXACT_MAX_DOFS` free
   coordinates the springs model, which follows the lowest modes by LOBPCG
   on Hessian-vector products preconditioned by the springs' stiffness and
   moves along the rest by truncated Newton: no dense Hessian of the scene)
   and converged on a verified index-1 saddle (the verification too by
   LOBPCG above :data:`~ase_maud.analysis.stationary.DENSE_MAX_DOFS`).

With an energy ``window`` these two make a round, and the search goes on
in rounds (the next ``modes`` modes, ``local`` more points) until
``empty_rounds`` rounds in a row find no new saddle whose barrier above the
minimum is below the window (and that passes a test given, ``connected``:
the landscape's asks whether it joins the minimum): until new searches stop
finding new saddles. The saddles missed lie along higher modes or where
only a local activation reaches, so a round that finds nothing is no sign
that the next will not. When the rounds end (``sweep``, the default, with
``local`` above 0), every free point not yet activated is activated once:
on the 400-point nets of docs/performance.md a local saddle below the
window is reached from one to three of the 324 free points, so neither a
count of empty rounds nor an estimate from the attempts made tells that it
is there. The sweep costs one local activation a free point.

3. **A path**, where a second minimum of the scene is given (``partner``),
   or the minimum's mirror image is another configuration (``mirror``, by
   default: through the plane of its fixed points,
   :func:`ase_maud.saddles.between_minima.reflection`, relaxed, its calls counted): a
   band of images between the two, its highest image refined to a verified
   index-1 saddle (:func:`ase_maud.saddles.between_minima.saddle_between`): a dome's
   snap-through, a whole-scene path no local push reaches. Where a
   refinement reaches a verified saddle that is not the band's (another
   barrier), the path stops there and that saddle is the attempt's. A search
   for the first ``wanted`` saddles takes the path **before** 1 and 2: on
   nets and domes held in a plane it is the attempt that finds a saddle, and
   climbs and activations before it would spend their CPU for nothing (the
   saddle families of docs/performance.md). Otherwise (every attempt, a
   window's rounds) it comes after them, if they found no saddle.
4. **A path to a neighbouring minimum**, if still none
   (:func:`ase_maud.saddles.attempts.path_to_neighbour`): the points where the
   attempts stopped (a failed path: its band's highest image), the highest
   first, relaxed one after another until one falls into another minimum
   (its energy apart from this one's, and the partner's, by more than
   ``energy_rtol``), and the band to it: a free cluster or tree whose climbs
   all ran out of budget, or a dome whose path to its mirror image failed,
   still gets the saddle between two of its minima.

An attempt is rejected, and said so, when the region's saddle lies along the
direction of a saddle already found (the cosine between the two moves from
the minimum above :data:`SAME_DIRECTION`), or when its end point is a saddle
already found (:func:`ase_maud.analysis.stationary.same_point`). Each attempt stops
once its calls, Hessian-vector product vectors and Hessians
(:class:`~ase_maud.counting.Work`) reach ``budget``; every attempt is
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

from ase_maud.analysis.stationary import StationaryPoint, classify, same_point
from ase_maud.checks import check, check_all
from ase_maud.counting import Work, cpu_seconds, fresh_copy
from ase_maud.physics.dofs import free_dofs
from ase_maud.saddles.attempts import (
    Attempt,
    climb_mode,
    climb_region,
    path_to_neighbour,
    path_to_partner,
)
from ase_maud.saddles.between_minima import check_same_scene, reflection

#: Default budget of one attempt, force-call equivalents (calls, Hessians,
#: Hessian-vector product vectors).
BUDGET = 500
#: A mode climb's first part: this share of the budget (docs/dev/bench/saddles.md,
#: "Whole-scene climbs bounded").
CLIMB_SHARE = 0.2


@dataclass
class SaddleSearch:
    """What :func:`search_saddles` found: the distinct verified index-1
    ``saddles`` (Atoms with their own calculators, in the order found), each
    :class:`Attempt` in the order made, the minimum's classification
    (``work``: what it computed, beside the attempts') and the ``rounds``
    made.

    Parameters
    ----------
    saddles : list of Atoms
        The saddles, each with its own calculator, energies in ``Q a^2``.
    attempts : list of Attempt
        Every attempt, with what it reached and cost.
    work : Work
        What classifying the minimum computed.
    rounds : int
        Rounds of attempts made.
    """

    saddles: list[Atoms] = field(default_factory=list)
    attempts: list[Attempt] = field(default_factory=list)
    work: Work = field(default_factory=Work)
    #: rounds of attempts made (one without a window)
    rounds: int = 0
    #: CPU seconds of one energy-and-forces call of the scene (a fresh
    #: calculator at the minimum, the median of three): the unit of
    #: :attr:`cpu_in_force_calls`
    force_call_cpu_s: float = float('nan')

    @property
    def cost(self) -> int:
        """Force-call equivalents of every attempt and of the minimum's modes."""
        return sum(a.cost for a in self.attempts) + self.work.total

    @property
    def cpu_s(self) -> float:
        """CPU seconds of the attempts."""
        return sum(a.cpu_s for a in self.attempts)

    @property
    def cpu_in_force_calls(self) -> float:
        """:attr:`cpu_s` in units of one energy-and-forces call of the scene
        (:attr:`force_call_cpu_s`): what the search cost, dense algebra
        included, where :attr:`cost` counts a Hessian or a product as one."""
        return self.cpu_s / self.force_call_cpu_s

    @property
    def found_by(self) -> list[Attempt]:
        """The attempts that found each of :attr:`saddles`, in its order."""
        return [next(a for a in self.attempts if a.saddle == k and a.outcome == 'saddle')
                for k in range(len(self.saddles))]

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
        no saddle says so first.

        Returns
        -------
        str
            The saddles found, the estimated coverage, the cost in force-call
            equivalents and CPU seconds, then one line per attempt.

        Raises
        ------
        None
            It reads the record only.
        """
        head = (f'{len(self.saddles)} index-1 saddles' if self.saddles
                else 'no index-1 saddle found')
        estimate = self.coverage
        coverage = ('' if estimate is None else
                    f' (estimated {estimate:.0%} of those its attempts reach)')
        lines = [f'{head}{coverage} in {len(self.attempts)} attempts ({self.rounds} '
                 f"round{'s' if self.rounds != 1 else ''}), {self.cost} force-call "
                 f'equivalents ({self.work.total} for the minimum\'s modes), '
                 f'{self.cpu_s:.2f} CPU s = {self.cpu_in_force_calls:.0f} force calls\' CPU:']
        return '\n'.join(lines + ['  ' + a.describe(self.force_call_cpu_s)
                                  for a in self.attempts])


def search_saddles(minimum: Atoms, modes: int = 1, local: int = 8, wanted: int | None = None,
                   budget: int | None = BUDGET, fmax: float = 1e-6, steps: int = 1000,
                   seed: int = 0, energy_rtol: float = 1e-8, distance_atol: float = 1e-4,
                   client: Any = None, point: StationaryPoint | None = None,
                   partner: Atoms | None = None, mirror: bool | None = None,
                   window: float | None = None, empty_rounds: int = 1,
                   connected: Callable[[Atoms], bool] | None = None,
                   sweep: bool = True) -> SaddleSearch:
    """The :class:`SaddleSearch` from the minimum ``minimum`` (a MaudCalculator
    scene relaxed to ``fmax``; see the module docstring): climbs along its
    lowest modes both ways, then local activations (a point's neighbourhood
    climbed with the rest held, then the whole released), each
    attempt within a budget of force-call equivalents; every saddle found is
    verified index 1 from a fresh calculator.

    Parameters
    ----------
    minimum : Atoms
        A minimum with a :class:`~ase_maud.MaudCalculator` and its
        constraints, relaxed to ``fmax`` (``Q a``).
    modes : int, default 1
        The lowest modes climbed, each both ways, a round.
    local : int, default 8
        Local activations a round, at points drawn with ``seed``.
    wanted : int or None, default None
        Stop once this many distinct saddles are found (None: make every
        attempt).
    budget : int or None, default ``BUDGET`` (500)
        Force-call equivalents an attempt may spend (calls, Hessian-vector
        products and Hessians); None: no bound but ``steps``.
    fmax : float, default 1e-6
        Convergence of each attempt, ``Q a``.
    steps : int, default 1000
        Steps an attempt may take.
    seed : int, default 0
        The seed of the points activated.
    energy_rtol, distance_atol : float, default 1e-8, 1e-4
        When two saddles are one
        (:func:`~ase_maud.analysis.stationary.same_point`; distances in ``a``).
    client : dask.distributed.Client or None, default None
        Workers to run the attempts on (None: in this process).
    point : StationaryPoint or None, default None
        The minimum's classification if known (else computed here, its work
        counted in :attr:`SaddleSearch.work`).
    partner : Atoms or None, default None
        A second minimum of the same scene (a dome's mirror image,
        :func:`~ase_maud.saddles.between_minima.mirrored`, say): an attempt
        joins the two by a band of images
        (:func:`~ase_maud.saddles.between_minima.saddle_between`), the first
        one where ``wanted`` is given, else the last one if the others found
        no saddle; if no attempt finds one, a minimum next to this one is
        looked for where the attempts stopped, and joined (module docstring,
        3 and 4).
    mirror : bool or None, default None
        Take as partner the mirror image of ``minimum`` through the plane of
        its fixed points (relaxed only when its path is taken); None:
        wherever no ``partner`` is given, the fixed points span a plane and
        the image is another configuration (a net sagging out of the plane
        of its supports); False: never.
    window : float or None, default None
        A barrier (``Q a^2`` above the minimum): go on in rounds (the next
        ``modes`` modes, ``local`` more points) until ``empty_rounds``
        rounds in a row find no new saddle below it, or the modes and points
        are used up (None: the first round only).
    empty_rounds : int, default 1
        See ``window``.
    connected : callable or None, default None
        A test a new saddle must pass too (the landscape's: one side of it
        relaxes into ``minimum``); None: every saddle passes.
    sweep : bool, default True
        With a ``window`` and ``local`` above 0: once the rounds end, a
        local activation at every free point not yet activated (module
        docstring); False: stop with the rounds.

    Returns
    -------
    SaddleSearch
        The distinct verified index-1 saddles (Atoms with their own
        calculators), every attempt with its cost, and the search's cost
        (:attr:`SaddleSearch.cost`, :meth:`SaddleSearch.report`).

    Raises
    ------
    ValueError
        An argument outside its rule (named, before any attempt); a
        ``partner`` that is not a configuration of the same scene; both a
        ``partner`` and ``mirror=True``; ``mirror=True`` where the fixed
        points span no plane; a minimum the calculator refuses.
    """
    checked = check_all(local=local, budget=budget, fmax=fmax, steps=steps, seed=seed,
                        energy_rtol=energy_rtol, distance_atol=distance_atol, window=window,
                        empty_rounds=empty_rounds, sweep=sweep)
    modes = check('modes', modes)
    local, budget, fmax, steps, window, empty_rounds, sweep = (
        checked[k] for k in ('local', 'budget', 'fmax', 'steps', 'window', 'empty_rounds',
                             'sweep'))
    if wanted is not None:
        wanted = check('wanted', wanted, 'count')
    check_client(client)
    if partner is not None:
        check_same_scene(minimum, partner)
    if mirror and partner is not None:
        raise ValueError('give a partner or mirror=True, not both')
    if mirror or (mirror is None and partner is None):
        partner = _mirror_image(minimum, distance_atol, required=bool(mirror))
        mirror = partner is not None   # relaxed only when its path is taken
    found = SaddleSearch(force_call_cpu_s=force_call_cpu(minimum))
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

    def activate(points: np.ndarray) -> None:   # local activations at ``points``
        for batch in _batches(list(points), client, enough):
            known = [s.positions - minimum.positions for s in found.saddles]
            merge(run_tasks(client, climb_region, [(minimum, int(c), known, fmax, steps, budget)
                                                for c in batch]))

    def path() -> None:
        merge([path_to_partner(minimum, partner, fmax, steps if mirror else None, distance_atol)])

    path_first = partner is not None and wanted is not None   # module docstring, 3
    if path_first:
        path()
    empty = 0   # rounds in a row that found no new saddle that counts
    for turn in itertools.count():   # rounds: modes [turn modes, (turn + 1) modes), ...
        if enough():   # the path found them
            break
        before = 0 if window is None else below()
        share = None if budget is None else max(1, round(CLIMB_SHARE * budget))
        climbs = [(minimum, sign * point.modes[k], Attempt('mode', k, sign), fmax, steps,
                   share, budget)
                  for k in range(turn * modes, min((turn + 1) * modes, len(point.modes)))
                  for sign in (1.0, -1.0)]
        stopped = []   # the continuations of climbs stopped at their share
        for batch in _batches(climbs, client, enough):
            results = run_tasks(client, climb_mode, batch)
            merge([(saddle, attempt) for saddle, attempt, _ in results])
            stopped += [rest for _, _, rest in results if rest is not None]
        activate(order[turn * local:(turn + 1) * local])
        for batch in _batches(stopped, client, enough):
            merge([(saddle, attempt)
                   for saddle, attempt, _ in run_tasks(client, climb_mode, batch)])
        found.rounds = turn + 1
        used_up = (turn + 1) * modes >= len(point.modes) and (turn + 1) * local >= len(free)
        empty = 0 if window is None or below() > before else empty + 1
        if window is None or enough() or used_up or empty >= empty_rounds:
            break
    if window is not None and sweep and local:   # module docstring, after 2
        activate(order[found.rounds * local:])
    if partner is not None and not path_first and not found.saddles:
        path()
    ends = sorted((a for a in found.attempts if a.end is not None), key=lambda a: -a.energy)
    if ends and not found.saddles:   # the highest first: the likeliest past a ridge
        tried = () if partner is None else (partner.get_potential_energy(),)
        merge([path_to_neighbour(minimum, [a.end for a in ends], fmax, steps, energy_rtol,
                                 tried)])
    return found


def _mirror_image(minimum: Atoms, distance_atol: float, required: bool) -> Atoms | None:
    """``minimum``'s mirror image through the plane of its fixed points
    (:func:`~ase_maud.saddles.between_minima.reflection`); unless
    ``required``, None where the fixed points span no plane or the image is
    ``minimum`` again (a flat scene), else the ValueError of the former."""
    try:
        image = reflection(minimum)
    except ValueError:
        if required:
            raise
        return None
    moved = np.abs(image.positions - minimum.positions).max(initial=0.0)
    return image if required or moved > distance_atol else None


def force_call_cpu(atoms: Atoms, repeat: int = 3) -> float:
    """CPU seconds of one energy-and-forces call of ``atoms``' scene: the
    median of ``repeat`` calls of a fresh calculator there (the kernels
    compiled first), the unit of :attr:`SaddleSearch.cpu_in_force_calls`."""
    copy = fresh_copy(atoms)
    copy.get_forces()
    times = []
    for _ in range(repeat):
        copy.calc.reset()
        start = cpu_seconds()
        copy.get_forces()
        times.append(cpu_seconds() - start)
    return max(float(np.median(times)), time.get_clock_info('process_time').resolution)


def check_client(client: Any) -> None:
    """A ValueError naming ``client`` unless it is None or has what the
    search asks of a ``dask.distributed`` client (``submit``, ``gather``,
    ``scheduler_info``)."""
    needed = ('submit', 'gather', 'scheduler_info')
    if client is not None and not all(callable(getattr(client, n, None)) for n in needed):
        raise ValueError(f'client must be None or a dask.distributed Client (with '
                         f'{", ".join(needed)}), got {client!r}')


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


