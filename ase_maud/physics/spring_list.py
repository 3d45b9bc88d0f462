"""Checks of the spring list; the springs' terms are in :mod:`.physics`."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike

#: The largest index an int64 holds (a larger one would wrap around).
INDEX_MAX = np.iinfo(np.int64).max


def _is_pair(row: Any) -> bool:
    """Whether ``row`` is a sequence of two scalars."""
    try:
        return np.asarray(row).shape == (2,)
    except ValueError:
        return False


def check_springs(springs: ArrayLike | None,
                  natoms: int | None = None) -> np.ndarray:
    """Return ``springs`` as an int array of shape (K, 2), or raise ValueError.

    Refused, each with the offending spring named by its row: a wrong shape,
    non-integer entries, a negative index or one ``>= natoms``, a spring from a
    point to itself, and a duplicate (the same pair listed twice, in either
    order: a pair is sprung or not, as in the specification).
    """
    try:
        raw = np.asarray(springs if springs is not None else [])
    except ValueError:   # numpy's 'inhomogeneous shape': rows of different lengths
        rows = list(springs)
        odd = next((s for s, row in enumerate(rows) if not _is_pair(row)), 0)
        raise ValueError(f'springs must be pairs of point indices, shape (K, 2); spring '
                         f'{odd} is {rows[odd]!r}') from None
    if raw.size == 0:
        return np.zeros((0, 2), dtype=int)
    if raw.ndim != 2 or raw.shape[1] != 2:
        raise ValueError(f'springs must have shape (K, 2), got {raw.shape}')
    if np.issubdtype(raw.dtype, np.unsignedinteger) and raw.max() > INDEX_MAX:
        raw = raw.astype(float)   # refused below, by value
    if not np.issubdtype(raw.dtype, np.integer):
        if not np.issubdtype(raw.dtype, np.floating):
            raise ValueError(f'springs must hold integer atom indices, got '
                             f'dtype {raw.dtype}')
        bad = ~np.isfinite(raw) | (raw != np.round(raw)) | (np.abs(raw) > INDEX_MAX)
        if bad.any():
            k = int(np.flatnonzero(bad.any(axis=1))[0])
            raise ValueError(f'spring {k} {raw[k].tolist()} is not a pair of '
                             'integer atom indices')
    pairs = raw.astype(int)
    _refuse_first(pairs.min(axis=1) < 0, pairs, 'has a negative atom index')
    if natoms is not None:
        check_range(pairs, natoms)
    _refuse_first(pairs[:, 0] == pairs[:, 1], pairs, 'ties an atom to itself')
    ordered = np.sort(pairs, axis=1)
    rows = ordered[np.lexsort((ordered[:, 1], ordered[:, 0]))]   # np.unique(axis=0) is slower
    repeated = (rows[1:] == rows[:-1]).all(axis=1)
    if repeated.any():   # the first of the pairs in order listed twice
        i, j = rows[np.argmax(repeated)]
        dup = [k for k in range(len(pairs)) if tuple(ordered[k]) == (i, j)]
        raise ValueError(f'springs {dup} all tie atoms {i} and {j}: '
                         'list each pair once')
    return pairs


def check_range(pairs: np.ndarray, natoms: int) -> None:
    """Raise ValueError naming the first spring of ``pairs`` (an int array of
    shape (K, 2)) with an index ``>= natoms``."""
    _refuse_first(pairs.max(axis=1, initial=-1) >= natoms, pairs,
                  f'names an atom beyond the last one (index {natoms - 1})')


def _refuse_first(bad, pairs, what):
    """Raise ValueError for the first spring marked in ``bad``, if any."""
    if bad.any():
        k = int(np.argmax(bad))
        i, j = pairs[k]
        raise ValueError(f'spring {k} ({i}, {j}) {what}')

