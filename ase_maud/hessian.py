"""The full Hessian ``d2E/dr dr`` of the Maud potential, for analysis.

The pair block of points i, j (``d = r_i - r_j``, ``L = |d|``, ``c = a**3 Q``) is

    B_ij = c (3 d d^T / L**5 - I / L**3)  [+ Q I if (i, j) is a spring]

and the Hessian has ``H_ij = -B_ij`` off the diagonal and
``H_ii = sum_j B_ij`` (the nodal block ``K_ii``) on it.
"""

import numpy as np

from .springs import spring_degrees


def dense_hessian(positions, springs, a, Q, dim, chunk_pairs=2_000_000):
    """Dense Hessian, shape (dim N, dim N), in units of ``Q``.

    Built row-chunk by row-chunk; memory is the output plus O(chunk_pairs).
    For ``dim=2`` only x and y enter (points on a plane z = const).
    """
    x = np.asarray(positions, dtype=float)[:, :dim]
    n = len(x)
    c = a**3 * Q
    eye = np.eye(dim)
    hess = np.zeros((n, dim, n, dim))
    rows = max(1, chunk_pairs // max(n, 1))
    for start in range(0, n, rows):
        idx = np.arange(start, min(start + rows, n))
        d = x[idx, None, :] - x[None, :, :]
        r2 = np.einsum('ijk,ijk->ij', d, d)
        r2[np.arange(len(idx)), idx] = np.inf
        inv = 1.0 / np.sqrt(r2)
        inv3 = inv**3
        pair = c * (3.0 * (inv3 * inv * inv)[:, :, None, None]
                    * d[:, :, :, None] * d[:, :, None, :]
                    - inv3[:, :, None, None] * eye)
        hess[idx] = -pair.transpose(0, 2, 1, 3)
        hess[idx, :, idx, :] = pair.sum(axis=1)
    i, j = springs[:, 0], springs[:, 1]
    hess[i, :, j, :] -= Q * eye
    hess[j, :, i, :] -= Q * eye
    deg = spring_degrees(springs, n)
    hess[np.arange(n), :, np.arange(n), :] += Q * deg[:, None, None] * eye
    return hess.reshape(n * dim, n * dim)
