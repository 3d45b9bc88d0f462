"""One writer at a time for a run's files.

Two runs writing one trajectory mix their frames, and a restart file written
by both holds neither run. :class:`RunLock` takes an exclusive advisory lock
(``flock``) on the trajectory and on the restart file's arrays file (the JSON
file itself is replaced at every step, so it cannot carry a lock) while a run
runs; a second run, in this process or another, is refused with
:class:`FileInUseError` when it is created, before ASE empties the trajectory
it would overwrite. The operating system drops the locks of a process that
dies, so a killed run never leaves a stale lock. Where ``fcntl`` is missing
(Windows) nothing is locked.

Why not filelock: it locks a lock file of its own, opened with ``O_TRUNC``
(given the trajectory itself, it would empty it), so it would leave a
``.lock`` file beside every trajectory and restart file; the lock here is on
the file itself and leaves nothing behind.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import IO, Any

from ase_maud.errors import FileInUseError

try:
    import fcntl
except ImportError:   # pragma: no cover (Windows)
    fcntl = None


class RunLock:
    """Exclusive locks on the files of one run (module docstring):
    ``trajectory`` and ``restart`` as given to the optimizer (file names, or
    None or an open file, which are not locked)."""

    def __init__(self, restart: Any, trajectory: Any):
        named = {'restart file': (restart, '.arrays'), 'trajectory': (trajectory, '')}
        self.files = {what: Path(os.fspath(value) + suffix)
                      for what, (value, suffix) in named.items()
                      if isinstance(value, (str, os.PathLike))}
        self._held: list[tuple[IO[bytes], Path, bool]] = []

    def check(self) -> None:
        """FileInUseError if a running run holds one of the files; nothing
        is kept locked, nothing created."""
        for what, path in self.files.items():
            if path.exists():
                self._take(what, path, created=False)
        self.__exit__()

    def __enter__(self) -> RunLock:
        """Take the locks (creating an empty file where none is yet; it is
        removed again on release if still empty)."""
        for what, path in self.files.items():
            self._take(what, path, created=not path.exists())
        return self

    def __exit__(self, *exc_info: Any) -> None:
        """Release the locks; remove files this lock created that are empty."""
        for handle, path, created in self._held:
            if created and os.fstat(handle.fileno()).st_size == 0:
                path.unlink(missing_ok=True)
            handle.close()
        self._held = []

    def _take(self, what: str, path: Path, created: bool) -> None:
        if fcntl is None or (path.exists() and not path.is_file()):
            return   # a device or a pipe is written in place, never locked
        handle = open(path, 'ab')
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            handle.close()
            self.__exit__()
            name = str(path).removesuffix('.arrays') if what == 'restart file' else str(path)
            raise FileInUseError(
                f'{what} {name!r} is in use by another run (a Maud run in this or '
                'another process holds its lock): let it finish, or give this run '
                'other files') from None
        self._held.append((handle, path, created))
