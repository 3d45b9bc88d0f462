"""Carrying a Maud run on: the restart file each step writes and reads,
the resume of a stopped or killed run, and ASE's replay of a trajectory.

A :class:`~ase_maud.optimize.maud.Maud` run owns one :class:`RunRestart`
(``opt.run_restart``; None without a restart file): after each step Maud's
``call_observers`` writes to it what the step leaves (positions, the
strategy's state, the monitor's counts, the scene's signature), and at the
start Maud's ``read`` takes it back, checked to be of the atoms given.
:func:`to_last_step` puts the atoms where a trajectory's last whole step
left them (:meth:`~ase_maud.optimize.maud.Maud.resume`), and :func:`replay`
teaches a strategy the steps of a trajectory (ASE's ``replay_trajectory``).
The file's format is :mod:`ase_maud.optimize.restart_file`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from ase.filters import UnitCellFilter

from ase_maud.files.trajectory import last_step
from ase_maud.optimize.restart_file import RestartFile, difference
from ase_maud.optimize.run_files import frame_atoms, other_scene
from ase_maud.optimize.state import MaudState


class RunRestart:
    """The restart file of one run at ``path``, with a row per mode the
    strategy keeps (``kept_modes``) and the model's learnt arrays
    (``kept_arrays``). The file is opened on first use, once per run: each
    step then writes only what is new."""

    def __init__(self, path: str | Path, kept_modes: int | None,
                 kept_arrays: tuple[str, ...]):
        self.path = path
        self._kept = kept_modes, kept_arrays
        self._file: RestartFile | None = None

    @property
    def file(self) -> RestartFile:
        """The :class:`~ase_maud.optimize.restart_file.RestartFile`."""
        if self._file is None:
            self._file = RestartFile(self.path, *self._kept)
        return self._file

    def read(self, atoms: Any) -> dict[str, Any]:
        """The file's fields (:meth:`RestartFile.read`); a cell filter
        ``atoms`` takes its original cell back first (its coordinates are
        relative to it)."""
        data = self.file.read()
        if data['orig_cell'] is not None and isinstance(atoms, UnitCellFilter):
            atoms.orig_cell = data['orig_cell']
        return data

    def check_scene(self, data: dict[str, Any], here: np.ndarray,
                    scene: dict[str, Any]) -> None:
        """A ValueError if the file's run moved other points (``here``: the
        coordinates given) or another scene (``scene``: its signature now)."""
        x = data['x'].ravel()
        why = (f'points {x.size // 3} in it, {here.size // 3} in the atoms given'
               if x.shape != here.shape else difference(data['scene'], scene, every=True))
        if why:
            raise ValueError(f'restart file {str(self.path)!r} is of another scene: {why}; '
                             'give the atoms of that run, or delete the file')

    def write(self, step: int, x: np.ndarray, state: MaudState, monitor: dict[str, Any],
              fmax_now: float, scene: dict[str, Any], atoms: Any) -> None:
        """Write one step: ``x`` (N, 3), the strategy's ``state``, the
        monitor's counts, the largest force, the scene's signature, and a
        cell filter ``atoms``' original cell (a filter made again on the
        last frame would measure from that frame's cell)."""
        orig_cell = (np.array(atoms.orig_cell) if isinstance(atoms, UnitCellFilter)
                     else None)
        self.file.write(step, x, state, monitor, fmax_now, scene, orig_cell)

def to_last_step(atoms: Any, trajectory: str | Path) -> None:
    """Put ``atoms`` (Atoms, a Filter, a cell filter or a NEB: each image
    its frame; the cell too under a cell filter) where the last whole step
    of ``trajectory`` left them, if it has one; a ValueError, before any
    atom moves, if a frame is of another scene."""
    images = frame_atoms(atoms)
    frames = last_step(trajectory, len(images)) or []
    for frame, image in zip(frames, images, strict=False):   # all checked first
        if (why := other_scene(frame, image)):
            raise ValueError(f'trajectory {str(trajectory)!r} is of another scene: '
                             f'{why}; give the atoms of that run, or another trajectory')
    for frame, image in zip(frames, images, strict=False):
        if isinstance(atoms, UnitCellFilter):
            image.set_cell(frame.cell)
        image.set_positions(frame.positions, apply_constraint=False)

def replay(strategy: Any, state: MaudState, frames: Any, size: int) -> None:
    """Teach ``strategy`` (its ``state``) each step of an earlier run's
    ``frames`` (of the atoms this run moves, ``size`` coordinates, each with
    its forces) as an accepted step: the model's state and the L-BFGS
    memory."""
    last = None
    for frame in frames:
        x, forces = frame.get_positions(), frame.get_forces()
        if x.size != size:
            raise ValueError(f'replay_trajectory: a frame of {len(x)} points, this '
                             f'run moves {size // 3}')
        if last is not None:
            strategy.learn(state, x - last[0], last[1] - forces)
        last = x, forces
