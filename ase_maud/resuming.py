"""Carrying a Maud run on: the restart file each step writes and reads,
the resume of a stopped or killed run, and ASE's replay of a trajectory.

:class:`Resumable` holds the ASE optimizer hooks that do it (``read``,
``call_observers``, ``_replay_trajectory``) and :meth:`Resumable.resume`;
:class:`~ase_maud.optimizer.Maud` inherits them. They use what the optimizer
holds: its strategy ``maud`` and ``state``, its ``model``, ``monitor`` and
``optimizable``, the scene's signature ``_scene`` and the atoms ``_atoms()``.
The file's format is :mod:`ase_maud.restart`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from ase import Atoms
from ase.filters import UnitCellFilter
from ase.optimize.optimize import Optimizer

from .restart import RestartFile, RestartFileError, difference
from .run_files import frame_atoms, other_scene
from .trajectory import last_step


class Resumable(Optimizer):
    """The restart file and the resume of :class:`~ase_maud.optimizer.Maud`
    (module docstring)."""

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
               trajectory: str | Path = 'maud.traj', **kwargs: Any) -> Resumable:
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
