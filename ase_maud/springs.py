"""Zero-length linear springs ``Q L**2 / 2`` on listed pairs: checks and terms."""

import numpy as np


def check_springs(springs, natoms=None):
    """Return ``springs`` as an int array of shape (K, 2), or raise ValueError.

    Refused, each with the offending spring named by its row: a wrong shape,
    non-integer entries, a negative index or one ``>= natoms``, a spring from a
    point to itself, and a duplicate (the same pair listed twice, in either
    order: a pair is sprung or not, as in the specification).
    """
    raw = np.asarray(springs if springs is not None else [])
    if raw.size == 0:
        return np.zeros((0, 2), dtype=int)
    if raw.ndim != 2 or raw.shape[1] != 2:
        raise ValueError(f'springs must have shape (K, 2), got {raw.shape}')
    if not np.issubdtype(raw.dtype, np.integer):
        if not np.issubdtype(raw.dtype, np.number):
            raise ValueError(f'springs must hold integer atom indices, got '
                             f'dtype {raw.dtype}')
        bad = ~np.isfinite(raw) | (raw != np.round(raw))
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
    _, first, counts = np.unique(ordered, axis=0, return_index=True,
                                 return_counts=True)
    if np.any(counts > 1):
        k0 = first[np.argmax(counts > 1)]
        i, j = ordered[k0]
        dup = [k for k in range(len(pairs)) if tuple(ordered[k]) == (i, j)]
        raise ValueError(f'springs {dup} all tie atoms {i} and {j}: '
                         'list each pair once')
    return pairs


def check_range(pairs, natoms):
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


def spring_degrees(springs, natoms):
    """Number of springs at each point, shape (natoms,)."""
    return np.bincount(springs.ravel(), minlength=natoms)


def spring_terms(positions, springs, Q):
    """Energy and forces of the springs alone.

    Energy ``sum Q L**2 / 2``; force on ``i`` of spring (i, j) is ``-Q d``
    with ``d = r_i - r_j`` (and ``+Q d`` on ``j``). The nodal block of a spring
    is ``Q I`` at both ends, added by the caller from :func:`spring_degrees`.
    """
    d = positions[springs[:, 0]] - positions[springs[:, 1]]
    energy = 0.5 * Q * np.einsum('ij,ij->', d, d)
    forces = np.zeros_like(positions)
    np.add.at(forces, springs[:, 0], -Q * d)
    np.add.at(forces, springs[:, 1], Q * d)
    return energy, forces
