"""Maud: the specification's step ``dr = gamma K^-1 f`` as an ASE optimizer.

This module is ASE's plumbing only: the optimizable, the log, the trajectory,
the restart file, the accuracy asked of the calculator, and the checks that
every energy and force is finite. The step is
:class:`ase_maud.method.MaudMethod` (its state a
:class:`~ase_maud.method.MaudState`), with a stiffness model
(:mod:`ase_maud.stiffness`); divergence and stagnation are watched by a
:class:`~ase_maud.monitor.RunMonitor`; the accuracy schedule is
:mod:`ase_maud.accuracy`; every keyword is checked by its rule in
:data:`ase_maud.checks.RULES`.

- ``model='auto'`` (default): the whole scene's stiffness: the exact Hessian
  (saddle-free Newton) for small scenes, a sparse model with an L-BFGS
  memory for large ones; the specification's nodal blocks (``model='nodal'``,
  with ``method='tensor'`` or ``'scalar'``) and Day's momentum remain as
  options; a calculator with no stiffness gets the secant model ``kappa I``.
- ``target='minimum'`` makes every model positive definite (absolute
  eigenvalues, floored), so no step is meant uphill; ``'stationary'`` keeps the
  signs: saddles and maxima are fixed points too; ``'saddle'`` climbs along
  ``order`` modes by eigenvector following (the exact model; minimum-mode
  following on the springs model above its size) and, once converged,
  checks the index of the point found (:class:`WrongIndexError` if it is
  another).
- Nothing silently wrong (docs/hard_cases.md): a bad keyword or run argument
  is a ValueError naming it; every energy and force the calculator returns
  is checked finite before it is logged or written: a non-finite one puts
  the positions back to the last step whose results were finite and raises
  :class:`MaudError` naming the step and the value; the restart file
  (:mod:`ase_maud.restart`) is replaced atomically after each trajectory
  frame and holds the positions its state belongs to, so a run killed at any
  moment carries on exactly (:meth:`Maud.resume`).
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Iterator
from dataclasses import dataclass, replace
from pathlib import Path
from typing import IO, Any

import numpy as np
from ase import Atoms
from ase.filters import Filter
from ase.optimize.optimize import DEFAULT_MAX_STEPS, Optimizer

from . import accuracy
from .checks import check, check_all, check_writable
from .lock import FileInUseError, RunLock
from .method import STEP_DEFAULTS, MaudMethod, StepRule, merit_tolerance, step_rule
from .monitor import (
    DivergenceError,
    MaudError,
    NoEquilibriumError,
    RunMonitor,
    StagnationError,
    WrongIndexError,
)
from .neighbours import NearestDistances
from .paths import check_run_files
from .restart import RestartFile, difference, signature
from .stiffness import PROJECTIONS, StiffnessModel, choose_model
from .subset import SubsetView
from .trajectory import last_frame, repair

#: The longest move of a row of a cell filter's coordinates when ``maxstep``
#: is not given (ASE's BFGS default).
CELL_MAXSTEP = 0.2

__all__ = ['DivergenceError', 'FileInUseError', 'Maud', 'MaudError', 'NoEquilibriumError',
           'StagnationError', 'WrongIndexError']



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
    target : 'minimum', 'stationary', 'saddle' or None
        Move only downhill, seek any stationary point, or climb to a
        stationary point with exactly ``order`` negative curvatures
        (eigenvector following; docs/optimizer.md). None (default):
        'minimum', except for a band of images (ASE's ``NEB``), whose forces
        are not the gradient of an energy: 'stationary' (said in the log).
        With a StiffnessModel given, the model's own.
    gamma : float
        Initial step factor (default 1: the full Newton step of the model).
    gamma_max, gamma_growth, beta_max, memory, maxstep_nn : float or None
        Largest step factor, its growth after each accepted step, largest
        momentum weight (in [0, 1)), L-BFGS pairs kept over ``K^-1``, and the
        largest move of a point in one step as a fraction of its distance to
        its nearest other point (in (0, 0.5)). None (default): the model's,
        :data:`ase_maud.method.STEP_DEFAULTS`.
    overshoot_shrink : float
        Factor gamma shrinks by at a kinetic-damping restart (default 0.6).
    floor : float or None
        Relative eigenvalue floor of the model (default: the model's, 1e-8
        for exact, 1e-2 for the others).
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
    order : int
        For ``target='saddle'``: the negative curvatures sought (default 1;
        0: a minimum). A converged run checks the index of the point from the
        analytic Hessian (:func:`ase_maud.analysis.classify`, in
        :attr:`found`) and raises :class:`WrongIndexError` if it differs.
    mode : int, array (N, 3) or None
        For ``target='saddle'``: which way to climb first: an index of the
        Hessian's internal modes at the start (0 the lowest), or a move whose
        closest mode is followed (with the next lowest for ``order`` > 1).
        None (default): the lowest ``order`` modes.
    restart, logfile, trajectory, append_trajectory, **kwargs
        As for every ASE optimizer.
    """

    def __init__(self, atoms: Atoms, restart: str | None = None,
                 logfile: IO | str | None = '-', trajectory: str | None = None,
                 append_trajectory: bool = False,
                 model: str | StiffnessModel = 'auto', method: str = 'tensor',
                 target: str | None = None, gamma: float = 1.0,
                 gamma_max: float | None = None, gamma_growth: float | None = None,
                 beta_max: float | None = None, memory: int | None = None,
                 floor: float | None = None, maxstep_nn: float | None = None,
                 maxstep: float | None = None, kappa0: float = 70.0,
                 overshoot_shrink: float = 0.6, divergence_factor: float = 3.0,
                 patience: int = 2000, order: int = 1,
                 mode: int | np.ndarray | None = None, **kwargs: Any):
        steps = check_all(gamma=gamma, gamma_max=gamma_max, gamma_growth=gamma_growth,
                          beta_max=beta_max, memory=memory, maxstep_nn=maxstep_nn,
                          maxstep=maxstep, overshoot_shrink=overshoot_shrink)
        run = check_all(divergence_factor=divergence_factor, patience=patience)
        order = check('order', order)
        _check_files(restart, logfile, trajectory, append_trajectory)
        self._lock = RunLock(restart, trajectory)
        self._lock.check()   # before ASE empties a trajectory another run writes
        if append_trajectory and isinstance(trajectory, (str, os.PathLike)):
            if (repaired := repair(trajectory)):
                warnings.warn(repaired, stacklevel=2)
        system = atoms.__ase_optimizable__() if hasattr(
            atoms, '__ase_optimizable__') else atoms
        self._subset = SubsetView(atoms) if type(atoms) is Filter else None
        image_size = _image_size(system)
        # what the model sees: the atoms (the whole scene behind a Filter), a
        # band of images, or nothing (a cell filter: its rows are not points)
        scene = (self._atoms() if self._subset is not None
                 else getattr(system, 'atoms', None if image_size is None else atoms))
        chosen_target = target is None and not isinstance(model, StiffnessModel)
        if chosen_target:  # NEB forces are not the gradient of its energy
            target = 'minimum' if image_size is None else 'stationary'
        nearest = (NearestDistances(image_size) if self._subset is None
                   else self._subset.nearest())
        if isinstance(model, StiffnessModel):
            if target is not None and check('target', target) != model.target:
                raise ValueError(f'target={target!r} differs from the target of the '
                                 f'model given ({model.target!r}): leave target out')
        else:
            model = choose_model(scene, model, target, nearest=nearest, method=method,
                                 floor=floor, kappa0=kappa0)
        self.model = model
        self._points = scene is not None
        self.maud = MaudMethod(model, _step_rule(model, scene, image_size, steps, order),
                               nearest, _check_mode(mode, scene))
        #: For ``target='saddle'``: the converged point's classification.
        self.found: Any = None
        self.divergence_factor, self.patience = run['divergence_factor'], run['patience']
        super().__init__(atoms, restart, logfile, trajectory,
                         append_trajectory=append_trajectory, **kwargs)
        self.optimizable = _CheckedOptimizable(self.optimizable, self)
        if chosen_target and model.target == 'stationary':
            self.logfile.write("Maud: target='stationary' (the forces of a "
                               'band of images are not the gradient of its '
                               'energy)\n')
        if model.name == 'secant':
            self.logfile.write('Maud: the calculator gives no stiffness; it is '
                               'estimated as kappa I (secant curvature)\n')

    @property
    def target(self) -> str:
        """'minimum' or 'stationary': the model's."""
        return self.model.target

    @property
    def rule(self) -> StepRule:
        """The step rule's settings."""
        return self.maud.rule

    def todict(self) -> dict[str, Any]:
        d = super().todict()
        rule = self.rule
        if self.target == 'saddle':
            d['order'] = rule.order
        d.update(model=self.model.name, target=self.target, gamma=rule.gamma,
                 gamma_max=rule.gamma_max, gamma_growth=rule.gamma_growth,
                 overshoot_shrink=rule.overshoot_shrink, beta_max=rule.beta_max,
                 memory=rule.memory, floor=self.model.floor,
                 maxstep_nn=rule.maxstep_nn)
        if hasattr(self.model, 'method'):
            d['method'] = self.model.method
        return d

    def initialize(self) -> None:
        self._handoff: _Handoff | None = None
        self.state = self.maud.start()
        calc = getattr(self._atoms(), 'calc', None)
        self.monitor = RunMonitor(   # a cell filter's rows do not spread like points
            self.divergence_factor if self._points else np.inf, self.patience,
            merit_name='energy' if self.target == 'minimum' else '|f|^2',
            length_scale=getattr(calc, 'length_scale', 0.0))
        self.fmax_now = np.inf   # largest force at the last step

    def read(self) -> None:
        """Take the restart file's state, and its positions (they win: the
        state belongs to them; a line in the log says if the atoms moved)."""
        data = self._restart_file().read()
        x, here = data['x'].ravel(), self.optimizable.get_x()
        why = (f'points {x.size // 3} in it, {here.size // 3} in the atoms given'
               if x.shape != here.shape else difference(data['scene'], self._scene()))
        if why:
            raise ValueError(
                f'restart file {str(self.restart)!r} is of another scene: {why}; '
                'give the atoms of that run, or delete the file')
        self.initialize()
        try:
            self.monitor.load(data['monitor'])   # this run counts its steps from 0 again
        except ValueError as error:
            raise ValueError(f'restart file {str(self.restart)!r} is damaged: {error}; '
                             'delete it and its arrays file') from None
        if not np.array_equal(x, here):
            gap = np.abs(x - here).max()
            self.optimizable.set_x(x)
            self.logfile.write(
                f'Maud: the atoms moved to the positions of step {data["step"]} '
                f'in {self.restart} (up to {gap:.3g} from the atoms given)\n')
        self.state = data['state']
        self.fmax_now = data['fmax_now']   # the accuracy of the next evaluation

    def call_observers(self) -> None:
        """ASE's observers (the trajectory first), then the restart file: it
        is never ahead of the trajectory's last frame, and holds nothing
        before the first step (there is no state to carry on yet)."""
        super().call_observers()
        if self.restart is not None and self.comm.rank == 0 and self.state.last is not None:
            self._restart_file().write(self.nsteps, self.optimizable.get_x().reshape(-1, 3),
                                       self.state, self.monitor.todict(self.nsteps),
                                       self.fmax_now, self._scene())

    def _scene(self) -> dict[str, Any]:
        """The :func:`~ase_maud.restart.signature` of the atoms (empty for a
        filter); computed once per calculator and constraints."""
        atoms = self._atoms()
        if atoms is None:
            return {}
        calc = atoms.calc
        key = (id(calc), id(getattr(calc, 'potential', None)), len(atoms),
               tuple(map(id, atoms.constraints)))
        if getattr(self, '_scene_key', None) != key:
            self._scene_key = key
            self._scene_held = signature(atoms, getattr(calc, 'potential', None))
        return self._scene_held

    def _restart_file(self) -> RestartFile:
        """The run's :class:`~ase_maud.restart.RestartFile` (one per run, so
        that each step writes only what is new), with a row per mode a saddle
        search keeps (:meth:`~ase_maud.method.MaudMethod.kept_modes`)."""
        if getattr(self, '_restart', None) is None:
            self._restart = RestartFile(self.restart, self.maud.kept_modes())
        return self._restart

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
            if (why := _other_scene(frame, atoms)):
                raise ValueError(f'trajectory {str(trajectory)!r} is of another scene: '
                                 f'{why}; give the atoms of that run, or another '
                                 'trajectory')
            atoms.set_positions(frame.positions, apply_constraint=False)
        return cls(atoms, restart=restart, trajectory=trajectory,
                   append_trajectory=True, **kwargs)

    # -- the step ---------------------------------------------------------------

    def _atoms(self) -> Atoms | None:
        """The Atoms the stiffness model and the calculator see: those behind
        the optimizable, the whole scene behind a Filter (held where the
        filter leaves atoms out), or None (a band of images, a cell filter)."""
        if self._subset is not None:
            return self._subset.current()
        return getattr(getattr(self, 'optimizable', None), 'atoms', None)

    def _evaluate(self) -> None:
        """One calculator call for the energy, the forces and what the model
        needs (the nodal blocks, say), computed together, at the accuracy the
        run needs now (:func:`ase_maud.accuracy.ask`)."""
        atoms = self._atoms()
        if atoms is None:
            return
        accuracy.ask(atoms.calc, self.fmax, self.fmax_now)
        if (prop := self.model.needs(atoms)) is not None:
            atoms.calc.get_property(prop, atoms)

    def _merit(self, forces: np.ndarray) -> float:
        if self.target == 'minimum':
            return self.optimizable.get_value()
        return float(np.vdot(forces, forces))

    def step(self) -> None:
        self._afresh_if_changed()
        opt = self.optimizable
        x = opt.get_x().reshape(-1, 3)
        forces = -opt.get_gradient().reshape(-1, 3)
        merit = self._merit(forces)
        self.fmax_now = float(np.linalg.norm(forces, axis=1).max())
        noise = accuracy.noise(getattr(self._atoms(), 'calc', None))
        state = self.state
        try:
            move = self.maud.step(state, x, merit, forces, noise, self._solver_at)
            here = state.last
            self.monitor.check(self.nsteps, here.x, here.merit, here.forces,
                               state.gamma, min(self.rule.gamma, self.rule.gamma_max),
                               merit_tolerance(here.merit, noise))
        except MaudError as error:
            self._stop(error)
        if not np.isfinite(move).all():
            self._no_step(f'the {self.model.name} stiffness model gave a non-finite move')
        opt.set_x((here.x + move).ravel())
        self.maud.moved(state, opt.get_x().reshape(-1, 3))
        self._evaluate()
        self._handoff = self._handoff_now()

    def _afresh_if_changed(self) -> None:
        """Start the step rule and the run monitor afresh if the atoms, the
        calculator or its potential changed since the last step (between two
        runs, or by an observer): the last point and the secant pairs belong
        to another landscape."""
        if self._handoff is not None and self._handoff != self._handoff_now():
            self.initialize()
            self.logfile.write(f'Maud: the atoms or the calculator changed after step '
                               f'{self.nsteps}: the step rule starts afresh\n')

    def _handoff_now(self) -> _Handoff:
        """Where a step left the run: the positions, the calculator and its
        potential (compared at the next run's start)."""
        calc = getattr(self._atoms(), 'calc', None)
        return _Handoff(self.optimizable.get_x().copy(), calc,
                        getattr(calc, 'potential', None))

    def _solver_at(self, x: np.ndarray) -> Any:
        """The stiffness model at positions ``x`` (the atoms are moved there
        first if they are elsewhere: back to a point of a restart file)."""
        if not np.array_equal(self.optimizable.get_x().reshape(-1, 3), x):
            self.optimizable.set_x(x.ravel())
        try:
            solver = self.model.at(self._atoms(), self.state.model)
        except np.linalg.LinAlgError as error:
            self._no_step(f'the {self.model.name} stiffness model failed ({error})')
        return solver if self._subset is None else self._subset.solver(solver)

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
        self._stop(MaudError(f'no finite step from step {self.nsteps}: {why}; the '
                             f'positions are those of step {self.nsteps}'))

    def irun(self, fmax: float = 0.05, steps: int = DEFAULT_MAX_STEPS):
        self.fmax, steps = check('fmax', fmax), check('steps', steps)
        self._preflight()
        return self._locked(super().irun(self.fmax, steps))

    def _locked(self, steps: Iterator[bool]) -> Iterator[bool]:
        with self._lock:
            for converged in steps:
                if converged:
                    self._verify()
                yield converged

    def run(self, fmax: float = 0.05, steps: int = DEFAULT_MAX_STEPS) -> bool:
        self.fmax, steps = check('fmax', fmax), check('steps', steps)
        self._preflight()
        with self._lock:
            converged = super().run(self.fmax, steps)
        if converged:
            self._verify()
        return converged

    def gradient_converged(self, gradient: np.ndarray) -> bool:
        """ASE's test (``fmax``); for ``target='saddle'`` also the index of
        the model's Hessian there (its lowest eigenvalues: negative beyond
        :data:`ase_maud.analysis.RTOL` of the largest): a stationary point of
        another index (the minimum a search starts from) is left, not
        reported."""
        if not super().gradient_converged(gradient):
            return False
        if self.target != 'saddle':
            return True
        from .analysis import RTOL
        solver = self._solver_at(self.optimizable.get_x().reshape(-1, 3))
        values = (solver.modes()[0] if hasattr(solver, 'modes')   # the exact model
                  else solver.lowest(self.rule.order + 1,
                                     self.state.modes[:self.rule.order + 1])[0])
        negative = int(np.sum(values < -RTOL * np.abs(values).max(initial=0.0)))
        return negative == self.rule.order

    def _verify(self) -> None:
        """For ``target='saddle'``: classify the converged point from the
        analytic Hessian (:attr:`found`); a WrongIndexError if its index is
        not the ``order`` sought, or a zero curvature leaves it unknown."""
        if self.target != 'saddle':
            return
        from .analysis import classify
        atoms = self._atoms()
        self.found = point = classify(atoms, ftol=max(self.fmax, self.fmax_now))
        order = self.rule.order
        self.logfile.write(f'Maud: converged on a {point.verdict} of index '
                           f'{point.index} (order {order} sought)\n')
        if point.index != order or point.n_zero:
            zero = (f' and {point.n_zero} zero curvatures' if point.n_zero else '')
            self._stop(WrongIndexError(
                f'converged at step {self.nsteps} on a {point.verdict} of index '
                f'{point.index}{zero}, not of index {order}: lowest curvatures '
                f'{np.array2string(point.eigenvalues[:order + 2], precision=4)}; '
                'try another mode= or start'))

    def _preflight(self) -> None:
        """Stop with a NoEquilibriumError before the first step if the
        calculator proves the scene has no finite equilibrium
        (``calc.no_equilibrium``: a net load nothing holds; for
        ``target='minimum'``, spring components that fly away); evaluate.
        Energy and forces held from an earlier run are dropped (the
        calculator or the band may have changed since), and the step rule
        starts afresh if the scene changed (:meth:`_afresh_if_changed`)."""
        self.optimizable.held = None
        atoms = self._atoms()
        calc = getattr(atoms, 'calc', None)
        self._afresh_if_changed()
        if hasattr(calc, 'no_equilibrium'):
            why = calc.no_equilibrium(atoms, minimum=self.target == 'minimum')
            if why:
                self._stop(NoEquilibriumError(f'before the first step: {why}'))
        self._evaluate()

    def _stop(self, error: MaudError) -> None:
        """Write ``error``'s message to the log and raise it."""
        self.logfile.write(f'Maud: stopped: {error}\n')
        raise error


@dataclass(eq=False)
class _Handoff:
    """Positions, calculator and potential at the end of a step; equal to
    another when the positions are equal in every bit and the calculator and
    potential are the same objects."""

    x: np.ndarray
    calc: Any
    potential: Any

    def __eq__(self, other: object) -> bool:
        return (isinstance(other, _Handoff) and np.array_equal(self.x, other.x)
                and self.calc is other.calc and self.potential is other.potential)


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
        # x, E, gradient, and the calculator's forces object they came from
        self.held: tuple[np.ndarray, float, np.ndarray, Any] | None = None

    def __getattr__(self, name: str) -> Any:
        return getattr(self.inner, name)

    def get_value(self) -> float:
        return self._results()[1]

    def get_gradient(self) -> np.ndarray:
        return self._results()[2].copy()

    def _results(self) -> tuple[np.ndarray, float, np.ndarray]:
        x = self.inner.get_x()
        if (self.held is not None and np.array_equal(x, self.held[0])
                and self.held[3] is self._witness()):
            return self.held[:3]
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
        self.held = (x.copy(), value, gradient, self._witness())
        return self.held[:3]

    def _witness(self) -> Any:
        """The calculator's forces object behind the results held: a new
        calculation or a ``calc.set`` that drops the results (from an
        observer, say) replaces it, and the results are fetched again."""
        calc = getattr(getattr(self.inner, 'atoms', None), 'calc', None)
        results = getattr(calc, 'results', None)
        return results.get('forces') if isinstance(results, dict) else None

    def _fail(self, what: str) -> None:
        if self.good is None:
            where = 'the atoms are at their start positions'
        else:
            self.inner.set_x(self.good[0])
            where = f'positions restored to step {self.good[1]}'
        self.optimizer._stop(MaudError(f'the calculator returned {what} at step '
                                       f'{self.optimizer.nsteps}; {where}'))


def _check_mode(mode: Any, scene: Atoms | None) -> int | np.ndarray | None:
    """``mode`` (see :class:`Maud`) checked: None, a whole number >= 0, or a
    finite move of ``scene``'s N points, shape (N, 3) or (3 N,)."""
    if mode is None:
        return None
    if isinstance(mode, (int, np.integer)) and not isinstance(mode, bool):
        if mode < 0:
            raise ValueError(f'mode must be an index >= 0 of the Hessian\'s modes, '
                             f'got {mode!r}')
        return int(mode)
    n = 0 if scene is None else len(scene)
    try:
        move = np.asarray(mode, dtype=float)
    except (TypeError, ValueError):
        move = None
    if move is None or move.size != 3 * n or not np.isfinite(move).all():
        raise ValueError(f'mode must be None, an index of the Hessian\'s modes or a '
                         f'finite move of the {n} points, shape ({n}, 3); got {mode!r}')
    return move.reshape(n, 3)


def _other_scene(frame: Atoms, atoms: Atoms) -> str | None:
    """How a trajectory's ``frame`` and the ``atoms`` given differ (points,
    fixed points, and with a MaudCalculator its springs, a, Q, dim), or None."""
    from .calculator import MaudCalculator
    from .io import stored_parameters
    if len(frame) != len(atoms):
        return f'points {len(frame)} in it, {len(atoms)} in the atoms given'
    potential = getattr(atoms.calc, 'potential', None)
    stored = stored_parameters(frame)
    held = signature(frame, MaudCalculator(**stored).potential
                     if stored and potential is not None else None)
    return difference(held, signature(atoms, potential))


def _step_rule(model: StiffnessModel, scene: Atoms | None, image_size: int | None,
               steps: dict[str, Any], order: int | None = None) -> StepRule:
    """The step rule of ``model`` (:func:`~ase_maud.method.step_rule`, with
    the user's ``steps`` and the saddle ``order``) for what the model sees: a
    cell filter's coordinates (``scene`` None) get ASE's usual ``maxstep``
    instead of the nearest-neighbour bound; atoms under constraints ASE adjusts
    every move for (SHAKE for a bond length, which fails on a move long against
    the distances between points) keep the nearest-neighbour bound in every
    model."""
    rule = step_rule(model.name, model.target, image_size, order=order, **steps)
    if scene is None:
        return replace(rule, maxstep_nn=None, maxstep=rule.maxstep or CELL_MAXSTEP)
    if rule.maxstep_nn is None and not all(isinstance(c, PROJECTIONS)
                                           for c in getattr(scene, 'constraints', ())):
        return replace(rule, maxstep_nn=STEP_DEFAULTS['common']['maxstep_nn'])
    return rule


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
        check_writable(name, value)
    check_run_files(restart, logfile, trajectory)
    if not isinstance(append_trajectory, (bool, np.bool_)):
        raise ValueError(f'append_trajectory must be True or False, got '
                         f'{append_trajectory!r}')


def _image_size(system: Any) -> int | None:
    """Points per image if ``system`` optimizes a band of images (ASE's
    NEB optimizable, which has ``neb``), else None."""
    neb = getattr(system, 'neb', None)
    return None if neb is None else len(neb.images[0])
