"""The ``numba`` backend: compiled, parallel direct sums over every pair.

The unit repulsion of :mod:`ase_maud.physics` (energy ``1 / L``, force on
``i`` ``d / L**3``, pair block ``3 d d^T / L**5 - I / L**3``, with
``d = r_i - r_j``), summed over every unordered pair, is written out here in
scalar code for speed; the tests compare it element-wise with the physics.
Memory is O(threads * N): nothing of size N x N is ever formed. Each unordered
pair is visited once and both points get their share (:func:`share`).

The same file holds the Hessian-vector product kernel of
:mod:`ase_maud.hessian`, so that numba's cache, which checks only the file of
the function it compiled, sees every change to :func:`share`.
"""

from __future__ import annotations

import numba
import numpy as np

from .base import Backend, Result


@numba.njit(inline='always')
def share(sx: float, sy: float, sz: float, ox: np.ndarray, oy: np.ndarray,
          oz: np.ndarray, j: int, px: float, py: float, pz: float,
          sign: float) -> tuple[float, float, float]:
    """Pair (i, j)'s term ``p`` of a sum over pairs, given to both points.

    Returns row i's running sums ``s + p``; adds ``sign * p`` to entry ``j``
    of ``ox, oy, oz`` (``sign`` -1 for a term odd in ``d``, as a force, +1
    for an even one, as a block).
    """
    ox[j] += sign * px
    oy[j] += sign * py
    oz[j] += sign * pz
    return sx + px, sy + py, sz + pz


def _make_numba_kernel(with_blocks):
    """Compile the direct sum, with or without the nodal blocks.

    ``with_blocks`` is a closure constant, so numba removes the block code from
    the energy-and-forces variant instead of testing it in the inner loop.
    Rows ``k`` and ``N-1-k`` (which hold ``N-1`` pairs together) go to the same
    chunk, so every thread gets the same amount of work; each chunk adds into a
    buffer of its own, summed at the end (no races, O(threads * N) memory).
    """

    @numba.njit(parallel=True, fastmath=True, cache=True)
    def kernel(x, y, z, nchunks):
        n = x.size
        energy = np.zeros(nchunks)
        force = np.zeros((nchunks, 3, n))
        nb = n if with_blocks else 0
        block = np.zeros((nchunks, 6, nb))
        half = (n + 1) // 2
        for t in numba.prange(nchunks):
            fx, fy, fz = force[t, 0], force[t, 1], force[t, 2]
            kxx, kyy, kzz = block[t, 0], block[t, 1], block[t, 2]
            kxy, kxz, kyz = block[t, 3], block[t, 4], block[t, 5]
            e = 0.0
            for k in range(t, half, nchunks):
                for r in range(2):
                    i = k if r == 0 else n - 1 - k
                    if r == 1 and i == k:
                        continue  # odd n: the middle row is visited once
                    xi, yi, zi = x[i], y[i], z[i]
                    gx = gy = gz = 0.0
                    bxx = byy = bzz = bxy = bxz = byz = 0.0
                    for j in range(i + 1, n):
                        dx = xi - x[j]
                        dy = yi - y[j]
                        dz = zi - z[j]
                        inv = 1.0 / np.sqrt(dx * dx + dy * dy + dz * dz)
                        inv3 = inv * inv * inv
                        e += inv
                        px, py, pz = dx * inv3, dy * inv3, dz * inv3
                        gx, gy, gz = share(gx, gy, gz, fx, fy, fz, j,
                                           px, py, pz, -1.0)
                        if with_blocks:
                            s = 3.0 * inv * inv
                            bxx, byy, bzz = share(
                                bxx, byy, bzz, kxx, kyy, kzz, j,
                                s * dx * px - inv3, s * dy * py - inv3,
                                s * dz * pz - inv3, 1.0)
                            bxy, bxz, byz = share(
                                bxy, bxz, byz, kxy, kxz, kyz, j,
                                s * dx * py, s * dx * pz, s * dy * pz, 1.0)
                    fx[i] += gx
                    fy[i] += gy
                    fz[i] += gz
                    if with_blocks:
                        kxx[i] += bxx
                        kyy[i] += byy
                        kzz[i] += bzz
                        kxy[i] += bxy
                        kxz[i] += bxz
                        kyz[i] += byz
            energy[t] = e
        return energy.sum(), force.sum(axis=0).T.copy(), block.sum(axis=0).T.copy()

    return kernel


_numba_forces = _make_numba_kernel(False)
_numba_blocks = _make_numba_kernel(True)


def evaluate(positions: np.ndarray, want_blocks: bool = False) -> Result:
    """Unit repulsion by the compiled direct sum; see :mod:`.base`."""
    p = np.ascontiguousarray(positions, dtype=float)
    kernel = _numba_blocks if want_blocks else _numba_forces
    nchunks = numba.get_num_threads()
    energy, forces, block6 = kernel(p[:, 0].copy(), p[:, 1].copy(),
                                    p[:, 2].copy(), nchunks)
    return energy, forces, (block6 if want_blocks else None)


@numba.njit(parallel=True, fastmath=True, cache=True)
def repulsion_hvp(x: np.ndarray, v: np.ndarray, nchunks: int) -> np.ndarray:
    """Unit repulsion part of ``H v``: ``sum_j B_ij (v_i - v_j)`` with c = 1.

    ``x`` (3, N) positions, ``v`` (m, 3, N) vectors, ``B_ij`` the pair block.
    Each unordered pair is visited once (``B_ji = B_ij``): ``w = B_ij (v_i -
    v_j)`` goes to ``i`` and ``-w`` to ``j``. The geometry of row ``i`` is
    computed once into buffers and reused for all m vectors. Rows go
    round-robin to ``nchunks`` chunks, each with buffers of its own; the
    chunks are summed at the end.
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
                    ax, ay, az = share(ax, ay, az, ox, oy, oz, j,
                                       geo[4, j] * (s * dx - ex),
                                       geo[4, j] * (s * dy - ey),
                                       geo[4, j] * (s * dz - ez), -1.0)
                ox[i] += ax
                oy[i] += ay
                oz[i] += az
    return out.sum(axis=0)


#: The compiled direct sum, the default backend.
BACKEND = Backend(
    name='numba', evaluate=evaluate, cost='N^2',
    summary='compiled direct sum over every pair, parallel over '
    'NUMBA_NUM_THREADS (the default)')
