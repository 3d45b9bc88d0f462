"""A Maud run on arrays: the minimiser's loop without ASE's per-step
plumbing, for a scene no one watches step by step.

ASE's loop asks the optimizable for the forces and the energy several times
a step, each request a property lookup with its change detection and a copy
of the atoms, and moves the atoms through their constraints; on a scene of
tens of points that is most of a step. :func:`run` makes the same steps as
ASE's loop with :class:`~ase_maud.optimize.maud.Maud`'s ``step`` (same positions,
calls and log, bit for bit), but per step it moves the positions array and
asks the calculator once for the energy, forces and whatever the local model
needs (the exact model's Hessian: one pass of its kernel), then builds the
local model there (:func:`relax`). It applies where :func:`applies` says:
plain ``Atoms`` whose only constraints hold coordinates (``FixAtoms``,
``FixCartesian``) and a MaudCalculator, a run seeking a minimum, and no
trajectory, restart file or attached observer (the log is written as ASE
writes it). With the exact model the steps are compiled
(:mod:`~ase_maud.optimize.compiled_step`, where it applies: the same moves
to round-off). The calculator holds the results of the last positions
throughout, so a run stopped at any step leaves the atoms and their results
consistent.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from typing import IO, Any

import numpy as np
from ase import Atoms
from ase.constraints import FixAtoms, FixCartesian

from ase_maud.calculator import accuracy
from ase_maud.calculator.maud_calculator import MaudCalculator
from ase_maud.errors import MaudError
from ase_maud.optimize import compiled_step
from ase_maud.optimize.models.base import StiffnessModel
from ase_maud.optimize.monitor import RunMonitor
from ase_maud.optimize.state import LocalAt, MaudState
from ase_maud.optimize.step_length import lengths, merit_tolerance
from ase_maud.optimize.strategy import Strategy
from ase_maud.physics.dofs import free_dofs


def applies(opt: Any) -> bool:
    """Whether the run of the optimizer ``opt`` (a
    :class:`~ase_maud.optimize.maud.Maud`) can go on arrays: its system plain
    Atoms with a MaudCalculator (it computes the results of positions it is
    handed, :meth:`~ase_maud.MaudCalculator.compute`), held by coordinate
    masks only, seeking a minimum, and nothing watching it per step (a
    trajectory, a restart file, an attached observer)."""
    atoms = opt.atoms
    return (type(atoms) is Atoms and isinstance(atoms.calc, MaudCalculator)
            and opt.model.target == 'minimum' and not opt.observers and opt.restart is None
            and all(isinstance(c, (FixAtoms, FixCartesian)) for c in atoms.constraints))


def log_line(logfile: IO | None, name: str, step: int, energy: float, fmax: float) -> None:
    """The line ASE's ``Optimizer.log`` writes for ``step`` (with its header
    before step 0); none for no ``logfile`` (:func:`run` gives None for ASE's
    log of ``logfile=None``, which writes nothing: no clock read and no line
    formatted for it, a few microseconds of a small scene's step)."""
    if logfile is None:
        return
    if step == 0:
        logfile.write(f'{" " * len(name)}  {"Step":>4} {"Time":>8} {"Energy":>15}  '
                      f'{"fmax":>12}\n')
    now = time.localtime()
    logfile.write(f'{name}:  {step:3d} {now[3]:02d}:{now[4]:02d}:{now[5]:02d} '
                  f'{energy:15.6f} {fmax:15.6f}\n')


def relax(atoms: Atoms, model: StiffnessModel, strategy: Strategy, state: MaudState,
          monitor: RunMonitor, fmax: float, step: Callable[[], int],
          no_step: Callable[[str], None]) -> Iterator[tuple[float, float]]:
    """The energy and the largest force at the start, then after each step
    (taken when the next value is asked for), as ASE's loop would make them.
    ``fmax`` is the run's (the accuracy asked of the calculator follows it),
    ``step()`` the optimizer's step count, ``no_step(why)`` stops the run (it
    raises)."""
    calc = atoms.calc
    held = ~free_dofs(atoms, 3)
    holds = bool(held.any())
    positions = atoms.arrays['positions']

    def held_results() -> tuple[float, np.ndarray]:
        """The energy and forces the calculator holds (held components zero)."""
        forces = calc.results['forces'].copy()
        if holds:
            forces[held] = 0.0
        return calc.results['energy'], forces

    def evaluate(moved: bool) -> tuple[float, np.ndarray]:
        """The energy and forces at the positions and what the model needs
        there, asked for (and counted) as the optimizer's evaluation asks:
        computed anew if the positions ``moved``, else from the results held
        (computed if they lack it)."""
        needed = model.needs(atoms)
        if moved:
            calc.compute(atoms, [needed or 'forces'])
        else:
            calc.get_property(needed or 'forces', atoms)
        model.work.hessians += needed == 'hessian'
        return held_results()

    def local_at(x: np.ndarray) -> Any:
        here = bool((x == positions).all())   # where the calculator's results are
        positions[:] = x   # (elsewhere: where a resumed run's step began)
        try:
            return (model.of_results(atoms, calc.results, state.model) if here
                    else model.at(atoms, state.model))
        except np.linalg.LinAlgError as error:
            no_step(f'the {model.name} stiffness model failed ({error})')

    calc.get_property('forces', atoms)   # the optimizer's first evaluation (counted there)
    energy, forces = held_results()
    fmax_now = float(lengths(forces).max())
    while True:
        if fmax_now < fmax and not accuracy.settled(calc, fmax, fmax_now):
            # below fmax on sums too coarse to say so: the same positions, finely
            accuracy.ask(calc, fmax, fmax_now)
            energy, forces = evaluate(True)
            fmax_now = float(lengths(forces).max())
        yield energy, fmax_now
        x = next_positions(strategy, state, monitor, step(), positions.copy(), energy,
                           forces, accuracy.energy_noise(calc, energy), local_at, no_step)
        if holds:
            x[held] = positions[held]
        strategy.moved(state, x)
        moved = not (x == positions).all()
        positions[:] = x
        accuracy.ask(calc, fmax, fmax_now)
        energy, forces = evaluate(moved)
        fmax_now = float(lengths(forces).max())


def next_positions(strategy: Strategy, state: MaudState, monitor: RunMonitor, step: int,
                   x: np.ndarray, merit: float, forces: np.ndarray, noise: float,
                   local_at: LocalAt, no_step: Callable[[str], None]) -> np.ndarray:
    """The positions (N, 3) the strategy's step from ``x`` (its ``merit``,
    ``forces`` and their relative error ``noise``) reaches, before the
    constraints, the run watched by ``monitor`` at ``step``; ``no_step(why)``
    stops a run whose move is not finite. The step of both loops: ASE's
    (:meth:`Maud.step <ase_maud.optimize.maud.Maud.step>`) and :func:`relax`."""
    move = strategy.step(state, x, merit, forces, noise, local_at)
    here = state.last
    monitor.check(step, here.x, here.merit, here.forces, state.gamma, strategy.rule.gamma0,
                  merit_tolerance(here.merit, noise))
    if not np.isfinite(move).all():
        no_step(f'the {strategy.model.name} stiffness model gave a non-finite move')
    return here.x + move


def run(opt: Any, steps: int, no_step: Callable[[str], None],
        stop: Callable[[MaudError], None]) -> bool:
    """ASE's loop (``Dynamics.irun``) over :func:`relax` for the optimizer
    ``opt`` (a :class:`~ase_maud.optimize.maud.Maud` on which :func:`applies`):
    at most ``steps`` steps to its ``fmax``, logged as ASE logs them;
    ``no_step(why)`` stops a run with no finite step, ``stop(error)`` any
    other MaudError (both raise). Returns whether it converged."""
    opt.max_steps = opt.nsteps + steps
    steps_made = (compiled_step.relax(opt.atoms, opt.strategy, opt.state, opt.monitor,
                                      lambda: opt.nsteps, no_step)
                  if compiled_step.applies(opt.strategy, opt.state, opt.atoms)
                  else relax(opt.atoms, opt.model, opt.strategy, opt.state, opt.monitor,
                             opt.fmax, lambda: opt.nsteps, no_step))
    name = type(opt).__name__
    logfile = None if getattr(opt.logfile, '_logfile', '') is None else opt.logfile
    try:
        energy, opt.fmax_now = next(steps_made)
        if opt.nsteps == 0:
            log_line(logfile, name, 0, energy, opt.fmax_now)
        while opt.fmax_now >= opt.fmax and opt.nsteps < opt.max_steps:
            energy, opt.fmax_now = next(steps_made)
            opt.nsteps += 1
            log_line(logfile, name, opt.nsteps, energy, opt.fmax_now)
    except MaudError as error:
        stop(error)
    return opt.fmax_now < opt.fmax
