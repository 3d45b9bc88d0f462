"""The files of a run: the arguments that name them, checked before any
work, and whether a trajectory or a restart file belongs to the atoms given
(:func:`~ase_maud.optimize.restart_file.signature`, computed once per calculator and
constraints by :class:`SceneSignature`)."""

from __future__ import annotations

import os
import warnings
from typing import Any

import numpy as np
from ase import Atoms
from ase.filters import Filter
from ase.mep.neb import BaseNEB

from ase_maud.calculator.identify import potential_of, stored_parameters
from ase_maud.calculator.maud_calculator import MaudCalculator
from ase_maud.checks import check_writable
from ase_maud.files.output_paths import check_run_files
from ase_maud.files.run_lock import RunLock
from ase_maud.files.trajectory import repair
from ase_maud.optimize.restart_file import difference, signature


class SceneSignature:
    """The :func:`~ase_maud.optimize.restart_file.signature` of a run's atoms, kept while
    the calculator, its potential, the number of atoms and the constraints
    are the same objects (empty without atoms: a filter's rows)."""

    def __init__(self) -> None:
        self._key: tuple | None = None
        self._held: dict[str, Any] = {}

    def __call__(self, atoms: Atoms | None) -> dict[str, Any]:
        if atoms is None:
            return {}
        potential = potential_of(atoms)
        key = (id(atoms.calc), id(potential), len(atoms),
               tuple(map(id, atoms.constraints)))
        if self._key != key:
            self._key = key
            self._held = signature(atoms, potential)
        return self._held


def frame_atoms(system: Any) -> list[Atoms]:
    """The Atoms each step of a run on ``system`` writes to its trajectory,
    one frame each: the images of a band (ASE's NEB), the atoms behind a
    Filter or a cell filter, or the atoms themselves."""
    if isinstance(system, BaseNEB):
        return list(system.images)
    if isinstance(system, Filter):
        return [system.atoms]
    return [system]


def other_scene(frame: Atoms, atoms: Atoms) -> str | None:
    """How a trajectory's ``frame`` and the ``atoms`` given differ (points,
    fixed points, and with a MaudCalculator its springs, a, Q, dim), or None."""
    if len(frame) != len(atoms):
        return f'points {len(frame)} in it, {len(atoms)} in the atoms given'
    potential = potential_of(atoms)
    stored = stored_parameters(frame)
    held = signature(frame, MaudCalculator(**stored).potential
                     if stored and potential is not None else None)
    return difference(held, signature(atoms, potential))


def check_files(restart: Any, logfile: Any, trajectory: Any,
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


def open_run(restart: Any, logfile: Any, trajectory: Any, append_trajectory: Any) -> RunLock:
    """A run's files made ready before ASE opens them: the arguments checked
    (:func:`check_files`), the lock of the restart file and trajectory
    checked free (before ASE empties a trajectory another run writes), and a
    trajectory to append to repaired (a warning says what was cut). Returns
    the lock the run holds while it steps."""
    check_files(restart, logfile, trajectory, append_trajectory)
    lock = RunLock(restart, trajectory)
    lock.check()
    if append_trajectory and isinstance(trajectory, (str, os.PathLike)):
        if (repaired := repair(trajectory)):
            warnings.warn(repaired, stacklevel=3)
    return lock
