"""Files replaced whole: a new version is written beside the old one, then
swapped in by ``os.replace``, so that a reader (or the writer after a kill,
or a full disk) sees the old file or the new one, never a part. The new
version keeps the old one's permissions (a new file gets the usual ones,
``0o666`` less the umask).

An output is written where the user pointed (:func:`write_target`): a
symbolic link's target is replaced (beside the target, the link kept); a
device node, a named pipe or another special file is written in place, never
replaced (a pipe opened without blocking: one that nobody reads is refused,
not waited on); an existing file in a directory that cannot take a
temporary file is written in place. Temporary names fit beside any legal
name (:func:`_temporary_pattern`).
"""

from __future__ import annotations

import errno
import glob
import os
import shutil
import stat
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

#: A temporary file of :func:`replace_with` older than this (seconds) was
#: left by a writer that was killed, and is removed by :func:`remove_leftovers`
#: (a live writer keeps its own for milliseconds).
LEFTOVER_SECONDS = 60.0

_UMASK = os.umask(0)   # read once, at import (setting it is the only way)
os.umask(_UMASK)


#: Bytes of a file name most file systems allow, and of the random part of
#: a temporary name (``tempfile.mkstemp``'s eight letters, and a margin).
NAME_BYTES, RANDOM_BYTES = 255, 12


def _temporary_pattern(path: Path) -> tuple[str, str]:
    """The prefix and suffix of :func:`replace_with`'s temporary files:
    ``.STEM.`` and ``.tmpSUFFIX``, the stem cut (at a character) so that the
    temporary name fits in :data:`NAME_BYTES` whatever the name's length."""
    suffix = f'.tmp{path.suffix}' if len(path.suffix.encode()) <= 32 else '.tmp'
    room = NAME_BYTES - RANDOM_BYTES - 2 - len(suffix.encode())
    stem = path.stem.encode()[:room].decode('utf-8', errors='ignore')
    return f'.{stem}.', suffix


def write_target(path: str | os.PathLike) -> Path:
    """The file a writer of ``path`` writes: ``path``, or the file its
    symbolic link (chain) points to, which may not exist yet (the link is
    kept, and the target written)."""
    path = Path(path)
    return Path(os.path.realpath(path)) if path.is_symlink() else path


def is_special(path: str | os.PathLike) -> bool:
    """Whether ``path`` (a link followed) is a device node, a named pipe, a
    socket or another file that is neither a regular file nor a directory:
    written in place, never replaced."""
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return False
    return not (stat.S_ISREG(mode) or stat.S_ISDIR(mode))


def open_in_place(path: str | os.PathLike, truncate: bool = False) -> int:
    """A file descriptor of ``path`` opened to write without replacing it
    (a special file, or a file whose directory takes no temporary file),
    blocking again once open; a named pipe nobody reads is an OSError (ENXIO)
    naming it at once, not a wait for a reader."""
    flags = os.O_WRONLY | os.O_NONBLOCK | (os.O_TRUNC if truncate else 0)
    try:
        handle = os.open(path, flags)
    except OSError as error:
        if error.errno == errno.ENXIO:
            raise OSError(errno.ENXIO, 'a named pipe (or socket) that nothing reads: '
                          'start its reader first, or give a file', str(path)) from None
        raise
    os.set_blocking(handle, True)
    return handle


def remove_leftovers(path: str | os.PathLike) -> list[Path]:
    """Remove the temporary files that writers of ``path`` killed before their
    replace left beside it (older than :data:`LEFTOVER_SECONDS`); return them."""
    path = Path(path)
    prefix, suffix = _temporary_pattern(path)
    removed = []
    for leftover in path.parent.glob(f'{glob.escape(prefix)}*{glob.escape(suffix)}'):
        try:
            if time.time() - leftover.stat().st_mtime > LEFTOVER_SECONDS:
                leftover.unlink()
                removed.append(leftover)
        except FileNotFoundError:   # another process took it first
            pass
    return removed


def temporary_beside(path: str | os.PathLike) -> Path:
    """A new empty file in the folder of ``path``, with its suffix, that
    :func:`remove_leftovers` knows, with the permissions ``path`` has (the
    usual ones if it does not exist): where a new version of ``path`` is
    written before ``os.replace`` moves it into place."""
    path = Path(path)
    prefix, suffix = _temporary_pattern(path)
    handle, name = tempfile.mkstemp(dir=path.parent, prefix=prefix, suffix=suffix)
    os.close(handle)
    try:
        mode = stat.S_IMODE(path.stat().st_mode) if path.exists() else 0o666 & ~_UMASK
        os.chmod(name, mode)   # mkstemp's are 0o600
    except BaseException:
        os.unlink(name)
        raise
    return Path(name)


def _write_in_place(path: Path, write: Callable[[Path], None], special: bool) -> None:
    """``write`` to a temporary file of the system's temporary folder (with
    ``path``'s suffix), then its bytes copied into ``path`` in place
    (:func:`open_in_place`; a regular file truncated to them)."""
    prefix, suffix = _temporary_pattern(path)
    handle, name = tempfile.mkstemp(prefix=prefix, suffix=suffix)
    os.close(handle)
    try:
        write(Path(name))
        target = open_in_place(path, truncate=not special)
        with open(name, 'rb') as source, open(target, 'wb', closefd=True) as sink:
            shutil.copyfileobj(source, sink)
    finally:
        os.unlink(name)


def replace_with(path: str | os.PathLike, write: Callable[[Path], None],
                 sync: bool = True) -> None:
    """Replace ``path`` by what ``write(temporary)`` writes to a temporary
    file in the same folder, with the same suffix (for writers that choose a
    format by it); flushed to disk first if ``sync``. The old file stays
    untouched until the new one is complete; a failure removes the temporary
    file and is raised. A symbolic link's target is replaced, the link kept;
    a special file (:func:`is_special`) is written in place, as is an
    existing writable file in a folder that takes no new file (module
    docstring)."""
    path = write_target(path)
    if is_special(path):
        _write_in_place(path, write, special=True)
        return
    try:
        temporary = temporary_beside(path)
    except PermissionError:
        if not (path.is_file() and os.access(path, os.W_OK)):
            raise
        _write_in_place(path, write, special=False)   # a read-only folder
        return
    try:
        write(temporary)
        if sync:
            with open(temporary, 'rb+') as fd:
                os.fsync(fd.fileno())
        os.replace(temporary, path)
    except BaseException:
        temporary.unlink(missing_ok=True)
        raise


def replace_text(path: str | os.PathLike, text: str, sync: bool = True,
                 newline: str | None = None) -> None:
    """Replace ``path`` by ``text`` in UTF-8 (:func:`replace_with`); ``newline`` as
    for :func:`open` (``''`` writes the text's own line endings)."""
    def write(temporary: Path) -> None:
        with open(temporary, 'w', encoding='utf-8', newline=newline) as fd:
            fd.write(text)
    replace_with(path, write, sync)
