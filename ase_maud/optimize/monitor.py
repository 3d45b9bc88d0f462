"""A run that cannot go on: divergence and stagnation, watched step by step;
a scene with no equilibrium, seen before the first step.

:class:`RunMonitor` knows nothing of Maud's step: any optimiser can call
:meth:`RunMonitor.check` once per step with the positions, the merit, the
forces and its step factor, and gets a :class:`DivergenceError` or a
:class:`StagnationError` (both :class:`MaudError`) whose message says what was
observed. Its state goes into a restart file (:meth:`RunMonitor.todict`).

- Divergence, only for a scene of a :class:`MaudCalculator`
  (:func:`divergence_judged`; another calculator's run ends by fmax, steps
  or stagnation, as ASE's optimizers' do) and only where no finite minimum
  is proved (``bounded`` False; a scene whose calculator proves one,
  ``calc.potential.minimum_proved``, is on its way there however far it spreads, and
  only the stagnation rules apply).
  The run is judged by its forces as it grows: each time the scene's
  extent (the larger of its size, the largest distance from the centroid,
  and the drift of its centroid) grows by ``divergence_factor`` again over
  its reference ``max(start size, a N)``, the move since the last such mark
  and the forces' change over it give the secant curvature along the move,
  and with the forces now, how much further on they would balance
  (:func:`balance_ahead`; exact for springs and loads, whose energy is
  quadratic). A run that at :data:`DIVERGENCE_PASSES` successive marks
  either moved past the balance predicted at the mark before or saw it no
  nearer (relative to its move) has no balance in reach: a constant force
  with nothing holding the scene shows no curvature (balance nowhere); a
  repulsion with nothing holding it shows a balance that recedes as the run
  goes. ``divergence_factor=inf`` switches the test off. A scene
  proved to have no finite equilibrium is stopped before its first step
  instead (:class:`NoEquilibriumError`, raised by the optimiser).
- Stagnation: ``gamma`` (the optimiser's step factor) underflowed, every
  step having been taken back; or no progress for ``patience`` steps,
  progress being fmax falling by 0.1 % below its best and, for
  ``target='minimum'``, the merit (the energy) falling below its lowest by
  more than its error and by more than :data:`ENERGY_PROGRESS` times fmax
  times the scene's size (what the forces could release over a move of that
  size): progress on the run's own scale of energy and length, so that a run
  creeping down at any scale is caught.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numba
import numpy as np
from ase import Atoms

from ase_maud.calculator.maud_calculator import MaudCalculator
from ase_maud.checks import as_number, as_whole
from ase_maud.errors import DivergenceError, NoEquilibriumError, StagnationError
from ase_maud.optimize.step_length import largest_length

#: fmax counts as progress when it falls below ``(1 - FMAX_PROGRESS)`` of its
#: best so far.
FMAX_PROGRESS = 1e-3
#: The energy counts as progress when it falls below its lowest by more than
#: this fraction of ``fmax * size`` (and by more than its error).
ENERGY_PROGRESS = 1e-3
#: Successive marks (growths of the scene by ``divergence_factor``) at which
#: the scene outran the extent its forces predicted for their balance before
#: the run counts as divergent.
DIVERGENCE_PASSES = 2
#: ``gamma`` has underflowed below this fraction of its start.
GAMMA_UNDERFLOW = 1e-12


def balance_ahead(move: np.ndarray, pull: np.ndarray, forces: np.ndarray) -> float:
    """How far on along ``move`` (the positions' change since the last mark,
    ``pull`` the forces' change over it) the forces now acting (``forces``,
    minus the energy's gradient) would balance, by the secant curvature
    ``-pull . move / |move|^2`` (exact for springs and loads, whose energy is
    quadratic): a length in the units of the positions; 0 if the forces
    already pull back, inf if nothing was seen to slow the run (no positive
    curvature along the move)."""
    length = float(np.linalg.norm(move))
    if length == 0:
        return np.inf
    unit = move / length
    push = float(np.vdot(forces, unit))
    curvature = -float(np.vdot(pull, unit)) / length
    if push <= 0:
        return 0.0
    return push / curvature if curvature > 0 else np.inf


@numba.njit(cache=True)
def measures(x: np.ndarray, forces: np.ndarray) -> tuple[np.ndarray, float, float]:
    """What :meth:`RunMonitor.check` watches at a step, in one compiled pass:
    the centroid (3,) of the points ``x`` (N, 3), the largest distance of a
    point from it and the largest force's length (``forces`` (N, 3); 0 if
    none). The sums are numpy's (``x.sum(axis=0) / N``, the rows' lengths),
    in the same order; a NaN anywhere is the result's."""
    n = x.shape[0]
    centre = np.zeros(3)
    for i in range(n):
        for k in range(3):
            centre[k] += x[i, k]
    if n:
        centre /= n
    return centre, largest_length(x, centre), largest_length(forces, np.zeros(3))


def divergence_judged(atoms: Atoms | None) -> bool:
    """Whether a run on ``atoms`` gets the divergence test: its calculator is
    a :class:`MaudCalculator`, whose terms (springs, repulsion, loads) the
    test's secant prediction is made for and whose scenes can fly apart for
    ever. Another calculator's forces are its own business: a fragment that
    leaves a cluster (a hop of BasinHopping, a desorption) feels forces that
    fade with distance or end at a cut-off, and its run ends by fmax, as
    with BFGS (issue 32)."""
    return isinstance(getattr(atoms, 'calc', None), MaudCalculator)


def minimum_proved(atoms: Atoms | None, target: str) -> bool:
    """True if a run seeks a ``target='minimum'`` whose existence the
    calculator of ``atoms`` proves (:meth:`MaudPotential.minimum_proved`):
    the run then gets no divergence test."""
    calc = getattr(atoms, 'calc', None)
    return (target == 'minimum' and isinstance(calc, MaudCalculator)
            and calc.potential.minimum_proved(atoms))


def no_equilibrium(atoms: Atoms | None, target: str) -> NoEquilibriumError | None:
    """The NoEquilibriumError of a run on ``atoms`` whose calculator proves
    the scene has no finite equilibrium, or no finite minimum for a
    ``target='minimum'`` (:meth:`MaudPotential.no_equilibrium`); None if
    nothing is proved (another calculator proves nothing)."""
    calc = getattr(atoms, 'calc', None)
    why = (calc.potential.no_equilibrium(atoms, minimum=target == 'minimum')
           if isinstance(calc, MaudCalculator) else None)
    return NoEquilibriumError(f'before the first step: {why}') if why else None


@dataclass
class RunMonitor:
    """Divergence and stagnation of one run; see the module docstring.

    ``merit_name``: what the merit is in messages (``'energy'`` for
    ``target='minimum'``, else ``'|f|^2'``, which is not watched for
    progress); ``band``: a band of images, whose steps are judged by the
    work of its forces (:attr:`~ase_maud.optimize.strategy.Strategy.band`);
    ``length_scale``: the scene's ``a`` (0 if unknown);
    ``bounded``: a finite minimum is proved (no divergence test);
    ``divergence_factor`` inf: no divergence test either. The divergence
    test's record: ``marks`` (growths seen), ``passes`` (successive ones
    that came no nearer), ``ahead`` (the last predicted balance: how far
    on, and that length over the move before it) and ``mark`` (positions and
    forces at the last growth); not kept in a restart file: a resumed run
    judges its growth afresh.
    """

    divergence_factor: float
    patience: int
    merit_name: str = 'energy'
    band: bool = False
    length_scale: float = 0.0
    size0: float | None = None
    centre0: np.ndarray | None = None
    best: tuple[float, int] = (np.inf, 0)
    lowest: tuple[float, int] = (np.inf, 0)
    bounded: bool = False
    marks: int = 0
    passes: int = 0
    ahead: tuple[float, float] | None = None
    mark: tuple[np.ndarray, np.ndarray] | None = None

    @classmethod
    def of_run(cls, atoms: Atoms | None, target: str, divergence_factor: float,
               patience: int, points: bool, band: bool = False) -> RunMonitor:
        """The monitor of a run seeking ``target`` on ``atoms`` (None: a band
        of images or a cell filter; ``band``: a band judged by its forces'
        work); the divergence test only where the
        coordinates are ``points`` (a cell filter's rows do not spread like
        points), the scene is a MaudCalculator's (:func:`divergence_judged`)
        and no finite minimum is proved."""
        return cls(divergence_factor if points and divergence_judged(atoms) else np.inf,
                   patience,
                   merit_name='energy' if target == 'minimum' else '|f|^2', band=band,
                   length_scale=getattr(getattr(atoms, 'calc', None), 'length_scale', 0.0),
                   bounded=minimum_proved(atoms, target))

    def check(self, step: int, x: np.ndarray, merit: float, forces: np.ndarray,
              gamma: float, gamma0: float, tolerance: float) -> None:
        """Raise DivergenceError or StagnationError (module docstring) at
        ``step``; ``gamma0`` is the step factor's start, ``tolerance`` the
        slack of a merit comparison."""
        centre, size, fmax = measures(x, forces)
        if self.size0 is None:
            self.size0 = max(size, self.length_scale * len(x), np.finfo(float).tiny)
            self.centre0 = centre
        if not self.bounded:
            self._judge_growth(step, x, forces, size, np.linalg.norm(centre - self.centre0))
        if fmax < (1 - FMAX_PROGRESS) * self.best[0]:
            self.best = (fmax, step)
        if (self.merit_name == 'energy'
                and merit < self.lowest[0] - max(tolerance, ENERGY_PROGRESS * fmax * size)):
            self.lowest = (merit, step)
        if step - max(self.best[1], self.lowest[1]) > self.patience:
            raise StagnationError(
                f'stagnant at step {step}: no progress for {self.patience} steps '
                f'(fmax {fmax:.3g}, best {self.best[0]:.3g} at step {self.best[1]}'
                f'{self._lowest_text()}; a requested fmax below the rounding '
                'noise of the forces, an oscillation, or a creep: the energy '
                f'falling by less than {ENERGY_PROGRESS:g} fmax times the size of '
                'the scene)')
        if gamma < GAMMA_UNDERFLOW * gamma0:
            rose = ("overshot (the band's forces did negative work over it)" if self.band
                    else f'raised the {self.merit_name}')
            raise StagnationError(
                f'stagnant at step {step}: the step factor gamma fell to '
                f'{gamma:.3g} ({gamma / gamma0:.3g} of its start): every step '
                f'since step {max(self.best[1], self.lowest[1])} {rose}, even the '
                f'shortest along the model\'s direction (fmax {fmax:.3g})')

    def _judge_growth(self, step: int, x: np.ndarray, forces: np.ndarray,
                      size: float, drift: float) -> None:
        """Mark the run at each growth by ``divergence_factor``; raise
        DivergenceError if it came no nearer its predicted balance at
        :data:`DIVERGENCE_PASSES` successive marks (module docstring)."""
        if self.mark is None:   # the start, or the first step of a resumed run
            self.mark = (x.copy(), forces.copy())
            return
        extent = max(size, drift)
        if not extent >= self.size0 * self.divergence_factor ** (self.marks + 1):
            return
        move, pull = x - self.mark[0], forces - self.mark[1]
        self.marks, self.mark = self.marks + 1, (x.copy(), forces.copy())
        length = float(np.linalg.norm(move))
        ahead = balance_ahead(move, pull, forces)
        before, self.ahead = self.ahead, (ahead, ahead / length)
        if before is None:
            return
        nearing = length <= before[0] and self.ahead[1] < before[1]
        self.passes = 0 if nearing else self.passes + 1
        if self.passes >= DIVERGENCE_PASSES:
            what = ('the scene as a whole drifted by' if drift > size
                    else 'the points spread to')
            raise DivergenceError(
                f'diverged at step {step}: {what} {extent:.3g}, {extent / self.size0:.3g} '
                f'times the reference size {self.size0:.3g}, and at {self.passes} '
                f'successive growths by {self.divergence_factor:g} it came no nearer '
                'the point where its forces would balance (the secant curvature '
                'along its move predicts it ' + (
                    'nowhere' if ahead == np.inf else
                    f'{self.ahead[1]:.3g} times that move further on') + '): no '
                'stationary point in reach (nothing holds the scene against a '
                'constant force or the repulsion?); fix some points, or give '
                'divergence_factor=inf (--divergence-factor inf) to run on')

    def _lowest_text(self) -> str:
        if self.merit_name != 'energy':
            return ''
        return f', energy {self.lowest[0]:.12g} lowest since step {self.lowest[1]}'

    def todict(self, step: int) -> dict[str, Any]:
        """The state to resume from at ``step`` (steps counted from it)."""
        return {'size0': self.size0, 'centre0': self.centre0,
                'best': [self.best[0], self.best[1] - step],
                'lowest': [self.lowest[0], self.lowest[1] - step]}

    def load(self, d: dict[str, Any]) -> None:
        """Take the state :meth:`todict` gave (its steps are relative to the
        step it was written at, which the resumed run counts as 0); a missing
        or malformed entry is a ValueError naming it."""
        def entry(key, valid, what):
            if key not in d:
                raise ValueError(f'the monitor\'s state has no {key!r}')
            if not valid(d[key]):
                raise ValueError(f'the monitor\'s {key!r} must be {what}, got {d[key]!r}')
            return d[key]

        def record(v):   # [a number or inf (not NaN), a step]
            return (isinstance(v, list) and len(v) == 2 and as_whole(v[1]) is not None
                    and (as_number(v[0]) is not None or v[0] == np.inf))

        size0 = entry('size0', lambda v: v is None or (as_number(v) or 0) > 0,
                      'a positive number or null')
        centre0 = entry('centre0', lambda v: v is None or (
            np.shape(v) == (3,) and all(as_number(c) is not None for c in v)),
            'three numbers or null')
        self.size0 = None if size0 is None else float(size0)
        self.centre0 = None if centre0 is None else np.asarray(centre0, float)
        best = entry('best', record, '[fmax, step]')
        lowest = entry('lowest', record, '[energy, step]')
        self.best = (float(best[0]), int(best[1]))
        self.lowest = (float(lowest[0]), int(lowest[1]))
