"""ase_maud: the Maud algorithm for points that repel and are tied by springs.

- :class:`MaudCalculator`: the potential ``a^3 Q / L`` between every pair plus
  zero-length springs ``Q L^2 / 2`` on listed pairs, with nodal stiffness blocks.
- :class:`Maud`: the Maud step ``dr = gamma K^-1 f`` with the stiffness of the
  whole scene (or the specification's nodal blocks), an ASE optimizer.
- :class:`MaudPrecon`: the sparse whole-scene stiffness as an ASE ``Precon``.

- :func:`search_saddles`, :func:`landscape`: saddles and the minima they join.
- :func:`read_net`, :func:`write_net`, :func:`form_result`: nets from files,
  relaxed, and their member forces and reactions; :mod:`scenes`: built-in scenes.

The subpackages are layers, each importing only those below it: ``physics``
(the pair law), ``backends`` (its sums), ``calculator``, ``analysis``,
``optimize``, ``saddles``, ``form``, ``io``, ``files``, ``scenes``, ``bench`` and
``cli`` (``docs/architecture.md``). Numba's cache is set up here
(:mod:`ase_maud.kernel_cache`).
"""

from __future__ import annotations

import importlib
import sys
from typing import TYPE_CHECKING, Any

from ase_maud.kernel_cache import kernels_cached, numba_cache_dir, use_numba_cache_dir
from ase_maud.old_paths import OldPathFinder

# Before anything imports numba.
use_numba_cache_dir()

#: The public names and the module each lives in: imported on first use
#: (PEP 562), so that ``ase-maud --help`` and ``import ase_maud`` import
#: neither numba nor ASE.
_LAZY = {'MaudCalculator': 'calculator.maud_calculator',
         'MaudPotential': 'calculator.potential',
         'Maud': 'optimize.maud', 'MaudPrecon': 'optimize.precon',
         'search_saddles': 'saddles.search', 'landscape': 'saddles.landscape',
         'read_net': 'io.nets', 'write_net': 'io.net_writer', 'form_result': 'form.member_forces',
         'classify': 'analysis.stationary',
         **{error: 'errors' for error in (
             'MaudError', 'DivergenceError', 'NoEquilibriumError', 'StagnationError',
             'WrongIndexError', 'FileInUseError', 'RestartFileError')}}

if TYPE_CHECKING:
    from ase_maud.analysis.stationary import classify
    from ase_maud.calculator.maud_calculator import MaudCalculator
    from ase_maud.calculator.potential import MaudPotential
    from ase_maud.errors import (
        DivergenceError,
        FileInUseError,
        MaudError,
        NoEquilibriumError,
        RestartFileError,
        StagnationError,
        WrongIndexError,
    )
    from ase_maud.form.member_forces import form_result
    from ase_maud.io.net_writer import write_net
    from ase_maud.io.nets import read_net
    from ase_maud.optimize.maud import Maud
    from ase_maud.optimize.precon import MaudPrecon
    from ase_maud.saddles.landscape import landscape
    from ase_maud.saddles.search import search_saddles

# The module paths of ase_maud 0.1 import for one more release, with a warning.
sys.meta_path.append(OldPathFinder())


def __getattr__(name: str) -> Any:
    """The public name ``name``, imported from its module on first use; the
    subpackage ``scenes`` likewise."""
    if name == 'scenes':
        return importlib.import_module('.scenes', __name__)
    if name not in _LAZY:
        raise AttributeError(f'module {__name__!r} has no attribute {name!r}')
    value = getattr(importlib.import_module(f'.{_LAZY[name]}', __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY) | {'scenes'})


__all__ = ['Maud', 'MaudCalculator', 'MaudPotential', 'MaudPrecon', 'classify', 'form_result',
           'landscape', 'read_net', 'search_saddles', 'write_net', 'scenes',
           'MaudError', 'DivergenceError', 'NoEquilibriumError', 'StagnationError',
           'WrongIndexError', 'FileInUseError', 'RestartFileError',
           'kernels_cached', 'numba_cache_dir']
__version__ = '0.2.0'
