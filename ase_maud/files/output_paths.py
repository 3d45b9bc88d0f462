"""The files a run reads and writes: one rule for all of them.

Before any work, every output is compared with every input and with every
other output as a file (:func:`same_file`: ``./a.obj``, ``a.obj``, a
symbolic or a hard link to it are one file). An output that is an input, or
another output, is refused by :func:`check_distinct` with a ValueError
naming both arguments and the file: nothing is read or written yet.

An output is put in place only when there is something to keep in it. A
trajectory is written under a temporary name beside its file and moved onto
it (``os.replace``) once it holds its first frame (:class:`StagedTrajectory`),
so a run that fails before its first step leaves the previous file as it
was; every other output is replaced whole once complete
(:mod:`ase_maud.files.atomic_replace`). A log is appended to, never emptied (ASE's).
"""

from __future__ import annotations

import json
import os
import stat
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from ase_maud.errors import FileInUseError
from ase_maud.files.atomic_replace import is_special, temporary_beside, write_target
from ase_maud.files.run_lock import RunLock
from ase_maud.files.trajectory import parameters_once_writer

PathLike = str | os.PathLike
#: (argument, file) pairs: the argument as the user wrote it ('--traj',
#: 'NET_FILE', 'logfile'); None for a file not given.
Files = Iterable[tuple[str, PathLike | None]]


def same_file(a: PathLike, b: PathLike) -> bool:
    """Whether ``a`` and ``b`` name one file: the same path once symbolic
    links, ``.`` and ``..`` are resolved, or (both existing) the same inode
    (hard links, a case-insensitive file system)."""
    if os.path.realpath(a) == os.path.realpath(b):
        return True
    try:
        return os.path.samefile(a, b)
    except OSError:   # one of them does not exist (yet)
        return False


def check_distinct(inputs: Files, outputs: Files) -> None:
    """A ValueError, in one line, if an output names an input or another
    output (:func:`same_file`), naming both arguments and the file."""
    inputs = [(name, path) for name, path in inputs if path is not None]
    seen: list[tuple[str, PathLike]] = []
    for name, path in outputs:
        if path is None:
            continue
        for other, known in inputs:
            if same_file(path, known):
                raise ValueError(f'{name} {str(path)!r} is the file {other} '
                                 f'{str(known)!r} is read from: an output may not '
                                 f'overwrite an input; give {name} another file')
        for other, known in seen:
            if same_file(path, known):
                raise ValueError(f'{name} {str(path)!r} and {other} {str(known)!r} are '
                                 'one file: each output needs its own')
        seen.append((name, path))


def check_own_json(name: str, path: PathLike, keys: Sequence[str], writer: str) -> None:
    """A ValueError naming ``name`` if ``path`` exists and is not what
    ``writer`` writes there (a JSON object of exactly ``keys``): a file of
    the user's is not replaced; one of an earlier run is."""
    path = Path(path)
    if not path.exists():
        return
    try:
        data = json.loads(path.read_bytes())
    except (ValueError, OSError):
        data = None
    if not isinstance(data, dict) or set(data) != set(keys):
        raise ValueError(f'{name}: {str(path)!r} exists and was not written by {writer}; '
                         'it is left as it is: give another file, or move it away')


class StagedTrajectory:
    """An ASE trajectory for ``path``, written under a temporary name beside
    it (:func:`~ase_maud.files.atomic_replace.temporary_beside`) and moved onto ``path``
    by :meth:`keep` once it holds a frame; on leaving the ``with`` block, a
    temporary file that got no frame is removed, and ``path`` is as it was.

    Give :attr:`trajectory` to the optimizer and attach :meth:`keep` as an
    observer after it (ASE runs observers in order, its trajectory's
    first). A run holding ``path`` (:class:`~ase_maud.files.run_lock.RunLock`) is
    refused first, and one whose first frame was kept at ``path`` while this
    one ran (both started with no file there) at this one's first frame;
    this one holds the lock of the previous file at ``path`` (if any: a lock
    would create, and on release remove, the file) and of its own file,
    which moves with it onto ``path``.
    """

    def __init__(self, path: PathLike):
        self.path = write_target(path)   # a link's target, the link kept
        self.kept = False
        if is_special(self.path):   # a device: written in place, nothing staged
            check_seekable('trajectory', self.path)
            self.temporary, self._locks = self.path, []
            self.trajectory = parameters_once_writer(self.path)
            self.kept = True
            return
        RunLock(None, self.path).check()
        self.temporary = temporary_beside(self.path)
        self._locks = [RunLock(None, self.temporary)]
        try:
            self.trajectory = parameters_once_writer(self.temporary)
        except BaseException:
            self.temporary.unlink()
            raise

    def keep(self) -> None:
        """Move the trajectory onto ``path`` if it holds a frame (once); a
        FileInUseError, ``path`` left alone, if a file appeared there since
        this run started with none (a second run's trajectory, whose first
        frame came first)."""
        if not self.kept and len(self.trajectory):
            if len(self._locks) == 1 and self.path.exists():
                raise FileInUseError(
                    f'trajectory {str(self.path)!r} was written by another run (or '
                    'program) since this one started: it is left as it is and this '
                    "run's is not kept; give this run another --traj")
            os.replace(self.temporary, self.path)
            self.kept = True

    def __enter__(self) -> StagedTrajectory:
        if self.path.exists() and not self.kept:
            self._locks.append(RunLock(None, self.path))
        try:
            for lock in self._locks:
                lock.__enter__()
        except BaseException:
            self.__exit__()
            raise
        return self

    def __exit__(self, *exc_info: Any) -> None:
        self.trajectory.close()
        if not self.kept:
            self.temporary.unlink(missing_ok=True)
        for lock in self._locks:
            lock.__exit__()


def check_seekable(name: str, path: PathLike) -> None:
    """A ValueError naming ``name`` if ``path`` is a named pipe or a socket:
    an ASE trajectory (or a restart file) is written with seeks, which a
    pipe has not, and opening one that nobody reads would wait for ever."""
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return
    if stat.S_ISFIFO(mode) or stat.S_ISSOCK(mode):
        raise ValueError(f'{name} {str(path)!r} is a named pipe (or socket): a '
                         f'{name} is written with seeks a pipe does not have; give a file')


def check_run_files(restart: Any, logfile: Any, trajectory: Any) -> None:
    """:func:`check_distinct` of an optimizer's files (those given by name:
    not None, ``'-'`` or an open file): ``restart`` and its arrays file
    (:class:`~ase_maud.optimize.restart_file.RestartFile`), ``logfile``, ``trajectory``."""
    named = [(name, value) for name, value in (
        ('restart', restart), ('logfile', logfile), ('trajectory', trajectory))
        if isinstance(value, (str, os.PathLike)) and value != '-']
    if isinstance(restart, (str, os.PathLike)):
        named.append(("restart's arrays file", os.fspath(restart) + '.arrays'))
    for name, value in named:
        if name != 'logfile':
            check_seekable(name, value)
    check_distinct((), named)
