"""The Maud pair law, written once: repulsion and spring, energy to Hessian.

Units and signs. Points ``r_i`` in any length unit; ``a`` is a length and
``Q`` a force per length, so ``c = a**3 Q`` is an energy times a length. For
the pair vector ``d = r_i - r_j`` (the last axis of every ``d`` below, of size
``dim`` = 2 or 3) and its length ``L = |d|``:

- repulsion (unit strength): energy ``1 / L``, force on ``i`` ``+d / L**3``,
  pair block ``3 d d^T / L**5 - I / L**3``; callers multiply all three by
  ``c``;
- spring (zero unstressed length): energy ``Q L**2 / 2``, force on ``i``
  ``-Q d``, pair block ``Q I``.

- Energies count each pair once (the specification's ``P`` counts it twice:
  ``P = 2E``).
- Forces follow ASE's sign, ``f = -dE/dr``: the force on ``i`` is
  ``-dE/dd``, the force on ``j`` its opposite. Repulsion pushes ``i`` away
  from ``j``, a spring pulls it back.
- The pair block is ``B = -d(force on i)/dr_i = d2E/dd2``. The Hessian
  ``d2E/dr dr`` of a sum of pairs has ``-B_ij`` off the diagonal and the
  nodal block ``K_ii = sum_j B_ij`` on it (the stiffness of ``i`` with every
  other point held fixed). ``B`` does not change when ``d`` changes sign.

The spring part of the Hessian is constant: ``Q (L (x) I_dim)`` with ``L``
the spring graph's Laplacian (:func:`spring_hessian`).

Every backend either calls these functions (the numpy reference, the dense
Hessian, the near-field model of :mod:`.analysis`) or is tested element-wise
against them (the numba kernel, the FMM backend, the Hessian-vector product).
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import scipy.sparse as sp


def repulsion_energy(d: np.ndarray) -> np.ndarray:
    """Unit repulsion ``1 / L`` of each pair vector, shape ``d.shape[:-1]``."""
    return 1.0 / np.linalg.norm(d, axis=-1)


def repulsion_force(d: np.ndarray) -> np.ndarray:
    """Unit repulsive force on ``i``, ``d / L**3``, shape of ``d``."""
    inv = repulsion_energy(d)
    return d * (inv * inv * inv)[..., None]


def repulsion_block(d: np.ndarray) -> np.ndarray:
    """Unit repulsion pair block ``3 d d^T / L**5 - I / L**3``,
    shape ``d.shape + (dim,)``."""
    inv = repulsion_energy(d)[..., None, None]
    outer = d[..., :, None] * d[..., None, :]
    return inv**3 * (3.0 * inv * inv * outer - np.eye(d.shape[-1]))


def spring_energy(d: np.ndarray, Q: float) -> np.ndarray:
    """Spring energy ``Q L**2 / 2`` of each pair vector, shape
    ``d.shape[:-1]``."""
    return 0.5 * Q * np.einsum('...k,...k->...', d, d)


def spring_force(d: np.ndarray, Q: float) -> np.ndarray:
    """Spring force on ``i``, ``-Q d``, shape of ``d``."""
    return -Q * d


def spring_block(d: np.ndarray, Q: float) -> np.ndarray:
    """Spring pair block ``Q I``, shape ``d.shape + (dim,)``, whatever ``d``."""
    dim = d.shape[-1]
    return Q * np.broadcast_to(np.eye(dim), d.shape + (dim,))


def spring_degrees(springs: np.ndarray, natoms: int) -> np.ndarray:
    """Number of springs at each point, shape (natoms,)."""
    return np.bincount(np.asarray(springs, dtype=int).ravel(),
                       minlength=natoms)


def spring_terms(positions: np.ndarray, springs: np.ndarray,
                 Q: float) -> tuple[float, np.ndarray]:
    """Energy and forces (shape of ``positions``) of the springs alone.

    ``springs`` is a (K, 2) int array; spring (i, j) has ``d = r_i - r_j``,
    its force goes to ``i`` and its opposite to ``j``.
    """
    d = positions[springs[:, 0]] - positions[springs[:, 1]]
    force = spring_force(d, Q)
    forces = np.zeros_like(positions)
    np.add.at(forces, springs[:, 0], force)
    np.add.at(forces, springs[:, 1], -force)
    return float(spring_energy(d, Q).sum()), forces


def spring_nodal_blocks(springs: np.ndarray, natoms: int, Q: float,
                        dim: int) -> np.ndarray:
    """The springs' part of the nodal blocks, ``deg(i) Q I``, shape
    (natoms, dim, dim)."""
    deg = spring_degrees(springs, natoms)
    return deg[:, None, None] * spring_block(np.zeros((natoms, dim)), Q)


def spring_laplacian(springs: np.ndarray, natoms: int) -> sp.csr_matrix:
    """The spring graph's Laplacian ``D - A`` (degrees minus adjacency),
    shape (natoms, natoms)."""
    pairs = np.asarray(springs, dtype=int).reshape(-1, 2)
    i, j = pairs.T
    adjacency = sp.coo_matrix((np.ones(2 * len(pairs)),
                               (np.r_[i, j], np.r_[j, i])),
                              shape=(natoms, natoms))
    degrees = sp.diags(spring_degrees(pairs, natoms).astype(float))
    return sp.csr_matrix(degrees - adjacency)


def pair_block_laplacian(i: np.ndarray, j: np.ndarray, blocks: np.ndarray,
                         natoms: int) -> sp.csr_matrix:
    """``sum_p (e_i - e_j)(e_i - e_j)^T (x) blocks[p]`` over the pairs
    ``(i[p], j[p])``: each (dim, dim) block on both diagonal places and its
    negative on both off-diagonal ones (block rows sum to zero), shape
    (dim N, dim N), coordinates point by point."""
    dim = blocks.shape[-1]
    axis = np.arange(dim)
    rows = dim * np.stack([i, j, i, j])[:, :, None, None] + axis[:, None]
    cols = dim * np.stack([j, i, i, j])[:, :, None, None] + axis
    data = np.stack([-blocks, -blocks, blocks, blocks])
    rows, cols = (np.broadcast_to(r, data.shape).ravel() for r in (rows, cols))
    return sp.csr_matrix((data.ravel(), (rows, cols)), shape=(dim * natoms,) * 2)


def spring_hessian_entries(springs: np.ndarray, natoms: int, Q: float,
                           dim: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The springs' exact, constant Hessian ``Q (L (x) I_dim)`` as entries
    ``(rows, columns, values)`` (repeated indices add up), coordinates
    ordered point by point (x0, y0, z0, x1, ...): each spring's pair block
    ``Q I`` (:func:`spring_block`) at ``(i, i)`` and ``(j, j)``, its negative
    at ``(i, j)`` and ``(j, i)``."""
    i, j = np.asarray(springs, dtype=int).reshape(-1, 2).T
    axis = np.arange(dim)
    rows = (dim * np.stack([i, j, i, j])[:, :, None] + axis).ravel()
    cols = (dim * np.stack([i, j, j, i])[:, :, None] + axis).ravel()
    block = spring_block(np.zeros(dim), Q)[0, 0]
    values = np.repeat(np.array([block, block, -block, -block]), len(i) * dim)
    return rows, cols, values


def spring_hessian(springs: np.ndarray, natoms: int, Q: float,
                   dim: int) -> sp.csr_matrix:
    """The springs' exact, constant Hessian ``Q (L (x) I_dim)``, shape
    (dim N, dim N) (csr), from :func:`spring_hessian_entries`."""
    rows, cols, values = spring_hessian_entries(springs, natoms, Q, dim)
    return sp.csr_matrix((values, (rows, cols)), shape=(dim * natoms,) * 2)


def pair_chunks(natoms: int,
                chunk_pairs: int = 1_000_000) -> Iterator[tuple[np.ndarray,
                                                                np.ndarray]]:
    """Every unordered pair ``i < j`` once, as index arrays ``(i, j)`` of at
    most ``chunk_pairs`` pairs (or one row of pairs, if longer), in row
    order: O(chunk_pairs) memory however many points."""
    counts = np.arange(natoms - 1, -1, -1)   # pairs (i, j > i) of row i
    ends = np.cumsum(counts)
    row = 0
    while row < natoms - 1:
        before = ends[row] - counts[row]
        stop = int(np.searchsorted(ends, before + chunk_pairs, side='right'))
        stop = min(max(stop, row + 1), natoms - 1)
        rows = np.arange(row, stop)
        i = np.repeat(rows, counts[rows])
        start_of_row = np.repeat(ends[rows] - counts[rows] - before,
                                 counts[rows])
        j = i + 1 + np.arange(len(i)) - start_of_row
        yield i, j
        row = stop


def closest_pair(points: np.ndarray) -> tuple[int, int, float]:
    """The two nearest distinct points ``(i, j, L)``, ``i < j``, of (N, d)
    ``points`` (N >= 2), with their distance exact even where its square
    underflows (below about 1e-154 of the coordinates' unit)."""
    from scipy.spatial import cKDTree

    index = cKDTree(points).query(points, k=2)[1]
    itself = index[:, 0] == np.arange(len(points))
    other = np.where(itself, index[:, 1], index[:, 0])
    gap = points - points[other]
    scale = np.abs(gap).max(axis=1)
    unit = np.divide(gap, scale[:, None], out=np.zeros_like(gap),
                     where=scale[:, None] > 0)
    distance = scale * np.linalg.norm(unit, axis=1)
    i = int(np.argmin(distance))
    j = int(other[i])
    return min(i, j), max(i, j), float(distance[i])
