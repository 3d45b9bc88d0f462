"""Files replaced whole: a new version is written beside the old one, then
swapped in by ``os.replace``, so that a reader (or the writer after a kill,
or a full disk) sees the old file or the new one, never a part. The new
version keeps the old one's permissions (a new file gets the usual ones,
``0o666`` less the umask)."""

from __future__ import annotations

import os
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


def _temporary_pattern(path: Path) -> tuple[str, str]:
    """The prefix and suffix of :func:`replace_with`'s temporary files."""
    return f'.{path.stem}.', f'.tmp{path.suffix}'


def remove_leftovers(path: str | os.PathLike) -> list[Path]:
    """Remove the temporary files that writers of ``path`` killed before their
    replace left beside it (older than :data:`LEFTOVER_SECONDS`); return them."""
    path = Path(path)
    prefix, suffix = _temporary_pattern(path)
    removed = []
    for leftover in path.parent.glob(f'{prefix}*{suffix}'):
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


def replace_with(path: str | os.PathLike, write: Callable[[Path], None],
                 sync: bool = True) -> None:
    """Replace ``path`` by what ``write(temporary)`` writes to a temporary
    file in the same folder, with the same suffix (for writers that choose a
    format by it); flushed to disk first if ``sync``. The old file stays
    untouched until the new one is complete; a failure removes the temporary
    file and is raised."""
    temporary = temporary_beside(path)
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
