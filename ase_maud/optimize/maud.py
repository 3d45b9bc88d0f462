"""Maud: the specification's step ``dr = gamma K^-1 f`` as an ASE optimizer.

This module is the ASE adapter only: it evaluates once per step, hands the
local model down to the strategy, watches the run and writes its files.
What a run is made of (model, target, step rule, strategy) is decided once
by :func:`ase_maud.optimize.run_setup.assemble`; the step is a strategy
(:mod:`ase_maud.optimize.strategy`: :class:`~ase_maud.optimize.strategy.Minimise` or
:class:`~ase_maud.optimize.strategy.Saddle`, its state a
:class:`~ase_maud.optimize.state.MaudState`) over a local model
(:mod:`ase_maud.optimize.models.base`); divergence and stagnation are watched by a
:class:`~ase_maud.optimize.monitor.RunMonitor`; the accuracy asked of the calculator
is :mod:`ase_maud.calculator.accuracy` (the user's own is put back when a run ends);
energies and forces are checked finite by
:class:`~ase_maud.optimize.evaluation.CheckedOptimizable`; every keyword is checked
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
  (:mod:`ase_maud.optimize.restart_file`) is replaced atomically after each trajectory
  frame and holds the positions its state belongs to, so a run killed at any
  moment carries on exactly (:meth:`Maud.resume`).
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

import numpy as np
from ase import Atoms
from ase.optimize.optimize import DEFAULT_MAX_STEPS, Optimizer

from ase_maud.calculator import accuracy
from ase_maud.checks import check, check_all
from ase_maud.counting import Work
from ase_maud.errors import (
    DivergenceError,
    FileInUseError,
    MaudError,
    NoEquilibriumError,
    RestartFileError,
    StagnationError,
    WrongIndexError,
)
from ase_maud.optimize import array_loop as arrays
from ase_maud.optimize.evaluation import CheckedOptimizable, Handoff, in_rows_of_3, no_step_error
from ase_maud.optimize.gauge import free_forces, free_view, gauge_point, held_move
from ase_maud.optimize.models.base import StiffnessModel
from ase_maud.optimize.monitor import RunMonitor, no_equilibrium
from ase_maud.optimize.resume import RunRestart, replay, to_last_step
from ase_maud.optimize.run_files import SceneSignature, open_run
from ase_maud.optimize.run_setup import assemble, check_calculator
from ase_maud.optimize.step_rules import StepRule

__all__ = ['DivergenceError', 'FileInUseError', 'Maud', 'MaudError', 'NoEquilibriumError',
           'StagnationError', 'WrongIndexError']


class Maud(Optimizer):
    """The Maud optimiser; see the module docstring, and docs/optimizer.md
    for every keyword and why it has its default.

    Units: lengths in ``a``, energies in ``Q a^2``, forces in ``Q a`` on a
    :class:`~ase_maud.MaudCalculator` (the calculator's own units, eV and
    Angstrom, on any other); forces have ASE's sign, ``f = -dE/dr``.

    Parameters
    ----------
    atoms : Atoms (or anything with ``__ase_optimizable__``)
        The system to relax: Atoms with a calculator that computes forces,
        a Filter, a cell filter or ASE's ``NEB``. Moved in place.
    restart : str or None, default None
        A restart file (``maud.json`` and its ``maud.json.arrays``) written
        after each step; if it exists, the run carries on from it
        (:meth:`resume`).
    logfile : file, str or None, default '-'
        ASE's log: ``'-'`` standard output, a file name or an open file.
    trajectory : str or None, default None
        An ASE trajectory written at each step.
    append_trajectory : bool, default False
        Append to ``trajectory`` instead of starting it afresh.
    model : 'auto', a name of ``ase_maud.optimize.models.registry.MODELS`` or a StiffnessModel
        The stiffness ``K`` of the step (:func:`ase_maud.optimize.models.registry.choose_model`):
        'auto' takes the exact Hessian up to 150 free coordinates, the
        springs model above, 'bfgs' for a calculator with forces only.
    method : 'tensor' or 'scalar', default 'tensor'
        The nodal model's blocks (``model='nodal'``, the specification's step).
    target : 'minimum', 'stationary', 'saddle' or None
        Only downhill, any stationary point, or one with exactly ``order``
        negative curvatures (:attr:`found`: the point, classified). None:
        'minimum' ('stationary' for a band of images, ASE's ``NEB``).
    gamma, gamma_max, gamma_growth, overshoot_shrink : float or None
        The step rule (:data:`ase_maud.optimize.step_rules.STEP_DEFAULTS`;
        None: the model's): the step factor, its cap and growth, the cut
        after an overshoot.
    beta_max, memory, maxstep_nn, maxstep : float, int or None
        Day's momentum cap, the L-BFGS memory (pairs), the largest move of
        a point as a fraction of its nearest distance (below 0.5), and the
        largest move of a point (``a``) where there is no such distance.
    floor : float or None, default None
        A model's relative eigenvalue floor (None: the model's).
    kappa0 : float, default 70.0
        The secant and bfgs models' starting curvature (energy per length
        squared, ASE's 70 eV/A^2).
    divergence_factor : float, default 2.0
        The growth of a MaudCalculator's scene between two looks at its
        forces; two looks that see no balance ahead stop the run as
        diverging (``inf``: never).
    patience : int, default 2000
        Steps without progress that stop the run as stagnant.
    order : int, default 1
        The index sought with ``target='saddle'``.
    mode : int, array (N, 3) or None, default None
        With ``target='saddle'``: the Hessian mode to climb first, by index
        (0 the lowest) or as a move.
    **kwargs
        As for every ASE optimizer (``maxstep`` of ASE, ``master``, ...).

    Raises
    ------
    ValueError
        A keyword outside its rule (named, with what it accepts), atoms
        without a calculator that computes forces, ``target='saddle'``
        with every coordinate held, or a file argument that cannot be
        written.
    FileInUseError
        Another run holds the lock of ``trajectory`` or ``restart``.
    RestartFileError
        ``restart`` exists but is damaged, of another scene or of another
        version (raised by :meth:`run` when it reads it).

    See Also
    --------
    ase_maud.MaudCalculator : the calculator whose stiffness the default model uses.
    ase_maud.search_saddles : saddles from a minimum, several attempts.
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
        self._lock = open_run(restart, logfile, trajectory, append_trajectory)
        parts = assemble(atoms, model, target, steps, check('order', order), mode,
                         method=method, floor=floor, kappa0=kappa0)
        self.model, self.strategy, self._subset = parts.model, parts.strategy, parts.subset
        #: The run's restart file (None without one): :class:`~ase_maud.optimize.resume.RunRestart`.
        self.run_restart = (None if restart is None else
                            RunRestart(restart, self.strategy.kept_modes, self.model.kept_arrays))
        self._points, self._scene = parts.points, SceneSignature()
        #: For ``target='saddle'``: the converged point's classification.
        self.found: Any = None
        self._stopped_by: MaudError | None = None
        self.divergence_factor, self.patience = check_all(
            divergence_factor=divergence_factor, patience=patience).values()
        super().__init__(atoms, restart, logfile, trajectory,
                         append_trajectory=append_trajectory, **kwargs)
        self.optimizable = CheckedOptimizable(in_rows_of_3(self.optimizable),
                                              lambda: self.nsteps, self._stop)
        self.logfile.write(''.join(parts.notes))
        #: A saddle search held at one point: the free scene's (optimize.gauge).
        self._gauge = gauge_point(self._atoms()) if self.target == 'saddle' else None

    @property
    def target(self) -> str:
        """'minimum', 'stationary' or 'saddle': the model's."""
        return self.model.target

    @property
    def work(self) -> Work:
        """The Hessian-vector products and Hessians of its runs so far (:class:`Work`)."""
        return self.model.work

    @property
    def rule(self) -> StepRule:
        """The step rule's settings."""
        return self.strategy.rule

    def todict(self) -> dict[str, Any]:
        return {**super().todict(), **self.model.todict(), **self.rule.todict()}

    def initialize(self) -> None:
        check_calculator(self._atoms())   # after a restart file was read, as ASE's
        self._handoff: Handoff | None = None
        self.state = self.strategy.start()
        self.monitor = RunMonitor.of_run(self._atoms(), self.target, self.divergence_factor,
                                         self.patience, self._points, self.strategy.band)
        self.fmax_now = np.inf   # largest force at the last step

    def _atoms(self) -> Atoms | None:
        """The Atoms the model and the calculator see: the optimizable's, the
        whole scene behind a Filter, or None (a band of images, a cell filter)."""
        return (self._subset.current() if self._subset is not None
                else getattr(getattr(self, 'optimizable', None), 'atoms', None))

    def _evaluate(self, ask: bool = True) -> None:
        """One call: energy, forces and what the model needs, at the accuracy
        needed now (``ask=False``: at the calculator's own)."""
        atoms = self._atoms()
        if atoms is None:
            return
        if ask:
            accuracy.ask(atoms.calc, self.fmax, self.fmax_now)
        if (prop := self.model.needs(atoms)) is not None:
            atoms.calc.get_property(prop, atoms)
            self.work.hessians += prop == 'hessian'

    def _afresh_if_changed(self) -> None:
        """Start afresh if the atoms or the calculator changed since the last step."""
        now = Handoff.of(self.optimizable.get_x(), self._atoms())
        if self._handoff is not None and self._handoff != now:
            self.initialize()
            self.logfile.write(f'Maud: the atoms or the calculator changed after step '
                               f'{self.nsteps}: the step rule starts afresh\n')

    def step(self) -> None:
        self._afresh_if_changed()
        opt = self.optimizable
        forces = -opt.get_gradient().reshape(-1, 3)
        start = opt.get_x().reshape(-1, 3)
        if self._gauge is not None:
            forces = free_forces(forces, self._gauge)
        calc = getattr(self._atoms(), 'calc', None)
        if self.target == 'minimum':
            merit = opt.get_value()
            noise = accuracy.energy_noise(calc, merit)
        else:
            merit, noise = float(np.vdot(forces, forces)), accuracy.force_noise(calc)
        self.fmax_now = float(np.linalg.norm(forces, axis=1).max())
        try:
            x = arrays.next_positions(self.strategy, self.state, self.monitor, self.nsteps,
                                      opt.get_x().reshape(-1, 3), merit, forces, noise,
                                      self._local_at, self._no_step)
        except MaudError as error:
            self._stop(error)
        if self._gauge is not None:
            x = held_move(x, start, self._gauge)
        opt.set_x(x.ravel())
        self.strategy.moved(self.state, opt.get_x().reshape(-1, 3))
        self._evaluate()
        self._handoff = Handoff.of(opt.get_x(), self._atoms())

    def _local_at(self, x: np.ndarray) -> Any:
        """The local model at ``x`` (the atoms moved there first if elsewhere)."""
        if not np.array_equal(self.optimizable.get_x().reshape(-1, 3), x):
            self.optimizable.set_x(x.ravel())
        try:
            atoms = self._atoms()
            if getattr(self, '_gauge', None) is not None:
                atoms = free_view(atoms, self._gauge)
            solver = self.model.at(atoms, self.state.model)
        except np.linalg.LinAlgError as error:
            self._no_step(f'the {self.model.name} stiffness model failed ({error})')
        return solver if self._subset is None else self._subset.solver(solver)

    def _no_step(self, why: str) -> None:
        """Stop: no finite step from here (:func:`~ase_maud.optimize.evaluation.no_step_error`)."""
        self._stop(no_step_error(self.nsteps, why, self.model, self._atoms()))

    def irun(self, fmax: float = 0.05, steps: int = DEFAULT_MAX_STEPS) -> Iterator[bool]:
        """ASE's ``irun``: the run step by step, one bool a step.

        Parameters
        ----------
        fmax, steps : float, int
            As for :meth:`run` (``Q a``; the most steps).

        Yields
        ------
        bool
            Whether the run has converged, after each step.

        Raises
        ------
        ValueError, NoEquilibriumError
            As :meth:`run`, when ``irun`` is called (not when iterated).
        MaudError, RestartFileError
            As :meth:`run`, from the step where they arise.
        """
        # bad arguments refused here, not when iterated; the first call at the
        # calculator's own accuracy (a generator never iterated would not put back
        # a tol asked here)
        steps = self._preflight(fmax, steps, ask=False)
        return self._locked(super().irun(self.fmax, steps))

    def _locked(self, steps: Iterator[bool]) -> Iterator[bool]:
        with self._lock, accuracy.kept(getattr(self._atoms(), 'calc', None)):
            for converged in steps:
                if converged:
                    self._verify()
                yield converged

    def run(self, fmax: float = 0.05, steps: int = DEFAULT_MAX_STEPS) -> bool:
        """ASE's ``run``; on arrays (:mod:`ase_maud.optimize.array_loop`, the same steps)
        where nothing watches the run step by step.

        Parameters
        ----------
        fmax : float, default 0.05
            Converged when the largest force on a point is below ``fmax``
            (``Q a`` on a MaudCalculator; for ``target='saddle'`` the index
            must be reached too). Write ``1e-300`` to run exactly ``steps``.
        steps : int, default ASE's ``DEFAULT_MAX_STEPS``
            The most steps to take (0 takes none).

        Returns
        -------
        bool
            True if converged; False if ``steps`` ran out first (no error).

        Raises
        ------
        ValueError
            ``fmax`` not a positive finite number, ``steps`` not a whole
            number >= 0, or atoms the calculator refuses (named).
        NoEquilibriumError
            The scene is proved to have no finite equilibrium (before the
            first step; the atoms are not moved).
        MaudError
            The run cannot go on: :class:`DivergenceError`,
            :class:`StagnationError`, :class:`WrongIndexError`, a non-finite
            energy or force (the positions are those of the last finite
            step); the message is in the log too.
        FileInUseError
            A file of this run was written by another run since it started.
        RestartFileError
            The restart file cannot be read or is of another run.
        """
        with accuracy.kept(getattr(self._atoms(), 'calc', None)):
            steps = self._preflight(fmax, steps, ask=True)
            with self._lock:
                try:
                    converged = (arrays.run(self, steps, self._no_step, self._stop)
                                 if arrays.applies(self)
                                 else super().run(self.fmax, steps))
                finally:   # the atoms moved outside the optimizable
                    self.optimizable.held = None
                    self._handoff = Handoff.of(self.optimizable.get_x(), self._atoms())
        if converged:
            self._verify()
        return converged

    def gradient_converged(self, gradient: np.ndarray) -> bool:
        """ASE's test (``fmax``; on forces fine enough to say so, computed
        again if they are not: :func:`.accuracy.settled`), and a saddle
        search's: its index reached."""
        if not super().gradient_converged(gradient):
            return False
        calc = getattr(self._atoms(), 'calc', None)
        if not accuracy.settled(calc, self.fmax, float(np.linalg.norm(
                gradient.reshape(-1, 3), axis=1).max())):
            accuracy.ask(calc, self.fmax, 0.0)
            if not super().gradient_converged(self.optimizable.get_gradient()):
                return False
        return self.strategy.index_reached(
            self.state, lambda: self._local_at(self.optimizable.get_x().reshape(-1, 3)))

    def _verify(self) -> None:
        """For ``target='saddle'``: the point found, classified (:attr:`found`)."""
        if self.target == 'saddle':
            self.found, error = self.strategy.verify(self._atoms(), max(self.fmax, self.fmax_now),
                                                 self.nsteps, self.work, None if self._subset
                                                 is not None else self.state.modes)
            self.logfile.write(f'Maud: converged on a {self.found.verdict} of index '
                               f'{self.found.index} (order {self.rule.order} sought)\n')
            if error is not None:
                self._stop(error)

    def _preflight(self, fmax: float, steps: int, ask: bool) -> int:
        """Before the first step: arguments checked (``steps`` returned), no proof of
        no equilibrium, held results dropped, a changed scene afresh, an evaluation
        (at the accuracy the run asks if ``ask``, else the calculator's own)."""
        self.fmax, steps = check('fmax', fmax, 'run_fmax'), check('steps', steps)
        self.optimizable.held = None
        self._afresh_if_changed()
        if (error := no_equilibrium(self._atoms(), self.target)) is not None:
            self._stop(error)
        self._evaluate(ask)
        return steps

    def _stop(self, error: MaudError) -> None:
        """Log ``error`` (once: it may pass here again on its way out), raise it."""
        if error is not self._stopped_by:
            self.logfile.write(f'Maud: stopped: {error}\n')
            self._stopped_by = error
        raise error

    # The restart file and the trajectory: ASE's hooks.

    def read(self) -> None:
        """Take the restart file's state, and its positions (they win: the
        state belongs to them; a line in the log says if the atoms moved)."""
        data = self.run_restart.read(self.atoms)
        x, here = data['x'].ravel(), self.optimizable.get_x()
        self.run_restart.check_scene(data, here, self._scene(self._atoms()))
        self.initialize()
        try:
            self.monitor.load(data['monitor'])   # this run counts its steps from 0 again
        except ValueError as error:
            raise RestartFileError(f'restart file {str(self.restart)!r} is damaged: {error}; '
                                   'delete it and its arrays file') from None
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
        if self.run_restart is not None and self.comm.rank == 0 and self.state.last is not None:
            self.run_restart.write(self.nsteps, self.optimizable.get_x().reshape(-1, 3),
                                   self.state, self.monitor.todict(self.nsteps),
                                   self.fmax_now, self._scene(self._atoms()), self.atoms)

    def _replay_trajectory(self, frames: Any) -> None:
        """ASE's ``replay_trajectory``: learn from each step of an earlier
        run's trajectory as from an accepted step; the run then starts where
        it is (:func:`~ase_maud.optimize.resume.replay`)."""
        replay(self.strategy, self.state, frames, self.optimizable.get_x().size)

    @classmethod
    def resume(cls, atoms: Atoms, restart: str | Path = 'maud.json',
               trajectory: str | Path = 'maud.traj', **kwargs: Any) -> Maud:
        """Carry on a run that was stopped or killed at any moment.

        ``atoms`` are the run's atoms with their calculator and constraints
        (or the Filter, cell filter or NEB the run was given); they take the
        last whole step of ``trajectory`` if it has one
        (:func:`~ase_maud.optimize.resume.to_last_step`), then the restart
        file's positions if it exists (its state belongs to them; it is never
        ahead of the trajectory, at most one frame behind, which is then
        written again). The trajectory is appended to; the resumed run makes
        the steps the uninterrupted one would have made.

        Parameters
        ----------
        atoms : Atoms, Filter or NEB
            The run's atoms (moved in place).
        restart : str or Path, default 'maud.json'
            The run's restart file (need not exist).
        trajectory : str or Path, default 'maud.traj'
            The run's trajectory, appended to (a damaged end is dropped,
            the cut file kept as ``NAME.damaged``).
        **kwargs
            The other keywords of :class:`Maud`, as the run was given them.

        Returns
        -------
        Maud
            The optimizer; call :meth:`run` on it.

        Raises
        ------
        ValueError
            A trajectory that cannot be read (cut into its header), or a
            keyword outside its rule.
        RestartFileError
            The restart file or trajectory is of another scene (the
            difference named), damaged, or of another version.
        FileInUseError
            Another run holds the lock of these files.
        """
        to_last_step(atoms, trajectory)
        return cls(atoms, restart=restart, trajectory=trajectory,
                   append_trajectory=True, **kwargs)
