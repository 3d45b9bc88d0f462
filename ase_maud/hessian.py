"""The full Hessian ``d2E/dr dr`` of the Maud potential, for analysis.

With the pair blocks ``B_ij`` of :mod:`.physics` (``c`` times the repulsion's
block, plus the spring's ``Q I`` if (i, j) is a spring), the Hessian has
``H_ij = -B_ij`` off the diagonal and ``H_ii = sum_j B_ij`` (the nodal block
``K_ii``) on it, in units of ``Q``; coordinates are ordered point by point
(x0, y0, [z0,] x1, ...). For ``dim=2`` only x and y enter (points on a plane
z = const).

The repulsion's part is computed in units of ``a``, ``Q`` times the unit
repulsion's Hessian at ``x / a`` (no ``a**3`` is formed: finite wherever the
blocks are).

Dense or not: :func:`dense_hessian` holds (dim N)**2 numbers (the calculator
refuses it above ``MaudCalculator.max_hessian_atoms``);
:func:`hessian_vector_product` is O(N) memory at any N, the way to the
spectrum of a large scene (:func:`ase_maud.analysis.hessian_operator`).
"""

from __future__ import annotations

import numba
import numpy as np
import scipy.sparse as sp

from . import physics
from .backends.direct import repulsion_hvp


def dense_hessian(positions: np.ndarray, springs: np.ndarray, a: float,
                  Q: float, dim: int, chunk_pairs: int = 1_000_000,
                  spring_part: sp.spmatrix | None = None) -> np.ndarray:
    """Dense Hessian, shape (dim N, dim N), in units of ``Q``.

    Built ``chunk_pairs`` pairs at a time; memory is the output plus
    O(chunk_pairs). ``spring_part``: the springs' Hessian
    (:func:`.physics.spring_hessian`) if the caller keeps it already.
    """
    x = np.asarray(positions, dtype=float)[:, :dim]
    n = len(x)
    hess = np.zeros((n, dim, n, dim))
    for i, j in physics.pair_chunks(n, chunk_pairs):
        block = Q * physics.repulsion_block((x[i] - x[j]) / a)
        hess[i, :, j, :] = hess[j, :, i, :] = -block
    diagonal = np.arange(n)
    hess[diagonal, :, diagonal, :] = -hess.sum(axis=2)   # K_ii = sum_j B_ij
    hess = hess.reshape(n * dim, n * dim)
    if spring_part is None:
        spring_part = physics.spring_hessian(springs, n, Q, dim)
    spring = spring_part.tocoo()
    hess[spring.row, spring.col] += spring.data
    return hess


def hessian_vector_product(positions: np.ndarray, springs: np.ndarray,
                           a: float, Q: float, dim: int,
                           v: np.ndarray) -> np.ndarray:
    """``H v`` without forming ``H``: ``(H v)_i = sum_j B_ij (v_i - v_j)``.

    ``v`` has shape (N, dim) (a displacement of every point) or (m, N, dim)
    (m of them, done in one pass over the pairs); the result has the same
    shape and units of ``Q`` times ``v``. O(m N**2) time, parallel over
    ``NUMBA_NUM_THREADS``; O(threads * m * N) memory.
    """
    n = len(positions)
    v = np.asarray(v, dtype=float)
    block = v.reshape(-1, n, dim)
    x = np.zeros((3, n))
    x[:dim] = np.asarray(positions, dtype=float)[:, :dim].T / a
    u = np.zeros((len(block), 3, n))
    u[:, :dim] = block.transpose(0, 2, 1)
    hv = repulsion_hvp(x, u, numba.get_num_threads())
    hv = Q * hv[:, :dim].transpose(0, 2, 1)
    spring = physics.spring_hessian(springs, n, Q, dim)
    hv += (spring @ block.reshape(len(block), -1).T).T.reshape(hv.shape)
    return hv.reshape(v.shape)
