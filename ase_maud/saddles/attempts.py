"""One attempt at a saddle from a minimum: a climb along a mode, a region's
climb and release, or the path to a partner minimum.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from ase import Atoms
from ase.filters import Filter
from scipy.spatial import cKDTree

from ase_maud.analysis import stationary
from ase_maud.counting import CallRecorder, cpu_seconds, fresh_copy
from ase_maud.errors import MaudError
from ase_maud.optimize.maud import Maud
from ase_maud.optimize.models.exact import EXACT_MAX_DOFS
from ase_maud.physics.dofs import free_dofs
from ase_maud.saddles.between_minima import saddle_between

#: A local region: the free points within this many times the centre
#: point's nearest-neighbour distance.
RADIUS = 2.0


#: The region grows by these factors of :data:`RADIUS` (while the exact
#: model takes it) before the whole scene is released.
GROWTH = (2.0, 4.0)


#: Steps of a region's climb (each a call and a Hessian of the region): one
#: that has not converged by then has no local saddle (a tighter bound, tried:
#: docs/dev/bench/saddles.md, "A region's first climb bounded, tried").
REGION_STEPS = 60


#: An attempt whose region's saddle lies this close in direction (cosine of
#: the moves from the minimum) to a saddle found is rejected.
SAME_DIRECTION = 0.9


@dataclass
class Attempt:
    """One attempt of a :func:`search_saddles`: its ``kind`` ('mode': a
    whole-scene climb along mode ``where`` of the minimum, ``sign`` +1 or
    -1; 'local': an activation around point ``where``; 'path': a band to
    the second minimum given, :func:`~ase_maud.saddles.between_minima.saddle_between`;
    'neighbour': a band to a minimum found where the others stopped,
    :func:`path_to_neighbour`), how it ended
    (``outcome``: 'saddle', 'known saddle', 'known direction', 'budget', 'no
    local saddle', 'steps', or the error that stopped it), the points of its last region
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
    #: the positions (N, 3) where an attempt that reached no saddle stopped
    #: (None otherwise): where :func:`path_to_neighbour` looks for another minimum
    end: np.ndarray | None = field(default=None, repr=False)

    @property
    def cost(self) -> int:
        """Calls, Hessian-vector product vectors and Hessians: force-call
        equivalents."""
        return self.calls + self.hvp_vectors + self.hessians

    def describe(self, force_call_cpu_s: float | None = None) -> str:
        """One line: what was tried, how it ended and what it cost (its CPU
        also in force calls of ``force_call_cpu_s`` CPU seconds, if given)."""
        what = {'mode': f"mode {self.where} {'+' if self.sign > 0 else '-'}",
                'path': 'path to the second minimum',
                'neighbour': 'path to a neighbouring minimum'}.get(
                    self.kind, f'local at point {self.where} ' + (
                        f'({self.region} points)' if self.region else
                        '(no region smaller than the net: the whole net climbed)'))
        in_calls = ('' if not force_call_cpu_s else
                    f' = {self.cpu_s / force_call_cpu_s:.0f} force calls\' CPU')
        return (f'{what}: {self.outcome}, {self.calls} calls + {self.hvp_vectors} HVP '
                f'vectors + {self.hessians} Hessians = {self.cost}, {self.cpu_s:.2f} CPU s'
                f'{in_calls}')


class Tally:
    """The calls, products, Hessians and CPU seconds of one attempt, and
    whether it is over its budget."""

    def __init__(self, attempt: Attempt, budget: int | None):
        self.attempt = attempt
        self.budget = np.inf if budget is None else budget
        self.cpu = cpu_seconds()

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
        attempt.cpu_s = cpu_seconds() - self.cpu
        attempt.energy = atoms.get_potential_energy()
        if outcome != 'saddle':
            attempt.end = atoms.positions.copy()
        return attempt


def climb_mode(start: Atoms, direction: np.ndarray, attempt: Attempt, fmax: float,
           steps: int, budget: int | None, whole: int | None = None,
           ) -> tuple[Atoms | None, Attempt, tuple | None]:
    """A whole-scene climb from ``start`` along ``direction`` within
    ``budget``: the saddle (else None), the attempt, and if it stopped on
    ``budget`` short of ``whole``, its continuation's arguments (else None)."""
    atoms = fresh_copy(start)
    tally = Tally(attempt, budget)
    opt = Maud(atoms, target='saddle', mode=direction, logfile=None)
    why = tally.run(opt, atoms, fmax, steps)
    attempt = tally.end(why or 'saddle', atoms)
    rest = None
    if why == 'budget' and whole is not None and whole > attempt.cost:
        along = direction if opt.state.modes is None else opt.state.modes[0].copy()
        rest = (atoms, along, Attempt('mode', attempt.where, attempt.sign), fmax, steps,
                whole - attempt.cost)
    return (None if why else atoms), attempt, rest


def climb_region(minimum: Atoms, centre: int, known: list[np.ndarray], fmax: float,
              steps: int, budget: int | None) -> tuple[Atoms | None, Attempt]:
    """A local activation around point ``centre`` of ``minimum`` (module
    docstring); ``known``: the moves from the minimum to the saddles found."""
    atoms = fresh_copy(minimum)
    tally = Tally(Attempt('local', centre), budget)
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
        mode = opt.found.modes[0]
        if factor == 1.0 and along_known(atoms.positions - x, known):
            return None, tally.end('known direction', atoms)
    # the release: the whole scene from the region's saddle along its
    # negative mode, on its dense Hessian up to the size classify takes
    # every eigenvalue at, above it Hessian-free (the springs model: LOBPCG
    # and truncated Newton on Hessian-vector products)
    small = free.sum() <= stationary.DENSE_MAX_DOFS
    opt = Maud(atoms, target='saddle', mode=mode, logfile=None,
               model='exact' if small else 'auto')
    why = tally.run(opt, atoms, fmax, steps)
    return (None if why else atoms), tally.end(why or 'saddle', atoms)


def path_to_partner(minimum: Atoms, partner: Atoms, fmax: float, relax: int | None = None,
          distance_atol: float = 0.0) -> tuple[Atoms | None, Attempt]:
    """The first verified saddle a band of images between ``minimum`` and
    ``partner`` reaches: the band's, or one a refinement from it reached
    elsewhere (:attr:`~ase_maud.saddles.between_minima.Transition.elsewhere`,
    ``saddle_between(..., any_saddle=True)``);
    ``partner`` first relaxed in at most ``relax`` steps if given (a mirror
    image: its calls and CPU seconds counted in the attempt), no path if no
    point then lies further than ``distance_atol`` from its place in
    ``minimum`` (a mirror image has the pair distances of its original, so
    :func:`~ase_maud.analysis.stationary.same_point` cannot tell them apart)."""
    attempt = Attempt('path', 0)
    if relax is not None:
        cpu = cpu_seconds()
        with CallRecorder(partner.calc) as calls:
            relaxed = Maud(partner, logfile=None).run(fmax=fmax, steps=relax)
        attempt.calls, attempt.cpu_s = len(calls.samples), cpu_seconds() - cpu
        if not relaxed:
            attempt.outcome = f'the mirror image did not relax to fmax {fmax:g} in {relax} steps'
            return None, attempt
        if np.abs(partner.positions - minimum.positions).max() <= distance_atol:
            attempt.outcome = 'the mirror image relaxed back to the minimum'
            return None, attempt
    found = saddle_between(minimum, partner, fmax=fmax, any_saddle=True)
    saddle = found.saddle if found.saddle is not None else next(iter(found.elsewhere), None)
    attempt.outcome = 'saddle' if saddle is not None else found.outcome
    attempt.calls += found.calls
    attempt.hvp_vectors, attempt.hessians = found.work.hvp_vectors, found.work.hessians
    attempt.cpu_s += found.cpu_s
    if saddle is not None:
        attempt.energy = saddle.get_potential_energy()
    else:   # where it stopped: the band's highest moving image
        top = max(found.band[1:-1], key=lambda image: image.get_potential_energy())
        attempt.energy, attempt.end = top.get_potential_energy(), top.positions.copy()
    return saddle, attempt


def path_to_neighbour(minimum: Atoms, ends: list[np.ndarray], fmax: float, steps: int,
                      energy_rtol: float, tried: tuple[float, ...] = ()
                      ) -> tuple[Atoms | None, Attempt]:
    """Where no attempt reached a saddle: the points they stopped at
    (``ends``, tried in the order given; a failed path's band its highest
    image) relaxed by Maud in at most ``steps`` steps, one after another,
    until one relaxes into another minimum (its energy apart from the
    minimum's, and from each of the energies ``tried``, a partner's whose
    path failed, by more than ``energy_rtol``, relative: not the minimum
    moved rigidly, nor along a flat valley), then the path to it
    (:func:`path_to_partner`). The relaxations' calls and CPU seconds are the
    attempt's."""
    cpu, calls, energy = cpu_seconds(), 0, minimum.get_potential_energy()
    known = (energy, *tried)
    for end in ends:
        partner = fresh_copy(minimum)
        partner.positions = end
        with CallRecorder(partner.calc) as recorded:
            try:
                relaxed = Maud(partner, logfile=None).run(fmax=fmax, steps=steps)
            except MaudError:
                relaxed = False
        calls += len(recorded.samples)
        if relaxed and all(abs(partner.get_potential_energy() - e) > energy_rtol * abs(e)
                           for e in known):
            saddle, attempt = path_to_partner(minimum, partner, fmax)
            break
    else:
        saddle, attempt = None, Attempt('path', 0, outcome=(
            f'none of the {len(ends)} points the attempts stopped at relaxed into another minimum'))
    attempt.kind = 'neighbour'
    attempt.calls += calls
    attempt.cpu_s = cpu_seconds() - cpu
    return saddle, attempt


def along_known(move: np.ndarray, known: list[np.ndarray]) -> bool:
    """Whether ``move`` points (cosine above :data:`SAME_DIRECTION`) along one
    of the ``known`` moves."""
    size = np.linalg.norm(move)
    return any(np.vdot(move, k) > SAME_DIRECTION * size * np.linalg.norm(k) for k in known)
