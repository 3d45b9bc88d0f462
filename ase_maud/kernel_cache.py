"""Where numba keeps the compiled kernels, and whether they are there.

Numba compiles the kernels on their first call and caches the machine code
(``cache=True``). The cache goes to ``NUMBA_CACHE_DIR`` if the user set it,
else to :func:`numba_cache_dir`, never next to the installed package: a cache
left in ``site-packages`` outlives ``pip uninstall`` as a bare directory that
Python then imports as an empty namespace package, shadowing a later editable
install. ``import ase_maud`` sets it (:func:`use_numba_cache_dir`) before
anything imports numba.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path


def numba_cache_dir() -> Path:
    """Per-user cache of the compiled kernels: ``$XDG_CACHE_HOME/ase_maud/numba``,
    by default ``~/.cache/ase_maud/numba``."""
    base = os.environ.get('XDG_CACHE_HOME') or Path.home() / '.cache'
    return Path(base) / 'ase_maud' / 'numba'


def use_numba_cache_dir() -> None:
    """Point numba's cache at :func:`numba_cache_dir` unless the user chose one.

    numba reads ``NUMBA_CACHE_DIR`` when it is first imported; if that was
    before ase_maud, its ``config.CACHE_DIR`` is set too (the kernels read it
    when they are defined).
    """
    if not os.environ.get('NUMBA_CACHE_DIR'):
        os.environ['NUMBA_CACHE_DIR'] = str(numba_cache_dir())
    numba = sys.modules.get('numba')
    if numba is not None and not numba.config.CACHE_DIR:
        numba.config.CACHE_DIR = os.environ['NUMBA_CACHE_DIR']


def kernels_cached() -> bool:
    """Whether numba's cache holds machine code for a kernel of a loaded
    ase_maud module (its index file, read without compiling): if not, the first
    force call compiles them, 10-30 s. True if numba's cache internals moved."""
    from numba.core.caching import FunctionCache
    from numba.core.dispatcher import Dispatcher

    caches = [value._cache for name, module in list(sys.modules.items())
              if name.startswith('ase_maud.') for value in vars(module).values()
              if isinstance(value, Dispatcher) and isinstance(value._cache, FunctionCache)]
    try:
        return any(cache._cache_file._load_index() for cache in caches)
    except AttributeError:
        return True
