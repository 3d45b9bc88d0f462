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
    from numba.core.caching import FunctionCache  # numba: only once the cache dir is set
    from numba.core.dispatcher import Dispatcher

    caches = [value._cache for name, module in list(sys.modules.items())
              if name.startswith('ase_maud.') for value in vars(module).values()
              if isinstance(value, Dispatcher) and isinstance(value._cache, FunctionCache)]
    try:
        return any(cache._cache_file._load_index() for cache in caches)
    except AttributeError:
        return True


#: What :func:`compile_notice` says, once, when a kernel starts compiling.
COMPILE_NOTICE = ('ase-maud: compiling the kernels (on the first run, and after an '
                  'upgrade; cached for later runs, 10-30 s)...')


class compile_notice:
    """A context in which the first compilation of an ase_maud kernel (a
    numba cache miss: numba's ``numba:compile`` event, which a kernel
    loaded from the cache does not fire) prints :data:`COMPILE_NOTICE` to
    ``stream`` (default stderr), once. Whatever the cache's index says:
    the notice comes when, and only when, a kernel compiles."""

    def __init__(self, stream=None):
        self.stream = stream
        self.said = False

    def __enter__(self):
        from numba.core import event  # numba: only once the cache dir is set

        notice = self

        class Listener(event.Listener):
            def on_start(self, ev):
                function = getattr(ev.data.get('dispatcher'), 'py_func', None)
                module = getattr(function, '__module__', '') or ''
                if not notice.said and module.startswith('ase_maud'):
                    notice.said = True
                    print(COMPILE_NOTICE, file=notice.stream or sys.stderr, flush=True)

            def on_end(self, ev):
                pass

        self._installed = event.install_listener('numba:compile', Listener())
        self._installed.__enter__()
        return self

    def __exit__(self, *exc):
        return self._installed.__exit__(*exc)
