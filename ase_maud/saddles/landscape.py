"""The landscape around a minimum: the saddles a search from it finds, and
the minima each saddle joins.

:func:`landscape` searches for saddles from a minimum
(:func:`ase_maud.saddles.search.search_saddles`: climbs along each of its
``modes`` lowest Hessian modes, both ways, then ``local`` local
activations, in rounds until ``empty_rounds`` in a row find no new saddle
below an energy ``window`` if one is given (then a local activation at every
free point not yet activated), and a band of images to a second
minimum if one is given and nothing else found a saddle), relaxes from each
index-1 saddle found to the minimum on either side of its unstable mode
(:func:`ase_maud.analysis.stationary.displace_along_mode`), and returns a
:class:`Landscape`: the distinct minima and saddles and which minima each
saddle joins. Two configurations are the same (:func:`same_point`) when their
energies agree to ``energy_rtol`` (relative) and their sorted pair distances
to ``distance_atol`` (length units): that is blind to rigid motion and to
relabelling of the points (and takes mirror images as one). An attempt or
descent that fails (a :class:`~ase_maud.errors.MaudError`, no convergence
in ``steps``, its budget spent; not a local activation whose region has no
saddle) is counted in :attr:`Landscape.failed`, never silently dropped;
:attr:`Landscape.search` tells what each attempt did, and
:attr:`Landscape.cost` what the whole map computed (the search's attempts,
the start's and the saddles' Hessians, the descents) in force-call
equivalents.

The attempts are independent tasks, and so are the descents from the saddles
they find: with a ``dask.distributed`` ``Client`` (a ``LocalCluster`` on this
machine, or a scheduler of a cluster of machines) they run on its workers,
otherwise one after another in this process; the graph is the same either
way (the results are merged in the order of the tasks).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from ase import Atoms

from ase_maud.analysis.stationary import (
    DISTANCE_ATOL,
    ENERGY_RTOL,
    classify,
    displace_along_mode,
    same_point,
)
from ase_maud.checks import check_all
from ase_maud.counting import CallRecorder, Work, fresh_copy
from ase_maud.errors import MaudError
from ase_maud.optimize.maud import Maud
from ase_maud.saddles.search import SaddleSearch, check_client, run_tasks, search_saddles

#: The keys of :meth:`Landscape.todict`, in order (``ase-maud saddles``
#: replaces a JSON file of these keys only).
GRAPH_KEYS = ('minima', 'saddles', 'joins', 'barriers', 'failed')


@dataclass
class Landscape:
    """Distinct ``minima`` and index-1 ``saddles`` (Atoms with their own
    calculators, the first minimum the start), ``joins``: for each saddle
    the indices of the two minima it joins (the same one twice if both sides
    fall back into it), ``failed``: attempts and descents that ended
    elsewhere, ran out of budget or raised, ``search``: what the saddle
    search tried (:class:`~ase_maud.saddles.search.SaddleSearch`), and beside
    it, ``calls`` and ``work``: the descents' calculator calls and the
    Hessian-vector product vectors and Hessians of the descents and of the
    start's and each saddle's classification.

    Parameters
    ----------
    minima, saddles : list of Atoms
        The points, each with its own calculator (energies in ``Q a^2``).
    joins : list of (int, int)
        For each saddle, the indices in ``minima`` of the two it joins.
    failed : int
        Attempts and descents that failed.
    search : SaddleSearch or None
        What the saddle search tried.
    calls : int
        The descents' calculator calls.
    work : Work
        Hessian-vector products and Hessians beside the search's.
    """

    minima: list[Atoms] = field(default_factory=list)
    saddles: list[Atoms] = field(default_factory=list)
    joins: list[tuple[int, int]] = field(default_factory=list)
    failed: int = 0
    search: SaddleSearch | None = None
    calls: int = 0
    work: Work = field(default_factory=Work)

    @property
    def cost(self) -> int:
        """Force-call equivalents of the whole map: the search's
        (:attr:`~ase_maud.saddles.search.SaddleSearch.cost`), the descents'
        calls and the Hessian-vector product vectors and Hessians beside
        them."""
        return (0 if self.search is None else self.search.cost) + self.calls + self.work.total

    def todict(self) -> dict:
        """The graph as plain data (JSON): energies and positions of the
        minima and saddles, ``joins``, ``barriers`` and ``failed``.

        Returns
        -------
        dict
            Keys :data:`GRAPH_KEYS`; energies in ``Q a^2``, positions in the
            unit of ``a``.

        Raises
        ------
        None
            It reads the record only.
        """
        def points(atoms_list):
            return [{'energy': a.get_potential_energy(), 'positions': a.positions.tolist()}
                    for a in atoms_list]
        return dict(zip(GRAPH_KEYS, (points(self.minima), points(self.saddles),
                                     [list(pair) for pair in self.joins],
                                     [list(pair) for pair in self.barriers()],
                                     self.failed), strict=True))

    def barriers(self) -> list[tuple[float, float]]:
        """For each saddle, its energy above each of the two minima it joins
        (energy units), in the order of :attr:`joins`.

        Returns
        -------
        list of (float, float)
            The two barriers of each saddle, in ``Q a^2``.

        Raises
        ------
        None
            It reads the record only.
        """
        return [(saddle.get_potential_energy() - self.minima[i].get_potential_energy(),
                 saddle.get_potential_energy() - self.minima[j].get_potential_energy())
                for saddle, (i, j) in zip(self.saddles, self.joins, strict=True)]


def landscape(atoms: Atoms, modes: int = 2, fmax: float = 1e-6, steps: int = 1000,
              energy_rtol: float = ENERGY_RTOL, distance_atol: float = DISTANCE_ATOL,
              client: Any = None, local: int = 1, budget: int | None = None,
              seed: int = 0, partner: Atoms | None = None, mirror: bool | None = None,
              window: float | None = None, empty_rounds: int = 6,
              sweep: bool = True) -> Landscape:
    """The :class:`Landscape` around the minimum ``atoms`` (a MaudCalculator
    scene relaxed to ``fmax``; a ValueError if it is not a minimum): the
    saddles of :func:`~ase_maud.saddles.search.search_saddles`, each saddle's
    two sides relaxed, all to ``fmax`` in at most ``steps`` steps; points
    compared by :func:`same_point`.

    Parameters
    ----------
    atoms : Atoms
        A minimum with a :class:`~ase_maud.MaudCalculator` and its
        constraints, relaxed to ``fmax``.
    modes : int, default 2
        The lowest modes climbed, each both ways, a round.
    fmax : float, default 1e-6
        Convergence of every attempt and descent, ``Q a``.
    steps : int, default 1000
        Steps an attempt or descent may take.
    energy_rtol, distance_atol : float, default 1e-8, 1e-4
        When two points are one (:func:`same_point`; distances in ``a``).
    client : dask.distributed.Client or None, default None
        Workers to run the attempts and descents on (None: in this process).
    local : int, default 1
        Local activations a round, at points drawn with ``seed``.
    budget : int or None, default None
        Force-call equivalents an attempt may spend (None: no bound but
        ``steps``).
    seed : int, default 0
        The seed of the points activated.
    partner : Atoms or None, default None
        A second minimum of the scene (a dome's mirror image,
        :func:`~ase_maud.saddles.between_minima.mirrored`): if the search
        found no saddle, the one a band of images between the two reaches.
    mirror : bool or None, default None
        Take as partner ``atoms``' mirror image through the plane of its
        fixed points, relaxed only if needed; None: wherever the fixed
        points span a plane and the image is another configuration; False:
        never.
    window : float or None, default None
        A barrier above the minimum (``Q a^2``): go on in rounds until
        ``empty_rounds`` rounds in a row find no new saddle below it that
        joins the minimum (None: one round).
    empty_rounds : int, default 6
        See ``window``.
    sweep : bool, default True
        With a ``window`` and ``local`` above 0: once the rounds end, a local
        activation at every free point not yet activated (a local saddle of
        a net is reached from one to three of its points:
        :func:`~ase_maud.saddles.search.search_saddles`); False: stop with
        the rounds.

    Returns
    -------
    Landscape
        The distinct minima (the start first) and index-1 saddles, which two
        minima each saddle joins, the barriers (``Q a^2``), the failed
        attempts and descents, and the cost in force-call equivalents.

    Raises
    ------
    ValueError
        An argument outside its rule (:data:`~ase_maud.checks.RULES`, named,
        before any work); ``atoms`` not a minimum within ``fmax``; a partner
        of another scene, or ``partner`` with ``mirror=True``.
    """
    checked = check_all(modes=modes, fmax=fmax, steps=steps, energy_rtol=energy_rtol,
                        distance_atol=distance_atol)
    modes, fmax, steps = checked['modes'], checked['fmax'], checked['steps']
    energy_rtol, distance_atol = checked['energy_rtol'], checked['distance_atol']
    start = fresh_copy(atoms)
    found = Landscape(minima=[start])
    check_client(client)
    point = classify(start, ftol=np.inf, work=found.work)   # its fmax is tested here
    if point.verdict != 'minimum' or point.fmax > fmax:
        raise ValueError(f'landscape needs a minimum to start from; this is a '
                         f'{point.verdict} with fmax {point.fmax:.3g} (> {fmax:g}?): '
                         'relax it first')

    def index_of(points: list[Atoms], candidate: Atoms) -> int:
        for i, known in enumerate(points):
            if same_point(known, candidate, energy_rtol, distance_atol):
                return i
        points.append(candidate)
        return len(points) - 1

    descended: dict[int, tuple] = {}   # id of a saddle: its _descend

    def joins_start(saddle: Atoms) -> bool:
        descended[id(saddle)] = _descend(saddle, fmax, steps)
        return any(end is not None and same_point(end, start, energy_rtol, distance_atol)
                   for end in descended[id(saddle)][0])

    found.search = search_saddles(start, modes=modes, local=local, budget=budget,
                                  fmax=fmax, steps=steps, seed=seed, energy_rtol=energy_rtol,
                                  distance_atol=distance_atol, client=client, point=point,
                                  partner=partner, mirror=mirror, window=window,
                                  empty_rounds=empty_rounds, sweep=sweep,
                                  connected=None if window is None else joins_start)
    distinct = found.search.saddles   # the saddles found, each once
    found.failed += sum(a.outcome not in _NOT_FAILED for a in found.search.attempts)
    rest = [s for s in distinct if id(s) not in descended]
    descended.update(zip(map(id, rest), run_tasks(client, _descend,
                                                  [(s, fmax, steps) for s in rest]),
                         strict=True))
    for saddle in distinct:
        ends, calls, work = descended[id(saddle)]
        found.calls += calls
        found.work.hvp_vectors += work.hvp_vectors
        found.work.hessians += work.hessians
        if None in ends:   # a saddle joins what its two sides reached
            found.failed += ends.count(None)
            continue
        found.saddles.append(saddle)
        found.joins.append(tuple(index_of(found.minima, end) for end in ends))
    return found


#: Outcomes of a saddle search's attempts that are not failures: a saddle,
#: one found before, or a local activation whose region has no saddle its
#: climb reaches (an answer about the region, in the search's report; with
#: ``local=1`` by default, most nets give one)
#: (:class:`~ase_maud.saddles.attempts.Attempt`).
_NOT_FAILED = ('saddle', 'known saddle', 'known direction', 'no local saddle')
#: A descent that converges on a saddle is pushed off it along its unstable
#: mode and relaxed again at most this many times (:func:`_descend`).
PUSHES = 2


def _descend(saddle: Atoms, fmax: float, steps: int
             ) -> tuple[list[Atoms | None], int, Work]:
    """The minima relaxed to from either side of ``saddle``'s unstable mode
    (None for a side that fails), the calculator calls of the relaxations
    and the Hessian-vector product vectors and Hessians of them and of the
    classifications. A relaxation that converges on a point with a negative
    curvature (another saddle, met on the way) is pushed off it along that
    mode and relaxed again, at most :data:`PUSHES` times. An end with no
    negative curvature is a minimum even where a curvature is flatter than
    :func:`classify`'s zero tolerance (its verdict 'degenerate'): a 2D trap
    cluster whose shells turn one against the other at almost no cost."""
    ends, calls, work = [], 0, Work()
    for side in displace_along_mode(saddle, classify(saddle, ftol=fmax, work=work)):
        end = None
        for _ in range(PUSHES + 1):
            opt = Maud(side, logfile=None)
            with CallRecorder(side.calc) as recorder:
                converged = _run(opt, fmax, steps)
                point = classify(side, ftol=fmax, work=work) if converged else None
            calls += len(recorder.samples)
            work.hvp_vectors += opt.work.hvp_vectors
            work.hessians += opt.work.hessians
            if point is None or point.n_negative == 0:
                end = side if point is not None else None
                break
            side = displace_along_mode(side, point)[0]
        ends.append(end)
    return ends, calls, work


def _run(opt: Maud, fmax: float, steps: int) -> bool:
    """Whether ``opt`` converged (a MaudError, a wrong index say, is no)."""
    try:
        return bool(opt.run(fmax=fmax, steps=steps))
    except MaudError:
        return False
