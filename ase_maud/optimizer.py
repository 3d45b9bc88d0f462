"""Maud: the specification's step ``dr = gamma K^-1 f`` as an ASE optimizer.

``K`` is a stiffness model (:mod:`ase_maud.stiffness`) and the step rule
around it (L-BFGS memory, Day's momentum, restarts, gamma, step bounds) is
:class:`ase_maud.method.MaudMethod`; this module is ASE's plumbing: the
optimizable, the log, the trajectory, the restart file, and the run's safety
checks.

- ``model='auto'`` (default): the whole scene's stiffness: the exact Hessian
  (saddle-free Newton) for small scenes, the sparse global model
  ``P = Q (L (x) I) + blockdiag(|K_mm - Q deg I|)`` with an L-BFGS memory for
  large ones; the specification's nodal blocks (``model='nodal'``, with
  ``method='tensor'`` or ``'scalar'``) and Day's momentum remain as options; a
  calculator with no stiffness gets the secant model ``kappa I``.
- ``target='minimum'`` makes every model positive definite (absolute
  eigenvalues, floored), so no step is meant uphill; ``'stationary'`` keeps the
  signs: saddles and maxima are fixed points too.
- Accuracy follows the run: with a calculator that takes ``tol`` (the force
  error allowed relative to its ``last_force_scale``, as MaudCalculator's
  ``backend='auto'`` does), each evaluation asks for a force error of
  :data:`ACCURACY_FRACTION` (0.1) of the larger of the requested ``fmax``
  and the current one, at most :data:`MAX_RUN_TOL`: coarse, cheap sums far
  from the answer, fine ones near it, and never a stall on evaluation noise.
  The calculator keeps the last ``tol`` after the run. Energies compared to
  accept or take back a step carry a relative error up to the calculator's
  ``last_tolerance``: differences below it are decided by the trapezoid
  estimate from the forces instead (:mod:`ase_maud.method`). Other
  calculators are left alone.
- A run never goes on for ever: a 3D scene whose spring graph has a free
  component beside others (no finite minimum) is reported in the log before
  the first step; :class:`DivergenceError` stops a run whose points spread
  beyond ``divergence_factor`` times their start size (or ``a N``), or, on a
  scene known to have no finite minimum, beyond twice their start size; and
  :class:`StagnationError` one whose gamma underflows or that has made no
  progress for ``patience`` steps (neither fmax fell by 0.1 % nor, for
  ``'minimum'``, the energy below its lowest beyond rounding). The
  trajectory written so far stays valid.
- Nothing silently wrong (docs/hard_cases.md): every keyword and run argument
  is checked (ValueError naming it and what is accepted); every energy and
  force the calculator returns is checked finite before it is logged or
  written: a non-finite one puts the positions back to the last step whose
  results were finite and raises :class:`MaudError` naming the step and the
  value; the restart file is replaced atomically after each trajectory frame
  and holds the positions its state belongs to, so a run killed at any moment
  carries on exactly (:meth:`Maud.resume`).
"""

from __future__ import annotations

import math
import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import IO, Any, NamedTuple

import numpy as np
from ase import Atoms
from ase.io.jsonio import write_json
from ase.optimize.optimize import DEFAULT_MAX_STEPS, Optimizer

from .checks import as_whole
from .method import MaudMethod, StepRule, _Point, merit_tolerance
from .stiffness import METHODS, TARGETS, StiffnessModel, choose_model
from .topology import describe_unbounded

#: The force error a run asks of a ``tol``-aware calculator (MaudCalculator
#: with ``backend='auto'``), as a fraction of the larger of the requested
#: ``fmax`` and the current one (:meth:`Maud._ask_accuracy`).
ACCURACY_FRACTION = 0.1
#: The coarsest ``tol`` a run asks for (relative to the largest force).
MAX_RUN_TOL = 1e-3


class MaudError(RuntimeError):
    """A run that cannot go on; the message (also in the log) says why."""


class DivergenceError(MaudError):
    """The points flew apart: the scene has no finite stationary point."""


class StagnationError(MaudError):
    """No progress: gamma underflowed or fmax stopped improving."""




class Maud(Optimizer):
    """The Maud optimiser; see the module docstring and docs/optimizer.md.

    Parameters
    ----------
    atoms : Atoms (or anything with ``__ase_optimizable__``)
        The system to relax.
    model : 'auto', 'exact', 'global', 'nodal', 'secant' or a StiffnessModel
        The stiffness ``K`` of the step (default 'auto'; see
        :func:`ase_maud.stiffness.choose_model`).
    method : 'tensor' (default) or 'scalar'
        For ``model='nodal'``: ``K_mm^-1 f_m`` or ``f_m / Tr K_mm``.
    target : 'minimum', 'stationary' or None
        Move only downhill, or seek any stationary point. None (default):
        'minimum', except for a band of images (ASE's ``NEB``), whose forces
        are not the gradient of an energy: 'stationary' (said in the log).
    gamma : float
        Initial step factor (default 1: the full Newton step of the model).
    gamma_max : float or None
        Largest step factor (default: the model's, 1 for exact and global,
        1.5 for nodal and secant).
    gamma_growth : float
        Factor gamma grows by after each accepted step (default 1.1).
    overshoot_shrink : float
        Factor gamma shrinks by at a kinetic-damping restart (default 0.6).
    beta_max : float or None
        Largest momentum weight, in [0, 1) (default: the model's, 0 for exact
        and global, 0.98 for nodal and secant).
    memory : int or None
        L-BFGS pairs kept over ``K^-1`` (default: the model's, 30 for global,
        0 for the others).
    floor : float or None
        Relative eigenvalue floor of the model (default: the model's, 1e-8
        for exact, 1e-2 for the others).
    maxstep_nn : float
        Largest move of a point in one step, as a fraction of its distance to
        its nearest other point, in (0, 0.5) (default 0.45).
    maxstep : float or None
        Largest move of a point in one step, in length units (default None).
    kappa0 : float
        Initial stiffness of the secant model (default 70, ASE's BFGS initial
        Hessian in eV/A**2).
    divergence_factor : float
        Growth of the scene's size (largest distance from the centroid) over
        its reference, ``max(start size, a N)``, that counts as divergence
        (default 3).
    patience : int
        Steps without progress after which the run stops as stagnant
        (default 2000).
    restart, logfile, trajectory, append_trajectory, **kwargs
        As for every ASE optimizer.
    """

    def __init__(self, atoms: Atoms, restart: str | None = None,
                 logfile: IO | str | None = '-', trajectory: str | None = None,
                 append_trajectory: bool = False,
                 model: str | StiffnessModel = 'auto', method: str = 'tensor',
                 target: str | None = None, gamma: float = 1.0,
                 gamma_max: float | None = None, gamma_growth: float = 1.1,
                 beta_max: float | None = None, memory: int | None = None,
                 floor: float | None = None, maxstep_nn: float = 0.45,
                 maxstep: float | None = None, kappa0: float = 70.0,
                 overshoot_shrink: float = 0.6, divergence_factor: float = 3.0,
                 patience: int = 2000, **kwargs: Any):
        system = atoms.__ase_optimizable__() if hasattr(
            atoms, '__ase_optimizable__') else atoms
        image_size = _image_size(system)
        chosen_target = target is None
        if chosen_target:  # NEB forces are not the gradient of its energy
            target = 'minimum' if image_size is None else 'stationary'
        for name, value, known, default in (
                ('target', target, TARGETS, ', or None (the default)'),
                ('method', method, METHODS, '')):
            if not (isinstance(value, str) and value in known):
                raise ValueError(f'{name} must be one of {known}{default}, got {value!r}')
        n = {name: _keyword(name, value) for name, value in (
            ('gamma', gamma), ('gamma_max', gamma_max),
            ('gamma_growth', gamma_growth), ('beta_max', beta_max),
            ('memory', memory), ('floor', floor), ('maxstep_nn', maxstep_nn),
            ('maxstep', maxstep), ('kappa0', kappa0),
            ('overshoot_shrink', overshoot_shrink),
            ('divergence_factor', divergence_factor), ('patience', patience))}
        _check_files(restart, logfile, trajectory, append_trajectory)
        if isinstance(model, StiffnessModel):
            self.model = model
        elif isinstance(model, str):
            self.model = choose_model(getattr(system, 'atoms', atoms), model,
                                      target, method=method, floor=n['floor'],
                                      kappa0=n['kappa0'])
        else:
            raise ValueError("model must be 'auto', a model name or a "
                             f'StiffnessModel, got {model!r}')
        defaults = self.model.step_defaults
        rule = StepRule(
            target=target, gamma=n['gamma'],
            gamma_max=_default(n['gamma_max'], defaults['gamma_max']),
            gamma_growth=n['gamma_growth'], overshoot_shrink=n['overshoot_shrink'],
            beta_max=_default(n['beta_max'], defaults['beta_max']),
            memory=_default(n['memory'], defaults['memory']),
            maxstep_nn=n['maxstep_nn'], maxstep=n['maxstep'],
            trust_region=defaults['trust_region'], image_size=image_size)
        if target == 'stationary':
            rule.memory = 0  # L-BFGS assumes a positive-definite model
        self.rule = rule
        self.method = method
        self.target = target
        self.divergence_factor = n['divergence_factor']
        self.patience = n['patience']
        super().__init__(atoms, restart, logfile, trajectory,
                         append_trajectory=append_trajectory, **kwargs)
        self.optimizable = _CheckedOptimizable(self.optimizable, self)
        if chosen_target and target == 'stationary':
            self.logfile.write("Maud: target='stationary' (the forces of a "
                               'band of images are not the gradient of its '
                               'energy)\n')
        if self.model.name == 'secant':
            self.logfile.write('Maud: the calculator gives no stiffness; it is '
                               'estimated as kappa I (secant curvature)\n')

    def todict(self) -> dict[str, Any]:
        d = super().todict()
        d.update(model=self.model.name, method=self.method, target=self.target,
                 gamma=self.rule.gamma, gamma_max=self.rule.gamma_max,
                 gamma_growth=self.rule.gamma_growth,
                 overshoot_shrink=self.rule.overshoot_shrink,
                 beta_max=self.rule.beta_max, memory=self.rule.memory,
                 floor=self.model.floor, maxstep_nn=self.rule.maxstep_nn)
        return d

    def initialize(self) -> None:
        self.maud = MaudMethod(self.model, self.rule)
        self.size0 = None       # reference size for the divergence test
        self.unbounded = []     # spring components that make E unbounded
        self.best = (np.inf, 0)  # best fmax so far, and the step it was seen
        self.lowest = (np.inf, 0)  # lowest merit so far ('minimum'), and step
        self.fmax_now = np.inf   # largest force at the last step

    def read(self) -> None:
        """Take the restart file's state, and its positions (they win: the
        state belongs to them; a line in the log says if the atoms moved)."""
        state = self.load()
        missing = {'x', 'step', 'method', 'size0', 'best', 'lowest',
                   'fmax_now'} - set(state)
        if missing:
            raise ValueError(f'restart file {str(self.restart)!r} was not written by '
                             f'this version of Maud (no {", ".join(sorted(missing))}); '
                             'delete it')
        x, here = np.asarray(state['x'], float), self.optimizable.get_x()
        if x.shape != here.shape:
            raise ValueError(
                f'restart file {str(self.restart)!r} holds {x.size // 3} points, '
                f'the atoms given {here.size // 3}: give the atoms of that run, '
                'or delete the file')
        if not np.array_equal(x, here):
            gap = np.abs(x - here).max()
            self.optimizable.set_x(x)
            self.logfile.write(
                f'Maud: the atoms moved to the positions of step {state["step"]} '
                f'in {self.restart} (up to {gap:.3g} from the atoms given)\n')
        self.initialize()
        self.maud.load(state['method'])
        step = state['step']   # this run counts its steps from 0 again
        self.size0 = state['size0']
        self.best = (state['best'][0], state['best'][1] - step)
        self.lowest = (state['lowest'][0], state['lowest'][1] - step)
        self.fmax_now = state['fmax_now']   # the accuracy of the next evaluation

    def call_observers(self) -> None:
        """ASE's observers (the trajectory first), then the restart file: it
        is never ahead of the trajectory's last frame."""
        super().call_observers()
        if self.restart is not None:
            self.dump({'x': self.optimizable.get_x(), 'step': self.nsteps,
                       'method': self.maud.state(), 'size0': self.size0,
                       'best': list(self.best), 'lowest': list(self.lowest),
                       'fmax_now': self.fmax_now})

    def dump(self, data: dict[str, Any]) -> None:
        """Replace the restart file atomically (a temporary file in the same
        directory, flushed and synced, then ``os.replace``): after a kill at
        any moment it holds the old state or the new one, never a part."""
        if self.comm.rank != 0 or self.restart is None:
            return
        path = Path(self.restart)
        handle, temporary = tempfile.mkstemp(dir=path.parent,
                                             prefix=f'.{path.name}.', suffix='.tmp')
        try:
            with os.fdopen(handle, 'w') as fd:
                write_json(fd, data)
                fd.flush()
                os.fsync(fd.fileno())
            os.replace(temporary, path)
        except BaseException:
            Path(temporary).unlink(missing_ok=True)
            raise

    @classmethod
    def resume(cls, atoms: Atoms, restart: str | Path = 'maud.json',
               trajectory: str | Path = 'maud.traj', **kwargs: Any) -> Maud:
        """Carry on a run that was stopped or killed at any moment.

        ``atoms`` are the run's atoms with their calculator and constraints
        (its start, or any frame: the positions are replaced). They take the
        last frame of ``trajectory`` if it has one, then the restart file's
        positions if it exists (its state belongs to them; it is never ahead
        of the trajectory, at most one frame behind, which is then written
        again). The trajectory is appended to. The resumed run makes the
        steps the uninterrupted one would have made. ``kwargs`` go to Maud.
        """
        frame = last_frame(trajectory)
        if frame is not None:
            if len(frame) != len(atoms):
                raise ValueError(f'trajectory {str(trajectory)!r} holds {len(frame)} '
                                 f'atoms, the atoms given {len(atoms)}')
            atoms.set_positions(frame.positions, apply_constraint=False)
        return cls(atoms, restart=restart, trajectory=trajectory,
                   append_trajectory=True, **kwargs)

    # -- the step ---------------------------------------------------------------

    def _atoms(self) -> Atoms | None:
        """The Atoms behind the optimizable, or None (a filter, say)."""
        return getattr(self.optimizable, 'atoms', None)

    def _evaluate(self) -> None:
        """One calculator call for the energy, the forces and what the model
        needs (the nodal blocks, say), computed together, at the accuracy the
        run needs now."""
        atoms = self._atoms()
        if atoms is None:
            return
        self._ask_accuracy(atoms.calc)
        if (prop := self.model.needs(atoms)) is not None:
            atoms.calc.get_property(prop, atoms)

    def _ask_accuracy(self, calc: Any) -> None:
        """Set a ``tol``-aware calculator's ``tol`` (force error relative to
        its ``last_force_scale``) to :data:`ACCURACY_FRACTION` of the larger
        of the run's ``fmax`` and the current one: coarse far from the
        answer, fine near it. Other calculators are left alone."""
        scale = getattr(calc, 'last_force_scale', None)
        if not scale or 'tol' not in getattr(calc, 'parameters', {}):
            return
        wanted = ACCURACY_FRACTION * max(self.fmax, self.fmax_now) / scale
        calc.set(tol=min(wanted, MAX_RUN_TOL))

    def _merit(self, forces: np.ndarray) -> float:
        if self.target == 'minimum':
            return self.optimizable.get_value()
        return float(np.vdot(forces, forces))

    def step(self) -> None:
        opt = self.optimizable
        x = opt.get_x().reshape(-1, 3)
        forces = -opt.get_gradient().reshape(-1, 3)
        merit = self._merit(forces)
        maud = self.maud
        self.fmax_now = float(np.linalg.norm(forces, axis=1).max())
        calc = getattr(self._atoms(), 'calc', None)
        maud.noise = getattr(calc, 'last_tolerance', None) or 0.0
        if maud.uphill(x, merit, forces):
            here = maud.revert()
            if here.solver is None:  # resumed from a restart file
                opt.set_x(here.x.ravel())
                here.solver = self._solver()
        else:
            maud.accept(x, forces)
            here = _Point(x.copy(), merit, forces.copy(), self._solver(), maud.noise)
        self._check_progress(here.x, here.merit, here.forces)
        move = maud.move(here)
        if not np.isfinite(move).all():
            self._no_step(f'the {self.model.name} stiffness model gave a non-finite move')
        opt.set_x((here.x + move).ravel())
        maud.moved(opt.get_x().reshape(-1, 3))
        self._evaluate()

    def _solver(self) -> Any:
        """The stiffness model at the current positions."""
        try:
            return self.model.at(self._atoms())
        except np.linalg.LinAlgError as error:
            self._no_step(f'the {self.model.name} stiffness model failed ({error})')

    def _no_step(self, why: str) -> None:
        """Stop: no finite step from here; the calculator's non-finite
        stiffness property is named if it is the cause."""
        atoms = self._atoms()
        prop = None if atoms is None else self.model.needs(atoms)
        if prop is not None:
            value = np.asarray(atoms.calc.get_property(prop, atoms))
            if not np.isfinite(value).all():
                where = np.argwhere(~np.isfinite(value))[0].tolist()
                why = (f'the calculator returned a non-finite {prop} (entry '
                       f'{where}: {value[tuple(where)]})')
        self._stop(MaudError, f'no finite step from step {self.nsteps}: {why}; the '
                   f'positions are those of step {self.nsteps}')

    def irun(self, fmax: float = 0.05, steps: int = DEFAULT_MAX_STEPS):
        fmax, steps = _run_arguments(fmax, steps)
        self.fmax = fmax
        self._preflight()
        return super().irun(fmax, steps)

    def run(self, fmax: float = 0.05, steps: int = DEFAULT_MAX_STEPS) -> bool:
        fmax, steps = _run_arguments(fmax, steps)
        self.fmax = fmax
        self._preflight()
        return super().run(fmax, steps)

    def _preflight(self) -> None:
        """Say in the log if the scene has no finite minimum; evaluate.
        Energy and forces held from an earlier run are dropped (the
        calculator or the band may have changed since)."""
        self.optimizable.held = None
        atoms = self._atoms()
        calc = getattr(atoms, 'calc', None)
        if hasattr(calc, 'unbounded_components') and self.target == 'minimum':
            self.unbounded = calc.unbounded_components(atoms)
            if self.unbounded:
                self.logfile.write('Maud: warning: '
                                   f'{describe_unbounded(self.unbounded)}\n')
        self._evaluate()

    def _stop(self, error: type[MaudError], message: str) -> None:
        self.logfile.write(f'Maud: stopped: {message}\n')
        raise error(message)

    def _check_progress(self, x, merit, forces):
        """Raise DivergenceError or StagnationError; see the module docstring."""
        size = np.linalg.norm(x - x.mean(axis=0), axis=1).max()
        if self.size0 is None:
            a = getattr(getattr(self._atoms(), 'calc', None), 'length_scale', 0.0)
            reference = size if self.unbounded else max(size, a * len(x))
            self.size0 = max(reference, np.finfo(float).tiny)
        factor = 2.0 if self.unbounded else self.divergence_factor
        if size > factor * self.size0:
            why = (describe_unbounded(self.unbounded) if self.unbounded
                   else 'no stationary point in reach')
            self._stop(DivergenceError,
                       f'diverged at step {self.nsteps}: the points spread to '
                       f'{size:.3g}, {size / self.size0:.3g} times their '
                       f'reference size {self.size0:.3g}; {why}')
        fmax = np.linalg.norm(forces, axis=1).max()
        if fmax < (1 - 1e-3) * self.best[0]:
            self.best = (fmax, self.nsteps)
        if (self.target == 'minimum'
                and merit < self.lowest[0] - merit_tolerance(merit, self.maud.noise)):
            self.lowest = (merit, self.nsteps)
        if self.nsteps - max(self.best[1], self.lowest[1]) > self.patience:
            self._stop(StagnationError,
                       f'stagnant at step {self.nsteps}: no progress for '
                       f'{self.patience} steps (fmax {fmax:.3g}, best '
                       f'{self.best[0]:.3g}{self._lowest_text()}; a requested '
                       'fmax below the rounding noise of the forces, or an '
                       'oscillation)')
        if self.maud.gamma < 1e-12 * min(self.rule.gamma, self.rule.gamma_max):
            self._stop(StagnationError,
                       f'stagnant at step {self.nsteps}: gamma fell to '
                       f'{self.maud.gamma:.3g}; every step raised the '
                       f'{"energy" if self.target == "minimum" else "|f|^2"}'
                       ' (energy and forces may disagree)')

    def _lowest_text(self):
        if self.target != 'minimum':
            return ''
        return f', energy {self.lowest[0]:.12g} lowest since step {self.lowest[1]}'


class _CheckedOptimizable:
    """The optimizable with its energy and gradient fetched together, once
    per positions, and checked finite (everything else passes through).

    ASE's loop and the step ask for both several times at the same
    positions; they are kept with the positions ``x`` they belong to and
    fetched again as soon as ``x`` differs in any bit (the calculator's own
    change detection then decides what to recompute). A non-finite value
    puts the positions back to the last ones whose results were finite and
    stops the run with a MaudError naming the step and the value. ASE asks
    for both before it logs a step or writes its frame, so neither sees it.
    """

    def __init__(self, inner: Any, optimizer: Maud):
        self.inner = inner
        self.optimizer = optimizer
        self.good: tuple[np.ndarray, int] | None = None  # positions, step
        self.held: tuple[np.ndarray, float, np.ndarray] | None = None  # x, E, gradient

    def __getattr__(self, name: str) -> Any:
        return getattr(self.inner, name)

    def get_value(self) -> float:
        return self._results()[1]

    def get_gradient(self) -> np.ndarray:
        return self._results()[2].copy()

    def _results(self) -> tuple[np.ndarray, float, np.ndarray]:
        x = self.inner.get_x()
        if self.held is not None and np.array_equal(x, self.held[0]):
            return self.held
        gradient = self.inner.get_gradient()
        rows = gradient.reshape(-1, 3)
        bad = np.flatnonzero(~np.isfinite(rows).all(axis=1))
        if bad.size:
            force = ', '.join(f'{v:.6g}' for v in 0.0 - rows[bad[0]])
            self._fail(f'non-finite forces (atom {bad[0]}: [{force}]'
                       f'{f" and {bad.size - 1} more atoms" if bad.size > 1 else ""})')
        value = self.inner.get_value()
        if not np.isfinite(value):
            self._fail(f'a non-finite energy ({value})')
        self.good = (x.copy(), self.optimizer.nsteps)
        self.held = (x.copy(), value, gradient)
        return self.held

    def _fail(self, what: str) -> None:
        if self.good is None:
            where = 'the atoms are at their start positions'
        else:
            self.inner.set_x(self.good[0])
            where = f'positions restored to step {self.good[1]}'
        self.optimizer._stop(MaudError, f'the calculator returned {what} at step '
                             f'{self.optimizer.nsteps}; {where}')


def last_frame(trajectory: str | Path) -> Atoms | None:
    """The last complete frame of an ASE trajectory file, or None if it has
    none (missing, empty, or killed before its first frame was complete).

    ASE's ulm writer counts a frame only once all of it is written, so a
    trajectory killed mid-write reads as its complete frames.
    """
    from ase.io.trajectory import Trajectory
    path = Path(trajectory)
    if not path.is_file() or path.stat().st_size == 0:
        return None
    with Trajectory(path) as frames:
        return frames[-1] if len(frames) else None


class _Range(NamedTuple):
    """What a numeric keyword accepts: the words for the error, the test, a
    whole number only, None too."""

    accepted: str
    test: Callable[[float], bool]
    whole: bool = False
    none: bool = False


#: Maud's numeric keywords and what each accepts.
KEYWORDS = {
    'gamma': _Range('a positive finite number', lambda v: v > 0),
    'gamma_max': _Range("a positive finite number, or None (the model's)",
                        lambda v: v > 0, none=True),
    'gamma_growth': _Range('a finite number >= 1', lambda v: v >= 1),
    'overshoot_shrink': _Range('a number in (0, 1]', lambda v: 0 < v <= 1),
    'beta_max': _Range("a number in [0, 1), or None (the model's)",
                       lambda v: 0 <= v < 1, none=True),
    'memory': _Range("a whole number >= 0, or None (the model's)",
                     lambda v: v >= 0, whole=True, none=True),
    'floor': _Range("a number in (0, 1), or None (the model's)",
                    lambda v: 0 < v < 1, none=True),
    'maxstep_nn': _Range('a number in (0, 0.5) (at 0.5 two points could meet)',
                         lambda v: 0 < v < 0.5),
    'maxstep': _Range('a positive finite length, or None (no bound)',
                      lambda v: v > 0, none=True),
    'kappa0': _Range('a positive finite number (force per length)', lambda v: v > 0),
    'divergence_factor': _Range('a finite number > 1', lambda v: v > 1),
    'patience': _Range('a whole number >= 0 (steps)', lambda v: v >= 0, whole=True),
    'fmax': _Range('a positive finite number (force units)', lambda v: v > 0),
    'steps': _Range('a whole number >= 0', lambda v: v >= 0, whole=True),
}


def _keyword(name: str, value: Any) -> Any:
    """``value`` as a float (an int for a whole number, or None where allowed),
    or ValueError naming ``name``, the value and what :data:`KEYWORDS` accepts."""
    accepted, test, whole, none = KEYWORDS[name]
    if value is None and none:
        return None
    number = None
    if whole:
        number = as_whole(value)
    elif isinstance(value, (bool, np.bool_)):
        pass
    elif isinstance(value, (int, np.integer)):
        number = float(value) if abs(value) < 2.0**1023 else None
    elif isinstance(value, (float, np.floating)) and math.isfinite(value):
        number = float(value)
    if number is not None and test(number):
        return number
    raise ValueError(f'{name} must be {accepted}, got {value!r}')


def _default(value: Any, default: Any) -> Any:
    return default if value is None else value


def _run_arguments(fmax: Any, steps: Any) -> tuple[float, int]:
    """Checked ``run``/``irun`` arguments (ValueError naming the bad one)."""
    return _keyword('fmax', fmax), _keyword('steps', steps)


def _check_files(restart: Any, logfile: Any, trajectory: Any,
                 append_trajectory: Any) -> None:
    """ValueError naming a file argument that could not be written: a type
    that is not a file name (or open file), a directory, or a name in a
    directory that does not exist or cannot be written."""
    for name, value in (('restart', restart), ('logfile', logfile),
                        ('trajectory', trajectory)):
        if (value is None or (name != 'restart' and hasattr(value, 'write'))
                or (name == 'logfile' and isinstance(value, str) and value == '-')):
            continue
        if not isinstance(value, (str, os.PathLike)):
            opened = '' if name == 'restart' else ', an open file'
            dash = ", '-' (standard output)" if name == 'logfile' else ''
            raise ValueError(f'{name} must be None, a file name{opened}{dash}, '
                             f'got {value!r}')
        path = Path(value)
        if path.is_dir():
            raise ValueError(f'{name} {str(value)!r} is a directory; give a file name')
        parent = path.parent
        if not parent.is_dir():
            raise ValueError(f'{name} {str(value)!r}: the directory {str(parent)!r} '
                             'does not exist')
        if not os.access(parent, os.W_OK | os.X_OK):
            raise ValueError(f'{name} {str(value)!r}: the directory {str(parent)!r} '
                             'is not writable')
    if not isinstance(append_trajectory, (bool, np.bool_)):
        raise ValueError(f'append_trajectory must be True or False, got '
                         f'{append_trajectory!r}')


def _image_size(system: Any) -> int | None:
    """Points per image if ``system`` optimizes a band of images (ASE's
    NEB optimizable, which has ``neb``), else None."""
    neb = getattr(system, 'neb', None)
    return None if neb is None else len(neb.images[0])
