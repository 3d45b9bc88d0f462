"""The ``numpy`` backend: the pair law of :mod:`ase_maud.physics`, summed.

The slow, plain reference the faster backends are compared with: every
unordered pair once, ``chunk_pairs`` pairs at a time (O(chunk_pairs) memory,
never O(N**2)), each pair's term from :mod:`ase_maud.physics` given to both
of its points.
"""

from __future__ import annotations

import numpy as np

from ase_maud.backends.base import Backend, Result, blocks_to_voigt
from ase_maud.physics import pair_law as physics


def evaluate(positions: np.ndarray, want_blocks: bool = False,
             chunk_pairs: int = 1_000_000) -> Result:
    """Unit repulsion by chunked numpy sums over pairs; see :mod:`.base`."""
    p = np.asarray(positions, dtype=float)
    n = len(p)
    energy = 0.0
    forces = np.zeros((n, 3))
    blocks = np.zeros((n, 9))
    with np.errstate(divide='ignore', invalid='ignore'):  # coincident points
        for i, j in physics.pair_chunks(n, chunk_pairs):
            d = p[i] - p[j]
            energy += physics.repulsion_energy(d).sum()
            force = physics.repulsion_force(d)
            for k in range(3):
                forces[:, k] += (np.bincount(i, force[:, k], n)
                                 - np.bincount(j, force[:, k], n))
            if want_blocks:
                block = physics.repulsion_block(d).reshape(-1, 9)
                for k in range(9):
                    blocks[:, k] += (
                        np.bincount(i, block[:, k], n)
                        + np.bincount(j, block[:, k], n))
    block6 = blocks_to_voigt(blocks.reshape(n, 3, 3)) if want_blocks else None
    return float(energy), forces, block6


def hessian(positions: np.ndarray, dim: int,
            chunk_pairs: int = 1_000_000) -> tuple[float, np.ndarray, np.ndarray]:
    """The unit repulsion's energy, forces and dense Hessian (dim N, dim N):
    ``-B_ij`` off the diagonal, the nodal block ``sum_j B_ij`` on it,
    ``chunk_pairs`` pairs at a time (memory: the output plus O(chunk_pairs))."""
    energy, forces, _ = evaluate(positions, False, chunk_pairs)
    x = np.asarray(positions, dtype=float)[:, :dim]
    n = len(x)
    hess = np.zeros((n, dim, n, dim))
    for i, j in physics.pair_chunks(n, chunk_pairs):
        block = physics.repulsion_block(x[i] - x[j])
        hess[i, :, j, :] = hess[j, :, i, :] = -block
    diagonal = np.arange(n)
    hess[diagonal, :, diagonal, :] = -hess.sum(axis=2)   # K_ii = sum_j B_ij
    return energy, forces, hess.reshape(n * dim, n * dim)


#: The numpy reference.
BACKEND = Backend(
    name='numpy', evaluate=evaluate, cost='N^2', hessian=hessian,
    summary='numpy sums of the pair law in ase_maud.physics: the slow '
    'reference')
