"""Maud: the specification's step ``dr = gamma K^-1 f`` as an ASE optimizer.

This module is the ASE adapter only: it evaluates once per step, hands the
local model down to the strategy, watches the run and writes its files.
What a run is made of (model, target, step rule, strategy) is decided once
by :func:`ase_maud.assembly.assemble`; the step is a strategy
(:mod:`ase_maud.strategy`: :class:`~ase_maud.strategy.Minimise` or
:class:`~ase_maud.strategy.Saddle`, its state a
:class:`~ase_maud.strategy.MaudState`) over a local model
(:mod:`ase_maud.stiffness`); divergence and stagnation are watched by a
:class:`~ase_maud.monitor.RunMonitor`; the accuracy asked of the calculator
is :mod:`ase_maud.accuracy` (the user's own is put back when a run ends);
energies and forces are checked finite by
:class:`~ase_maud.evaluation.CheckedOptimizable`; every keyword is checked
by its rule in :data:`ase_maud.checks.RULES`.

- ``model='auto'`` (default): the whole scene's stiffness: the exact Hessian
  (saddle-free Newton) for small scenes, a sparse model with an L-BFGS
  memory for large ones; the specification's nodal blocks (``model='nodal'``,
  with ``method='tensor'`` or ``'scalar'``) and Day's momentum remain as
  options; a calculator with no stiffness gets BFGS's inverse Hessian
  (``'bfgs'``; the secant model ``kappa I`` for a band of images).
- ``target='minimum'`` makes every model positive definite, so no step is
  meant uphill; ``'stationary'`` keeps the signs: saddles and maxima are
  fixed points too; ``'saddle'`` climbs along ``order`` modes by eigenvector
  following and, once converged, checks the index of the point found
  (:class:`WrongIndexError` if it is another).
- Nothing silently wrong (docs/hard_cases.md): a bad keyword or run argument
  is a ValueError naming it; a non-finite energy or force puts the
  positions back to the last step whose results were finite and raises
  :class:`MaudError` naming the step and the value; the restart file
  (:mod:`ase_maud.restart`) is replaced atomically after each trajectory
  frame and holds the positions its state belongs to, so a run killed at any
  moment carries on exactly (:meth:`Maud.resume`).
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

import numpy as np
from ase import Atoms
from ase.filters import UnitCellFilter
from ase.optimize.optimize import DEFAULT_MAX_STEPS, Optimizer

from . import accuracy, arrays
from .analysis import Work
from .assembly import assemble, check_calculator
from .checks import check, check_all
from .evaluation import CheckedOptimizable, Handoff, in_rows_of_3
from .lock import FileInUseError, RunLock
from .monitor import (
    DivergenceError,
    MaudError,
    NoEquilibriumError,
    RunMonitor,
    StagnationError,
    WrongIndexError,
    divergence_judged,
    minimum_proved,
)
from .restart import RestartFile, RestartFileError, difference
from .run_files import SceneSignature, check_files, frame_atoms, other_scene
from .search import merit_tolerance
from .stiffness import SecantModel, StiffnessModel
from .strategy import StepRule
from .trajectory import last_step, repair

__all__ = ['DivergenceError', 'FileInUseError', 'Maud', 'MaudError', 'NoEquilibriumError',
           'StagnationError', 'WrongIndexError']


class Maud(Optimizer):
    """The Maud optimiser; see the module docstring, and docs/optimizer.md
    for every keyword and why it has its default.

    Parameters
    ----------
    atoms : Atoms (or anything with ``__ase_optimizable__``)
        The system to relax.
    model : 'auto', 'exact', 'global', 'nodal', 'bfgs', 'secant', 'springs' or a StiffnessModel
        The stiffness ``K`` of the step (:func:`ase_maud.stiffness.choose_model`);
        ``method`` ('tensor' or 'scalar') is the nodal model's, ``floor`` a
        model's relative eigenvalue floor, ``kappa0`` the secant and bfgs models' start.
    target : 'minimum', 'stationary', 'saddle' or None
        Only downhill, any stationary point, or one with exactly ``order``
        negative curvatures (``mode``: which Hessian mode, by index or by a
        move (N, 3), to climb first; :attr:`found` holds the converged point,
        a WrongIndexError says it is of another index). None: 'minimum', or
        'stationary' for a band of images (ASE's ``NEB``).
    gamma, gamma_max, gamma_growth, overshoot_shrink, beta_max, memory, maxstep_nn, maxstep
        The step rule (:data:`ase_maud.strategy.STEP_DEFAULTS`; None: the model's).
    divergence_factor, patience
        On a MaudCalculator's scene where no finite minimum is proved (no test
        on another calculator's): the growth of the scene between two
        looks at its forces (default 2; inf: no divergence test;
        :class:`ase_maud.monitor.RunMonitor`); steps without progress after
        which the run stops as stagnant (default 2000).
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
                 overshoot_shrink: float = 0.6, divergence_factor: float = 2.0,
                 patience: int = 2000, order: int = 1,
                 mode: int | np.ndarray | None = None, **kwargs: Any):
        steps = check_all(gamma=gamma, gamma_max=gamma_max, gamma_growth=gamma_growth,
                          beta_max=beta_max, memory=memory, maxstep_nn=maxstep_nn,
                          maxstep=maxstep, overshoot_shrink=overshoot_shrink)
        run = check_all(divergence_factor=divergence_factor, patience=patience)
        check_files(restart, logfile, trajectory, append_trajectory)
        self._lock = RunLock(restart, trajectory)
        self._lock.check()   # before ASE empties a trajectory another run writes
        if append_trajectory and isinstance(trajectory, (str, os.PathLike)):
            if (repaired := repair(trajectory)):
                warnings.warn(repaired, stacklevel=2)
        parts = assemble(atoms, model, target, steps, check('order', order), mode,
                         method=method, floor=floor, kappa0=kappa0)
        self.model, self.maud, self._subset = parts.model, parts.strategy, parts.subset
        self._points, self._scene = parts.points, SceneSignature()
        #: For ``target='saddle'``: the converged point's classification.
        self.found: Any = None
        self.divergence_factor, self.patience = run['divergence_factor'], run['patience']
        super().__init__(atoms, restart, logfile, trajectory,
                         append_trajectory=append_trajectory, **kwargs)
        self.optimizable = CheckedOptimizable(in_rows_of_3(self.optimizable),
                                              lambda: self.nsteps, self._stop)
        if parts.chosen and self.target == 'stationary':
            self.logfile.write("Maud: target='stationary' (the forces of a band of "
                               'images are not the gradient of its energy)\n')
        if isinstance(self.model, SecantModel):
            self.logfile.write(f'Maud: the calculator gives no stiffness; it is '
                               f'learnt from the forces ({self.model.name} model)\n')

    @property
    def target(self) -> str:
        """'minimum', 'stationary' or 'saddle': the model's."""
        return self.model.target

    @property
    def work(self) -> Work:
        """The Hessian-vector products and Hessians of the optimizer's runs so
        far, beside its calculator calls (force-call equivalents,
        :class:`~ase_maud.analysis.Work`)."""
        return self.model.work

    @property
    def rule(self) -> StepRule:
        """The step rule's settings."""
        return self.maud.rule

    def todict(self) -> dict[str, Any]:
        rule = self.rule
        saddle = {'order': rule.order} if self.target == 'saddle' else {}
        return {**super().todict(), **saddle, **self.model.todict(), 'target': self.target,
                **{name: getattr(rule, name) for name in (
                    'gamma', 'gamma_max', 'gamma_growth', 'overshoot_shrink', 'beta_max',
                    'memory', 'maxstep_nn')}}

    def initialize(self) -> None:
        check_calculator(self._atoms())   # after a restart file was read, as ASE's
        self._handoff: Handoff | None = None
        self.state = self.maud.start()
        atoms = self._atoms()
        self.monitor = RunMonitor(   # a cell filter's rows do not spread like points
            self.divergence_factor if self._points and divergence_judged(atoms) else np.inf,
            self.patience,
            merit_name='energy' if self.target == 'minimum' else '|f|^2',
            length_scale=getattr(getattr(atoms, 'calc', None), 'length_scale', 0.0),
            bounded=minimum_proved(atoms, self.target))
        self.fmax_now = np.inf   # largest force at the last step

    def read(self) -> None:
        """Take the restart file's state, and its positions (they win: the
        state belongs to them; a line in the log says if the atoms moved)."""
        data, name = self._restart_file().read(), repr(str(self.restart))
        if data['orig_cell'] is not None and isinstance(self.atoms, UnitCellFilter):
            self.atoms.orig_cell = data['orig_cell']   # the coordinates of its state
        x, here = data['x'].ravel(), self.optimizable.get_x()
        why = (f'points {x.size // 3} in it, {here.size // 3} in the atoms given'
               if x.shape != here.shape
               else difference(data['scene'], self._scene(self._atoms()), every=True))
        if why:
            raise ValueError(f'restart file {name} is of another scene: {why}; give '
                             'the atoms of that run, or delete the file')
        self.initialize()
        try:
            self.monitor.load(data['monitor'])   # this run counts its steps from 0 again
        except ValueError as error:
            raise RestartFileError(f'restart file {name} is damaged: {error}; delete '
                                   'it and its arrays file') from None
        if not np.array_equal(x, here):
            self.optimizable.set_x(x)
            self.logfile.write(f'Maud: the atoms moved to the positions of step '
                               f'{data["step"]} in {self.restart} (up to '
                               f'{np.abs(x - here).max():.3g} from the atoms given)\n')
        self.state, self.fmax_now = data['state'], data['fmax_now']

    def call_observers(self) -> None:
        """ASE's observers (the trajectory first), then the restart file: it
        is never ahead of the trajectory's last frame, and holds nothing
        before the first step (there is no state to carry on yet)."""
        super().call_observers()
        if self.restart is not None and self.comm.rank == 0 and self.state.last is not None:
            self._restart_file().write(self.nsteps, self.optimizable.get_x().reshape(-1, 3),
                                       self.state, self.monitor.todict(self.nsteps),
                                       self.fmax_now, self._scene(self._atoms()),
                                       self._orig_cell())

    def _orig_cell(self) -> np.ndarray | None:
        """A cell filter's original cell, which its coordinates are relative
        to (a restart file holds it: a filter made again on the last frame
        would measure from that frame's cell), or None."""
        return (np.array(self.atoms.orig_cell) if isinstance(self.atoms, UnitCellFilter)
                else None)

    def _restart_file(self) -> RestartFile:
        """The run's restart file (one per run: each step writes only what is
        new), with a row per mode a saddle search keeps."""
        if getattr(self, '_restart', None) is None:
            self._restart = RestartFile(self.restart, self.maud.kept_modes,
                                        self.model.kept_arrays)
        return self._restart

    @classmethod
    def resume(cls, atoms: Atoms, restart: str | Path = 'maud.json',
               trajectory: str | Path = 'maud.traj', **kwargs: Any) -> Maud:
        """Carry on a run that was stopped or killed at any moment.

        ``atoms`` are the run's atoms with their calculator and constraints
        (or the Filter, cell filter or NEB the run was given); they take the
        last whole step of ``trajectory`` if it has one (a NEB's images each
        their frame; the cell too under a cell filter), then the restart
        file's positions if it exists (its state belongs to them; it is never
        ahead of the trajectory, at most one frame behind, which is then
        written again). The trajectory is appended to; the resumed run makes
        the steps the uninterrupted one would have made. ``kwargs`` go to
        Maud.
        """
        images = frame_atoms(atoms)
        frames = last_step(trajectory, len(images)) or []
        for frame, image in zip(frames, images, strict=False):   # all checked first
            if (why := other_scene(frame, image)):
                raise ValueError(f'trajectory {str(trajectory)!r} is of another scene: '
                                 f'{why}; give the atoms of that run, or another '
                                 'trajectory')
        for frame, image in zip(frames, images, strict=False):
            if isinstance(atoms, UnitCellFilter):
                image.set_cell(frame.cell)
            image.set_positions(frame.positions, apply_constraint=False)
        return cls(atoms, restart=restart, trajectory=trajectory,
                   append_trajectory=True, **kwargs)

    def _replay_trajectory(self, frames: Any) -> None:
        """ASE's ``replay_trajectory``: learn from each step of an earlier
        run's trajectory (frames of the atoms this run moves, each with its
        forces) as from an accepted step (the model's state and the L-BFGS
        memory); the run then starts where it is."""
        last = None
        for frame in frames:
            x, forces = frame.get_positions(), frame.get_forces()
            if x.size != self.optimizable.get_x().size:
                raise ValueError(f'replay_trajectory: a frame of {len(x)} points, this '
                                 f'run moves {self.optimizable.get_x().size // 3}')
            if last is not None:
                self.maud.learn(self.state, x - last[0], last[1] - forces)
            last = x, forces

    # -- the step ---------------------------------------------------------------

    def _atoms(self) -> Atoms | None:
        """The Atoms the model and the calculator see: those behind the
        optimizable, the whole scene behind a Filter, or None (a band of
        images, a cell filter)."""
        if self._subset is not None:
            return self._subset.current()
        return getattr(getattr(self, 'optimizable', None), 'atoms', None)

    def _evaluate(self) -> None:
        """One calculator call for the energy, the forces and what the model
        needs (the Hessian, say), at the accuracy the run needs now."""
        atoms = self._atoms()
        if atoms is None:
            return
        accuracy.ask(atoms.calc, self.fmax, self.fmax_now)
        if (prop := self.model.needs(atoms)) is not None:
            atoms.calc.get_property(prop, atoms)
            self.work.hessians += prop == 'hessian'

    def _afresh_if_changed(self) -> None:
        """Start afresh if the atoms, the calculator or its potential changed
        since the last step (between two runs, or by an observer)."""
        if self._handoff is not None and self._handoff != self._handoff_now():
            self.initialize()
            self.logfile.write(f'Maud: the atoms or the calculator changed after step '
                               f'{self.nsteps}: the step rule starts afresh\n')

    def _handoff_now(self) -> Handoff:
        return Handoff.of(self.optimizable.get_x(), self._atoms())

    def step(self) -> None:
        self._afresh_if_changed()
        opt, state = self.optimizable, self.state
        x = opt.get_x().reshape(-1, 3)
        forces = -opt.get_gradient().reshape(-1, 3)
        merit = (opt.get_value() if self.target == 'minimum'
                 else float(np.vdot(forces, forces)))
        self.fmax_now = float(np.linalg.norm(forces, axis=1).max())
        noise = accuracy.noise(getattr(self._atoms(), 'calc', None))
        try:
            move = self.maud.step(state, x, merit, forces, noise, self._local_at)
            here = state.last
            self.monitor.check(self.nsteps, here.x, here.merit, here.forces, state.gamma,
                               min(self.rule.gamma, self.rule.gamma_max),
                               merit_tolerance(here.merit, noise))
        except MaudError as error:
            self._stop(error)
        if not np.isfinite(move).all():
            self._no_step(f'the {self.model.name} stiffness model gave a non-finite move')
        opt.set_x((here.x + move).ravel())
        self.maud.moved(state, opt.get_x().reshape(-1, 3))
        self._evaluate()
        self._handoff = self._handoff_now()

    def _local_at(self, x: np.ndarray) -> Any:
        """The local model at positions ``x`` (the atoms are moved there
        first if they are elsewhere: back to a point of a restart file)."""
        if not np.array_equal(self.optimizable.get_x().reshape(-1, 3), x):
            self.optimizable.set_x(x.ravel())
        try:
            solver = self.model.at(self._atoms(), self.state.model)
        except np.linalg.LinAlgError as error:
            self._no_step(f'the {self.model.name} stiffness model failed ({error})')
        return solver if self._subset is None else self._subset.solver(solver)

    def _no_step(self, why: str) -> None:
        """Stop: no finite step from here; a non-finite property of the
        calculator is named if it is the cause."""
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
        self.fmax, steps = check('fmax', fmax, 'run_fmax'), check('steps', steps)
        self._preflight()
        return self._locked(super().irun(self.fmax, steps))

    def _locked(self, steps: Iterator[bool]) -> Iterator[bool]:
        with self._lock, accuracy.kept(getattr(self._atoms(), 'calc', None)):
            for converged in steps:
                if converged:
                    self._verify()
                yield converged

    def run(self, fmax: float = 0.05, steps: int = DEFAULT_MAX_STEPS) -> bool:
        """ASE's ``run``; on arrays (:mod:`ase_maud.arrays`, the same steps)
        where nothing watches the run step by step."""
        self.fmax, steps = check('fmax', fmax, 'run_fmax'), check('steps', steps)
        self._preflight()
        observed = bool(self.observers) or self.restart is not None
        with self._lock, accuracy.kept(getattr(self._atoms(), 'calc', None)):
            if arrays.applies(self.atoms, self.model, observed):
                converged = self._run_on_arrays(steps)
            else:
                converged = super().run(self.fmax, steps)
        if converged:
            self._verify()
        return converged

    def _run_on_arrays(self, steps: int) -> bool:
        """ASE's loop (``Dynamics.irun``) over :func:`ase_maud.arrays.relax`."""
        self.max_steps = self.nsteps + steps
        relax = arrays.relax(self.atoms, self.model, self.maud, self.state, self.monitor,
                             self.fmax, min(self.rule.gamma, self.rule.gamma_max),
                             lambda: self.nsteps, self._no_step)
        name = type(self).__name__
        try:
            energy, self.fmax_now = next(relax)
            if self.nsteps == 0:
                arrays.log_line(self.logfile, name, 0, energy, self.fmax_now)
            while self.fmax_now >= self.fmax and self.nsteps < self.max_steps:
                energy, self.fmax_now = next(relax)
                self.nsteps += 1
                arrays.log_line(self.logfile, name, self.nsteps, energy, self.fmax_now)
        except MaudError as error:
            self._stop(error)
        finally:
            self.optimizable.held = None
            self._handoff = self._handoff_now()
        return self.fmax_now < self.fmax

    def gradient_converged(self, gradient: np.ndarray) -> bool:
        """ASE's test (``fmax``), and the strategy's: a saddle search also
        needs the index it seeks at the point (the minimum it starts from is
        left, not reported)."""
        return super().gradient_converged(gradient) and (
            self.target != 'saddle' or self.maud.index_reached(
                self.state, self._local_at(self.optimizable.get_x().reshape(-1, 3))))

    def _verify(self) -> None:
        """For ``target='saddle'``: the converged point classified from the
        analytic Hessian (:attr:`found`); a WrongIndexError if it is not of
        the index sought (:meth:`~ase_maud.strategy.Saddle.verify`). The exact
        model's Hessian there is the calculator's, counted already."""
        if self.target == 'saddle':
            work = None if self.model.complete_modes else self.work
            self.found, error = self.maud.verify(self._atoms(), max(self.fmax, self.fmax_now),
                                                 self.nsteps, work)
            self.logfile.write(f'Maud: converged on a {self.found.verdict} of index '
                               f'{self.found.index} (order {self.rule.order} sought)\n')
            if error is not None:
                self._stop(error)

    def _preflight(self) -> None:
        """Before the first step: a NoEquilibriumError if the calculator
        proves the scene has no finite equilibrium (``calc.no_equilibrium``);
        energy and forces held from an earlier run dropped, the step rule
        started afresh if the scene changed; an evaluation."""
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
