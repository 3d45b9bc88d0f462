"""ase_maud: the Maud algorithm for points that repel and are tied by springs.

- :class:`MaudCalculator`: the potential ``a^3 Q / L`` between every pair plus
  zero-length springs ``Q L^2 / 2`` on listed pairs, with nodal stiffness blocks.
- :class:`Maud`: the Maud step ``dr = gamma K^-1 f`` with the stiffness of the
  whole scene (or the specification's nodal blocks), an ASE optimizer.
- :class:`MaudPrecon`: the sparse whole-scene stiffness as an ASE ``Precon``.

Numba compiles the kernels on their first call and caches the machine code
(``cache=True``). The cache goes to ``NUMBA_CACHE_DIR`` if the user set it,
else to :func:`numba_cache_dir`, never next to the installed package: a cache
left in ``site-packages`` outlives ``pip uninstall`` as a bare directory that
Python then imports as an empty namespace package, shadowing a later editable
install. It is set here, before anything imports numba.
"""

from __future__ import annotations

import importlib
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any


def numba_cache_dir() -> Path:
    """Per-user cache of the compiled kernels: ``$XDG_CACHE_HOME/ase_maud/numba``,
    by default ``~/.cache/ase_maud/numba``."""
    base = os.environ.get('XDG_CACHE_HOME') or Path.home() / '.cache'
    return Path(base) / 'ase_maud' / 'numba'


def _use_numba_cache_dir() -> None:
    """Point numba's cache at :func:`numba_cache_dir` unless the user chose one.

    numba reads ``NUMBA_CACHE_DIR`` when it is first imported; if that was
    before ase_maud, its ``config.CACHE_DIR`` is set too (the kernels read it
    when they are defined, below).
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


_use_numba_cache_dir()

#: The public names and the module each lives in: imported on first use
#: (PEP 562), so that ``ase-maud --help`` and ``import ase_maud`` import
#: neither numba nor ASE.
_LAZY = {'MaudCalculator': 'calculator', 'FileInUseError': 'lock',
         'DivergenceError': 'monitor', 'MaudError': 'monitor',
         'NoEquilibriumError': 'monitor', 'StagnationError': 'monitor',
         'WrongIndexError': 'monitor', 'Maud': 'optimizer', 'MaudPotential': 'potential',
         'MaudPrecon': 'precon'}

if TYPE_CHECKING:
    from .calculator import MaudCalculator
    from .lock import FileInUseError
    from .monitor import (
        DivergenceError,
        MaudError,
        NoEquilibriumError,
        StagnationError,
        WrongIndexError,
    )
    from .optimizer import Maud
    from .potential import MaudPotential
    from .precon import MaudPrecon


def __getattr__(name: str) -> Any:
    """The public class ``name``, imported from its module on first use."""
    if name not in _LAZY:
        raise AttributeError(f'module {__name__!r} has no attribute {name!r}')
    value = getattr(importlib.import_module(f'.{_LAZY[name]}', __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))


__all__ = ['MaudCalculator', 'Maud', 'MaudPotential', 'MaudPrecon', 'MaudError',
           'DivergenceError', 'NoEquilibriumError', 'StagnationError', 'WrongIndexError',
           'FileInUseError',
           'kernels_cached',
           'numba_cache_dir']
__version__ = '0.1.0'
