"""The Maud pair law, written once: repulsion and spring, energy to Hessian.

Units and signs. Points ``r_i`` in any length unit; ``a`` is a length and
``Q`` a force per length, so ``c = a**3 Q`` is an energy times a length. For
the pair vector ``d = r_i - r_j`` (the last axis of every ``d`` below, of size
``dim`` = 2 or 3) and its length ``L = |d|``:

- repulsion (unit strength): energy ``1 / L``, force on ``i`` ``+d / L**3``,
  pair block ``3 d d^T / L**5 - I / L**3``; callers multiply all three by
  ``c``;
- spring (zero unstressed length): energy ``Q L**2 / 2``, force on ``i``
  ``-Q d``, pair block ``Q I``; ``Q`` is each spring's own constant where
  one is given per spring (the potential's ``Q q_s``, ``q_s`` its force
  density multiplier);
- constant nodal load ``F_i`` (force units): energy ``-F_i . r_i``, force
  ``F_i``, no block.

- Energies count each pair once (the specification's ``P`` counts it twice:
  ``P = 2E``).
- Forces follow ASE's sign, ``f = -dE/dr``: the force on ``i`` is
  ``-dE/dd``, the force on ``j`` its opposite. Repulsion pushes ``i`` away
  from ``j``, a spring pulls it back.
- The pair block is ``B = -d(force on i)/dr_i = d2E/dd2``. The Hessian
  ``d2E/dr dr`` of a sum of pairs has ``-B_ij`` off the diagonal and the
  nodal block ``K_ii = sum_j B_ij`` on it (the stiffness of ``i`` with every
  other point held fixed). ``B`` does not change when ``d`` changes sign.

The spring part of the Hessian is constant: ``L_Q (x) I_dim`` with ``L_Q``
the spring graph's Laplacian weighted by each spring's constant
(:func:`spring_laplacian`, :func:`spring_hessian`).

Every backend either calls these functions (the numpy reference, the dense
Hessian, the near-field model of :mod:`.analysis`) or is tested element-wise
against them (the numba kernel, the FMM backend, the Hessian-vector product).
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree


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


def repulsion_stiffness(length: np.ndarray) -> np.ndarray:
    """Unit repulsion's stiffness along its pair, ``d2(1/L)/dL2 = 2 / L**3``
    (the largest eigenvalue of :func:`repulsion_block`), for lengths ``L``."""
    return 2.0 / length**3


def _per_pair(Q: float | np.ndarray, d: np.ndarray) -> np.ndarray:
    """``Q`` (a number, or one value per pair vector of ``d``) shaped to
    broadcast against the pairs of ``d``: ``d.shape[:-1]``."""
    return np.broadcast_to(np.asarray(Q, dtype=float), d.shape[:-1])


def repulsion_hessian_block(x: np.ndarray, index: np.ndarray, dim: int,
                            chunk_pairs: int = 1_000_000) -> np.ndarray:
    """The unit repulsion's Hessian on the coordinates of the points
    ``index`` (n,) of ``x`` (N, 3), shape (dim n, dim n), coordinates point
    by point in ``index``'s order: ``-B_ij`` between two of them, the nodal
    block ``K_ii = sum_j B_ij`` over every other point of ``x`` on the
    diagonal (:func:`repulsion_block`). O(n N) time, O(n**2 + chunk_pairs)
    memory: the whole Hessian's rows and columns there without forming it.
    Coincident points give non-finite entries, never an error."""
    index = np.asarray(index, dtype=np.intp)
    n = len(index)
    hessian = np.zeros((n, dim, n, dim))
    rows_a_chunk = max(1, chunk_pairs // max(len(x), 1))
    for start in range(0, n, rows_a_chunk):
        rows = np.arange(start, min(start + rows_a_chunk, n))
        d = x[index[rows], None, :dim] - x[None, :, :dim]   # (r, N, dim)
        d[np.arange(len(rows)), index[rows]] = np.inf   # no pair with itself
        with np.errstate(divide='ignore', over='ignore', invalid='ignore'):
            blocks = repulsion_block(d)   # inf at itself: zeroed
        blocks[np.arange(len(rows)), index[rows]] = 0.0
        hessian[rows] = -blocks[:, index].transpose(0, 2, 1, 3)
        hessian[rows, :, rows, :] = blocks.sum(axis=1)
    return hessian.reshape(dim * n, dim * n)


def spring_energy(d: np.ndarray, Q: float | np.ndarray) -> np.ndarray:
    """Spring energy ``Q L**2 / 2`` of each pair vector, shape
    ``d.shape[:-1]``; ``Q`` a number or one per pair (each spring's ``Q q``)."""
    return 0.5 * _per_pair(Q, d) * np.einsum('...k,...k->...', d, d)


def spring_force(d: np.ndarray, Q: float | np.ndarray) -> np.ndarray:
    """Spring force on ``i``, ``-Q d``, shape of ``d``; ``Q`` as
    :func:`spring_energy`."""
    return -_per_pair(Q, d)[..., None] * d


def spring_block(d: np.ndarray, Q: float | np.ndarray) -> np.ndarray:
    """Spring pair block ``Q I``, shape ``d.shape + (dim,)``, whatever ``d``;
    ``Q`` as :func:`spring_energy`."""
    return _per_pair(Q, d)[..., None, None] * np.eye(d.shape[-1])


def load_terms(positions: np.ndarray,
               loads: np.ndarray | None) -> tuple[float, np.ndarray]:
    """Energy ``-sum_i F_i . r_i`` and forces ``F_i`` (shape of
    ``positions``) of constant nodal loads ``F`` (same shape, force units;
    None: no loads)."""
    if loads is None:
        return 0.0, np.zeros_like(positions)
    return -float(np.einsum('ij,ij->', loads, positions)), loads.copy()


def spring_degrees(springs: np.ndarray, natoms: int,
                   Q: float | np.ndarray = 1.0) -> np.ndarray:
    """Weighted degree of each point, ``sum`` of ``Q`` over its springs,
    shape (natoms,); ``Q`` a number or one per spring (1: the number of
    springs at each point)."""
    pairs = np.asarray(springs, dtype=int).reshape(-1, 2)
    weights = np.broadcast_to(np.asarray(Q, dtype=float), len(pairs))
    return np.bincount(pairs.ravel(), weights=np.repeat(weights, 2),
                       minlength=natoms).astype(float)


def spring_terms(positions: np.ndarray, springs: np.ndarray,
                 Q: float | np.ndarray) -> tuple[float, np.ndarray]:
    """Energy and forces (shape of ``positions``) of the springs alone.

    ``springs`` is a (K, 2) int array; spring (i, j) has ``d = r_i - r_j``,
    its force goes to ``i`` and its opposite to ``j``; ``Q`` a number or one
    per spring.
    """
    d = positions[springs[:, 0]] - positions[springs[:, 1]]
    force = spring_force(d, Q)
    n = len(positions)
    forces = np.stack([np.bincount(springs[:, 0], force[:, k], n)
                       - np.bincount(springs[:, 1], force[:, k], n)
                       for k in range(positions.shape[1])], axis=1)
    return float(spring_energy(d, Q).sum()), forces


def spring_nodal_blocks(springs: np.ndarray, natoms: int, Q: float | np.ndarray,
                        dim: int) -> np.ndarray:
    """The springs' part of the nodal blocks, the weighted degree times
    ``I`` (:func:`spring_degrees`), shape (natoms, dim, dim)."""
    return spring_degrees(springs, natoms, Q)[:, None, None] * np.eye(dim)


def spring_laplacian(springs: np.ndarray, natoms: int,
                     Q: float | np.ndarray = 1.0) -> sp.csr_matrix:
    """The spring graph's weighted Laplacian ``sum_s Q_s (e_i - e_j)(e_i -
    e_j)^T`` (weighted degrees minus weighted adjacency), shape (natoms,
    natoms); ``Q`` a number or one per spring (1: ``D - A``). The one home
    of the springs' constant Hessian: :func:`spring_hessian` is it times
    ``I_dim``."""
    return _weighted_laplacian(springs, natoms, Q, 1)


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


def spring_hessian(springs: np.ndarray, natoms: int, Q: float | np.ndarray,
                   dim: int) -> sp.csr_matrix:
    """The springs' exact, constant Hessian ``L_Q (x) I_dim`` (``L_Q`` the
    Laplacian weighted by ``Q``, a number or one per spring:
    :func:`spring_laplacian`), shape (dim N, dim N) (csr), coordinates
    ordered point by point (x0, y0, z0, x1, ...)."""
    return _weighted_laplacian(springs, natoms, Q, dim)


def _weighted_laplacian(springs: np.ndarray, natoms: int, Q: float | np.ndarray,
                        dim: int) -> sp.csr_matrix:
    """``L_Q (x) I_dim`` (``dim`` 1: ``L_Q``) from
    :func:`spring_hessian_entries`, in one sparse construction (duplicates
    summed)."""
    rows, cols, data = spring_hessian_entries(springs, Q, dim)
    return sp.csr_matrix((data, (rows, cols)), shape=(dim * natoms,) * 2)


def spring_hessian_entries(springs: np.ndarray, Q: float | np.ndarray,
                           dim: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The entries of ``L_Q (x) I_dim`` as (rows, columns, values), a pair
    listed once per spring that meets it (their sum is the entry): each
    spring's ``Q_s`` on both diagonal places of each coordinate and ``-Q_s``
    on both off-diagonal ones; coordinates point by point (the matrix's
    size, and the springs' indices within it, are the callers')."""
    pairs = np.asarray(springs, dtype=int).reshape(-1, 2)
    i, j = pairs.T
    weights = np.broadcast_to(np.asarray(Q, dtype=float), len(pairs))
    axis = np.arange(dim)
    rows = dim * np.stack([i, j, i, j])[:, :, None] + axis
    cols = dim * np.stack([j, i, i, j])[:, :, None] + axis
    data = np.broadcast_to(np.stack([-weights, -weights, weights, weights])[:, :, None],
                           rows.shape)
    return rows.ravel(), cols.ravel(), data.ravel()


def entries_block(flat: np.ndarray, data: np.ndarray, size: int,
                  coords: np.ndarray) -> np.ndarray:
    """The dense block on the coordinates ``coords`` (m,) of a (size, size)
    matrix given by its entries as flat indices ``flat``, each once, and
    their values ``data``: (m, m), without the matrix."""
    where = np.full(size, -1)
    where[coords] = np.arange(len(coords))
    rows, columns = where[flat // size], where[flat % size]
    inside = (rows >= 0) & (columns >= 0)
    block = np.zeros((len(coords), len(coords)))
    block[rows[inside], columns[inside]] = data[inside]
    return block


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


#: Pairs closer than this many ``a`` overflow the blocks ``1 / L**3`` (and
#: from about 1e-154 a the forces): named when a result is not finite.
CLOSEST_REDUCED_DISTANCE = 1e-100


def raise_on_closest(scaled: np.ndarray, a: float) -> None:
    """Raise ValueError naming the closest pair of points if it is closer
    than :data:`CLOSEST_REDUCED_DISTANCE` ``a`` (``scaled`` is ``x / a``),
    or at the same position."""
    if len(scaled) < 2:
        return
    i, j, distance = closest_pair(scaled)
    if distance == 0:
        raise ValueError(f'atoms {i} and {j} are at the same position '
                         f'{(a * scaled[i]).tolist()}: the repulsion a^3 Q / L '
                         'is infinite there')
    if distance < CLOSEST_REDUCED_DISTANCE:
        raise ValueError(
            f'atoms {i} and {j} are {distance:.3g} a '
            f'apart (a = {a!r}): 1/L**3 overflows float64 below about '
            f'{CLOSEST_REDUCED_DISTANCE:g} a; move them apart or choose a '
            'smaller a')
