"""The full Hessian ``d2E/dr dr`` of the Maud potential, for analysis.

The pair block of points i, j (``d = r_i - r_j``, ``L = |d|``, ``c = a**3 Q``) is

    B_ij = c (3 d d^T / L**5 - I / L**3)  [+ Q I if (i, j) is a spring]

and the Hessian has ``H_ij = -B_ij`` off the diagonal and
``H_ii = sum_j B_ij`` (the nodal block ``K_ii``) on it.
"""

import numba
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


@numba.njit(parallel=True, fastmath=True, cache=True)
def _repulsion_hvp(x, v, nchunks):
    """Unit repulsion part of ``H v``: ``sum_j B_ij (v_i - v_j)`` with c = 1.

    ``x`` (3, N) positions, ``v`` (m, 3, N) vectors. Each unordered pair is
    visited once (``B_ji = B_ij``): ``w = B_ij (v_i - v_j)`` goes to ``i`` and
    ``-w`` to ``j``. The geometry of row ``i`` is computed once into buffers
    and reused for all m vectors. Rows go round-robin to ``nchunks`` chunks,
    each with buffers of its own; the chunks are summed at the end.
    """
    m, n = v.shape[0], x.shape[1]
    out = np.zeros((nchunks, m, 3, n))
    for t in numba.prange(nchunks):
        geo = np.empty((5, n))
        for i in range(t, n, nchunks):
            for j in range(i + 1, n):
                dx = x[0, i] - x[0, j]
                dy = x[1, i] - x[1, j]
                dz = x[2, i] - x[2, j]
                inv2 = 1.0 / (dx * dx + dy * dy + dz * dz)
                geo[0, j] = dx
                geo[1, j] = dy
                geo[2, j] = dz
                geo[3, j] = 3.0 * inv2
                geo[4, j] = inv2 * np.sqrt(inv2)
            for k in range(m):
                ox, oy, oz = out[t, k, 0], out[t, k, 1], out[t, k, 2]
                vx, vy, vz = v[k, 0], v[k, 1], v[k, 2]
                ax = ay = az = 0.0
                for j in range(i + 1, n):
                    dx, dy, dz = geo[0, j], geo[1, j], geo[2, j]
                    ex = vx[i] - vx[j]
                    ey = vy[i] - vy[j]
                    ez = vz[i] - vz[j]
                    s = geo[3, j] * (dx * ex + dy * ey + dz * ez)
                    px = geo[4, j] * (s * dx - ex)
                    py = geo[4, j] * (s * dy - ey)
                    pz = geo[4, j] * (s * dz - ez)
                    ax += px
                    ay += py
                    az += pz
                    ox[j] -= px
                    oy[j] -= py
                    oz[j] -= pz
                ox[i] += ax
                oy[i] += ay
                oz[i] += az
    return out.sum(axis=0)


def hessian_vector_product(positions, springs, a, Q, dim, v):
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
    x[:dim] = np.asarray(positions, dtype=float)[:, :dim].T
    u = np.zeros((len(block), 3, n))
    u[:, :dim] = block.transpose(0, 2, 1)
    hv = _repulsion_hvp(x, u, numba.get_num_threads())
    hv = a**3 * Q * hv[:, :dim].transpose(0, 2, 1)
    i, j = springs[:, 0], springs[:, 1]
    stretch = Q * (block[:, i] - block[:, j])
    np.add.at(hv, (slice(None), i), stretch)
    np.add.at(hv, (slice(None), j), -stretch)
    return hv.reshape(v.shape)
