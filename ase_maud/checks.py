"""Every user setting's rule, in one table, and the one function that checks it.

:data:`RULES` says what each keyword of the package accepts: the optimiser's
(:class:`ase_maud.Maud` and its ``run``), the stiffness models', the
calculator's and the backends'. :func:`check` is the only place a value is
tested against its rule: a bad value is a ValueError that names the keyword,
the value and what is accepted. Each keyword is checked where it enters (the
object that keeps it), nowhere else. :func:`check_writable` is the one test of
a file or directory the package will write.
"""

from __future__ import annotations

import difflib
import math
import os
from collections.abc import Callable
from dataclasses import dataclass
from numbers import Integral, Real
from pathlib import Path
from typing import Any

import numpy as np


def as_whole(value: Any) -> int | None:
    """``value`` as an int if it is a whole number (an integer, numpy's
    included, or a finite float with no fraction; never a bool), else None."""
    if type(value) is int:   # the usual case, without the abstract classes' tests
        return value
    if isinstance(value, bool) or not isinstance(value, Real):
        return None
    if isinstance(value, Integral):
        return int(value)
    return int(value) if math.isfinite(value) and float(value).is_integer() else None


def as_number(value: Any) -> float | None:
    """``value`` as a finite float (never a bool), else None."""
    if type(value) is float:   # the usual case, without the abstract classes' tests
        return value if math.isfinite(value) else None
    if isinstance(value, bool) or not isinstance(value, Real):
        return None
    if isinstance(value, Integral):
        return float(value) if abs(value) < 2.0**1023 else None
    return float(value) if math.isfinite(value) else None


@dataclass(frozen=True)
class Rule:
    """What a keyword accepts.

    ``accepted``: the words of the error message. Either ``choices`` (the
    values allowed, compared by equality with a value of the same type) or a
    number: ``test`` on the float (or, if ``whole``, on the int) value.
    ``none``: None is accepted too (a default decided elsewhere);
    ``infinite``: +inf is accepted too (a test switched off).
    """

    accepted: str
    test: Callable[[float], bool] | None = None
    whole: bool = False
    none: bool = False
    infinite: bool = False
    choices: tuple[Any, ...] = ()


def _choice(*choices: Any, none: bool = False, words: str = '') -> Rule:
    accepted = f'one of {choices}' + (words or (', or None' if none else ''))
    return Rule(accepted, none=none, choices=choices)


#: Each keyword's rule (see :func:`check`).
RULES: dict[str, Rule] = {
    # the optimiser's step rule and run
    'gamma': Rule('a positive finite number', lambda v: v > 0),
    'gamma_max': Rule("a positive finite number, or None (the model's)",
                      lambda v: v > 0, none=True),
    'gamma_growth': Rule("a finite number >= 1, or None (the model's)",
                         lambda v: v >= 1, none=True),
    'overshoot_shrink': Rule('a number in (0, 1]', lambda v: 0 < v <= 1),
    'beta_max': Rule("a number in [0, 1), or None (the model's)",
                     lambda v: 0 <= v < 1, none=True),
    'memory': Rule("a whole number >= 0, or None (the model's)",
                   lambda v: v >= 0, whole=True, none=True),
    'maxstep_nn': Rule("a number in (0, 0.5) (at 0.5 two points could meet), "
                       "or None (the model's)", lambda v: 0 < v < 0.5, none=True),
    'maxstep': Rule('a positive finite length, or None (no bound)',
                    lambda v: v > 0, none=True),
    'divergence_factor': Rule('a number > 1, or inf (no divergence test)',
                              lambda v: v > 1, infinite=True),
    'patience': Rule('a whole number >= 0 (steps)', lambda v: v >= 0, whole=True),
    'fmax': Rule('a positive finite number (force units)', lambda v: v > 0),
    # a run's fmax (Maud.run, irun): ASE's convention, 0 takes every step asked
    'run_fmax': Rule('a finite number >= 0 (force units; 0 takes every step asked, '
                     'as in ASE)', lambda v: v >= 0),
    'steps': Rule('a whole number >= 0', lambda v: v >= 0, whole=True),
    # the stiffness models
    'target': _choice('minimum', 'stationary', 'saddle', none=True,
                      words=", or None (the default: 'minimum', 'stationary' "
                      'for a band of images)'),
    'order': Rule('a whole number >= 0 (negative curvatures of the saddle sought; '
                  '0: a minimum)', lambda v: v >= 0, whole=True),
    'method': _choice('tensor', 'scalar'),
    'floor': Rule("a number in (0, 1), or None (the model's)",
                  lambda v: 0 < v < 1, none=True),
    'kappa0': Rule('a positive finite number (force per length)', lambda v: v > 0),
    'refresh': Rule('a finite number >= 0 (a fraction of the nearest-neighbour '
                    'distance; 0 rebuilds at every step)', lambda v: v >= 0),
    # the calculator
    'a': Rule('a finite number >= 0 (0: no repulsion, the force-density method)',
              lambda v: v >= 0),
    'Q': Rule('a positive finite number', lambda v: v > 0),
    'dim': Rule('2 or 3', choices=(2, 3)),
    # the calculator's arrays, each entry (check_each)
    'q': Rule('a finite nonzero number (the force density multiplier of Q; '
              'negative: a member in compression, as in compas_fd)', lambda v: v != 0),
    'loads': Rule('a finite number (force units)', lambda v: abs(v) < math.inf),
    # the backends
    'tol': Rule('a number in [0, 1), the force error allowed relative to the '
                'largest repulsive force (0: exact)', lambda v: 0 <= v < 1),
    'crossover': Rule('None (the measured table) or the number of points from '
                      'which the FMM is used, an integer >= 0',
                      lambda v: v >= 0, whole=True, none=True),
    'fmm_eps': Rule('a number in (0, 1), the force error allowed relative to '
                    'the largest force',
                    lambda v: 0 < v < 1),
    # the landscape (ase_maud.saddles.landscape)
    'modes': Rule('a whole number >= 0 (the lowest modes climbed, each both ways, '
                  'before the local activations)', lambda v: v >= 0, whole=True),
    'distance_atol': Rule('a finite number >= 0 (length units)', lambda v: v >= 0),
    # the saddle search (ase_maud.saddles.search)
    'local': Rule('a whole number >= 0 (local activations after the mode climbs)',
                  lambda v: v >= 0, whole=True),
    'budget': Rule('a whole number >= 1 (force-call equivalents of one attempt), '
                   'or None (no bound but the steps)', lambda v: v >= 1, whole=True,
                   none=True),
    'empty_rounds': Rule('a whole number >= 1 (rounds in a row that find no new saddle '
                         'below the window before the rounds stop)',
                         lambda v: v >= 1, whole=True),
    'window': Rule('a positive number (a barrier above the minimum, energy units), inf '
                   '(every saddle), or None (no window: one round of attempts)',
                   lambda v: v > 0, none=True, infinite=True),
    'sweep': _choice(True, False, words=' (a local activation at every free point once '
                     "a window's rounds end)"),
    # the command line's own
    'count': Rule('a whole number >= 1', lambda v: v >= 1, whole=True),
    'seed': Rule('a whole number >= 0', lambda v: v >= 0, whole=True),
    'energy_rtol': Rule('a positive finite number (relative)', lambda v: v > 0),
}


def check(name: str, value: Any, rule_name: str | None = None) -> Any:
    """``value`` checked against ``RULES[rule_name or name]``: returned as a
    float (an int for a whole number or an integer choice, the value itself
    for a string choice, None where allowed), or a ValueError naming
    ``name``, the value and what is accepted."""
    rule = RULES[rule_name or name]
    if value is None and rule.none:
        return None
    if rule.infinite and isinstance(value, Real) and value == math.inf:
        return math.inf
    if rule.choices:
        for choice in rule.choices:
            if _matches(value, choice):
                return choice
    else:
        number = as_whole(value) if rule.whole else as_number(value)
        if number is not None and rule.test(number):
            return number
    raise ValueError(f'{name} must be {rule.accepted}, got {value!r}')


def all_finite(value: float | np.ndarray) -> bool:
    """Whether every entry of ``value`` (a number or an array) is finite: its
    sum is (one pass; a sum that overflows is checked entry by entry). The
    one test of computed results (arguments are checked by their rules)."""
    if isinstance(value, np.ndarray):
        return math.isfinite(value.sum()) or bool(np.isfinite(value).all())
    return math.isfinite(value)


def check_each(name: str, values: Any, what: str) -> np.ndarray:
    """Every entry of the array ``values`` checked against ``RULES[name]`` (a
    number rule): a float array of its shape, or a ValueError naming
    ``name``, the ``what`` (``'spring'``, ``'atom'``) of the first bad entry
    (its row), the value and what is accepted."""
    rule = RULES[name]
    array = np.asarray(values)
    try:
        if array.dtype == bool:
            raise TypeError
        numbers = array.astype(float)
    except (TypeError, ValueError, OverflowError):
        raise ValueError(f'{name} must be an array of numbers, each '
                         f'{rule.accepted}; got {values!r}') from None
    with np.errstate(invalid='ignore', over='ignore'):
        good = np.isfinite(numbers) & rule.test(numbers)
    if not np.all(good):
        where = tuple(np.argwhere(~np.asarray(good))[0])
        at = f' of {what} {where[0]}' if where else ''
        raise ValueError(f'{name}{at} must be {rule.accepted}, got {array[where]!r}')
    return numbers


def _matches(value: Any, choice: Any) -> bool:
    """A string equal to a string ``choice``, a bool that is a bool one, or
    an integer (not a float, not a bool) equal to an integer one."""
    if isinstance(choice, str):
        return isinstance(value, str) and value == choice
    if isinstance(choice, bool):
        return value is choice
    return (as_whole(value) is not None and not isinstance(value, float)
            and value == choice)


def check_all(**values: Any) -> dict[str, Any]:
    """:func:`check` of each keyword, as a dict of the checked values."""
    return {name: check(name, value) for name, value in values.items()}


def check_writable(name: str, value: str | os.PathLike, directory: bool = False) -> Path:
    """``value`` as a Path that can be written, or a ValueError naming
    ``name`` and the value: a file (not a directory) in a writable directory
    that exists, or with ``directory`` a writable directory or one that can
    be made (its nearest existing parent writable, and no part a file)."""
    path = Path(value)
    text = f'{name} {str(value)!r}'
    if directory:
        existing = next(p for p in (path, *path.parents) if p.exists())   # '.' or '/' at last
        if not existing.is_dir():
            raise ValueError(f'{text}: {str(existing)!r} is a file, not a directory')
        if not os.access(existing, os.W_OK | os.X_OK):
            raise ValueError(f'{text}: the directory {str(existing)!r} is not writable')
        return path
    if path.is_dir():
        raise ValueError(f'{text} is a directory; give a file name')
    if str(value).endswith(('/', os.sep)):
        raise ValueError(f'{text} names a directory (it ends in {os.sep!r}); give a file '
                         'name')
    if path.is_symlink():   # its target is written, the link kept
        path = Path(os.path.realpath(path))
        text += f' (a link to {str(path)!r})'
        if path.is_dir():
            raise ValueError(f'{text} is a directory; give a file name')
    if path.exists() and not path.is_file():   # a device or a pipe: written in place
        if not os.access(path, os.W_OK):
            raise ValueError(f'{text} is not writable')
        return Path(value)
    parent = path.parent
    if not parent.is_dir():
        raise ValueError(f'{text}: the directory {str(parent)!r} does not exist')
    try:
        longest = os.pathconf(parent, 'PC_NAME_MAX')
    except (OSError, ValueError, AttributeError):   # not said (Windows)
        longest = 255
    if len(path.name.encode()) > longest:
        raise ValueError(f'{text}: the name is {len(path.name.encode())} bytes, longer than '
                         f'the {longest} its file system takes; give a shorter name')
    if not os.access(parent, os.W_OK | os.X_OK) and not (
            path.is_file() and os.access(path, os.W_OK)):   # else written in place
        raise ValueError(f'{text}: the directory {str(parent)!r} is not writable')
    return Path(value)



def check_indices(indices: Any, natoms: int) -> np.ndarray:
    """``indices`` as distinct atom indices (n,) among ``natoms``, or a
    ValueError naming the bad one."""
    index = np.asarray(indices)
    if index.ndim != 1 or not (index.size == 0 or np.issubdtype(index.dtype, np.integer)):
        raise ValueError(f'indices must be a 1-D sequence of atom indices, got {indices!r}')
    if index.size and (index.min() < 0 or index.max() >= natoms):
        bad = index[(index < 0) | (index >= natoms)][0]
        raise ValueError(f'indices: atom {bad} is not one of the {natoms} atoms')
    if np.unique(index).size != index.size:
        raise ValueError('indices: an atom is given twice')
    return index.astype(np.intp)


def did_you_mean(word: str, choices) -> str:
    """'; did you mean X?' for the choice closest to a mistyped ``word``
    (difflib's ratio at least 0.6), else ''."""

    close = difflib.get_close_matches(word, [str(c) for c in choices], n=1)
    return f'; did you mean {close[0]!r}?' if close else ''
