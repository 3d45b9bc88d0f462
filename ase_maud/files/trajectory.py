"""A run's ASE trajectory read back after a kill or a cut: its last intact
frame, and the file made whole before a resumed run appends to it.

ASE's trajectory format counts a frame only once all of it is written, so a
run killed mid-write leaves complete frames. A file cut short afterwards (a
full disk, an interrupted copy) still names frames whose bytes are gone:
reading them fails deep inside ASE. Here such frames are found (read from the
last one back until one reads whole) and, by :func:`repair`, dropped from a
new copy of the file; the cut file is kept beside it.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

from ase import Atoms
from ase.io.trajectory import Trajectory, TrajectoryWriter

from ase_maud.files.atomic_replace import replace_with

#: Suffix of the copy :func:`repair` keeps of a cut trajectory.
DAMAGED_SUFFIX = '.damaged'


def _frames(path: Path):
    """ASE's reader of ``path``, or ValueError naming the file if even its
    header cannot be read."""
    try:
        return Trajectory(path)
    except Exception as error:   # ASE's ulm reader raises many kinds
        raise ValueError(f'trajectory {str(path)!r} cannot be read ({type(error).__name__}: '
                         f'{error}); move it away to start afresh') from None


def _read(frames, index: int) -> Atoms | None:
    """Frame ``index`` with its energy and forces, or None if its bytes are
    damaged or missing."""
    try:
        atoms = frames[index]
        if atoms.calc is not None:
            atoms.calc.get_property('forces', atoms, allow_calculation=False)
        return atoms
    except Exception:   # noqa: BLE001 (a damaged frame raises anything)
        return None


def _last_intact(path: Path) -> tuple[Atoms | None, int, int]:
    """The last intact frame of ``path`` (or None), how many frames read whole
    from the start, and how many the file names."""
    if not path.is_file() or path.stat().st_size == 0:
        return None, 0, 0
    with _frames(path) as frames:
        named = len(frames)
        for index in range(named - 1, -1, -1):
            if (atoms := _read(frames, index)) is not None:
                return atoms, index + 1, named
    return None, 0, named


def intact(path: str | os.PathLike) -> tuple[int, int]:
    """``(intact, named)``: how many frames of the trajectory at ``path`` read
    whole from its start, and how many it names (0, 0 for a missing or empty
    file)."""
    return _last_intact(Path(path))[1:]


def last_frame(path: str | os.PathLike) -> Atoms | None:
    """The last intact frame of the trajectory at ``path``, or None if it has
    none (missing, empty, killed before its first frame was complete, or cut
    before it)."""
    frames = last_step(path, 1)
    return None if frames is None else frames[0]


def last_step(path: str | os.PathLike, count: int) -> list[Atoms] | None:
    """The frames of the last whole step of the trajectory at ``path``, a
    step being ``count`` frames (a band of ``count`` images writes each
    image): its last ``count`` frames after dropping a step written in part,
    or None if it has no whole step (missing, empty, or cut before it)."""
    path = Path(path)
    whole = intact(path)[0] // count * count
    if whole == 0:
        return None
    with _frames(path) as frames:
        return [_read(frames, index) for index in range(whole - count, whole)]


def repair(path: str | os.PathLike) -> str | None:
    """Make the trajectory at ``path`` hold only its intact frames, so that a
    run can append to it: if frames at its end are damaged, the file is kept
    as ``path + '.damaged'`` and replaced by a copy of its intact frames.
    Returns what was done, in words, or None if nothing was needed."""
    path = Path(path)
    count, named = intact(path)
    if count == named:
        return None
    kept = path.with_name(path.name + DAMAGED_SUFFIX)
    shutil.copy2(path, kept)

    def write(temporary: Path) -> None:
        with _frames(path) as frames, Trajectory(temporary, 'w') as copy:
            for index in range(count):
                copy.write(_read(frames, index))
    replace_with(path, write)
    return (f'trajectory {str(path)!r}: frames {count + 1}-{named} of {named} were '
            f'damaged (the file was cut short?) and are dropped; it now ends at frame '
            f'{count}; the cut file is kept as {str(kept)!r}')


class _ResultsOnly:
    """A calculator's results without its parameters: what ASE's trajectory
    writer stores of a frame after the first (it writes ``todict()`` of any
    calculator that has one; this has none)."""

    def __init__(self, calc):
        self.name = calc.name
        self._calc = calc

    def get_property(self, name, atoms=None, allow_calculation=True):
        return self._calc.get_property(name, atoms, allow_calculation=allow_calculation)


def parameters_once_writer(path: str | os.PathLike):
    """An ASE trajectory writer for ``path`` that stores the calculator's
    parameters (a MaudCalculator's: springs, ``a``, ``Q``, ``dim``, ``q``,
    loads) with the first frame only, and each frame's energy and forces as
    ASE does: the springs of every frame made a run's trajectory 27 % larger
    than ASE's own for the same frames. :func:`ase_maud.io.nets.read_net`
    reads the parameters of any frame from the first (:func:`first_frame`);
    ``ase gui`` reads every frame as before."""

    class ParametersOnce(TrajectoryWriter):
        def _write_atoms(self, atoms, **kwargs):
            calc = atoms.calc
            if not len(self) or calc is None:
                return super()._write_atoms(atoms, **kwargs)
            atoms.calc = _ResultsOnly(calc)
            try:
                return super()._write_atoms(atoms, **kwargs)
            finally:
                atoms.calc = calc

    return ParametersOnce(path, 'w')


def first_frame(path: str | os.PathLike) -> Atoms | None:
    """The first frame of the trajectory at ``path`` (None if it has none):
    it holds the calculator's parameters of every frame of a run's
    trajectory (:func:`parameters_once_writer`)."""
    with _frames(Path(path)) as frames:
        return frames[0] if len(frames) else None
