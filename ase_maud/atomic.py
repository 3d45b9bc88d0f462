"""Files replaced whole: a new version is written beside the old one, then
swapped in by ``os.replace``, so that a reader (or the writer after a kill,
or a full disk) sees the old file or the new one, never a part."""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable
from pathlib import Path


def replace_with(path: str | os.PathLike, write: Callable[[Path], None],
                 sync: bool = True) -> None:
    """Replace ``path`` by what ``write(temporary)`` writes to a temporary
    file in the same folder, with the same suffix (for writers that choose a
    format by it); flushed to disk first if ``sync``. The old file stays
    untouched until the new one is complete; a failure removes the temporary
    file and is raised."""
    path = Path(path)
    handle, name = tempfile.mkstemp(dir=path.parent, prefix=f'.{path.stem}.',
                                    suffix=f'.tmp{path.suffix}')
    os.close(handle)
    temporary = Path(name)
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
    """Replace ``path`` by ``text`` (:func:`replace_with`); ``newline`` as
    for :func:`open` (``''`` writes the text's own line endings)."""
    def write(temporary: Path) -> None:
        with open(temporary, 'w', newline=newline) as fd:
            fd.write(text)
    replace_with(path, write, sync)
