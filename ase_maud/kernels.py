"""Direct-sum kernels for the all-pairs repulsion ``sum_{i<j} 1/L_ij``.

Every kernel works on the unit-strength potential; the calculator multiplies by
``c = a**3 * Q``. For positions ``x`` (N, 3) it returns

- ``energy``: ``sum_{i<j} 1 / L_ij``;
- ``forces`` (N, 3): ``f_i = sum_j d_ij / L_ij**3`` with ``d_ij = x_i - x_j``
  (ASE sign: minus the gradient, so repulsion pushes points apart);
- ``blocks`` (N, 6), only when asked: the nodal stiffness ``K_ii`` (the diagonal
  3x3 Hessian block) ``sum_j (3 d d^T / L**5 - I / L**3)`` stored as
  xx, yy, zz, xy, xz, yz.

Memory is O(N): nothing of size N x N is ever formed. The numba kernel visits
each unordered pair once and gives both points their share; the numpy kernel is
the slow, plain reference the tests compare it with.
"""

import numba
import numpy as np

#: Order of the six independent entries of a symmetric 3x3 block.
VOIGT_PAIRS = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))


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
                        gx += px
                        gy += py
                        gz += pz
                        fx[j] -= px
                        fy[j] -= py
                        fz[j] -= pz
                        if with_blocks:
                            s = 3.0 * inv * inv
                            kxx = s * dx * px - inv3
                            kyy = s * dy * py - inv3
                            kzz = s * dz * pz - inv3
                            kxy = s * dx * py
                            kxz = s * dx * pz
                            kyz = s * dy * pz
                            bxx += kxx
                            byy += kyy
                            bzz += kzz
                            bxy += kxy
                            bxz += kxz
                            byz += kyz
                            block[t, 0, j] += kxx
                            block[t, 1, j] += kyy
                            block[t, 2, j] += kzz
                            block[t, 3, j] += kxy
                            block[t, 4, j] += kxz
                            block[t, 5, j] += kyz
                    fx[i] += gx
                    fy[i] += gy
                    fz[i] += gz
                    if with_blocks:
                        block[t, 0, i] += bxx
                        block[t, 1, i] += byy
                        block[t, 2, i] += bzz
                        block[t, 3, i] += bxy
                        block[t, 4, i] += bxz
                        block[t, 5, i] += byz
            energy[t] = e
        return energy.sum(), force.sum(axis=0).T.copy(), block.sum(axis=0).T.copy()

    return kernel


_numba_forces = _make_numba_kernel(False)
_numba_blocks = _make_numba_kernel(True)


def repulsion_numba(positions, blocks=False):
    """Unit repulsion by the compiled direct sum; see the module docstring."""
    p = np.ascontiguousarray(positions, dtype=float)
    kernel = _numba_blocks if blocks else _numba_forces
    nchunks = numba.get_num_threads()
    energy, forces, block6 = kernel(p[:, 0].copy(), p[:, 1].copy(),
                                    p[:, 2].copy(), nchunks)
    return energy, forces, (block6 if blocks else None)


def repulsion_numpy(positions, blocks=False, chunk_pairs=2_000_000):
    """Unit repulsion by chunked numpy broadcasting (the reference kernel).

    Rows are processed ``chunk_pairs // N`` at a time, so memory stays
    O(chunk_pairs), never O(N**2).
    """
    p = np.asarray(positions, dtype=float)
    n = len(p)
    rows = max(1, chunk_pairs // max(n, 1))
    energy = 0.0
    forces = np.zeros((n, 3))
    block6 = np.zeros((n, 6)) if blocks else None
    for start in range(0, n, rows):
        idx = np.arange(start, min(start + rows, n))
        d = p[idx, None, :] - p[None, :, :]
        r2 = np.einsum('ijk,ijk->ij', d, d)
        r2[np.arange(len(idx)), idx] = np.inf  # no self-interaction
        inv = 1.0 / np.sqrt(r2)
        inv3 = inv**3
        energy += 0.5 * inv.sum()
        forces[idx] = np.einsum('ij,ijk->ik', inv3, d)
        if blocks:
            s = 3.0 * inv3 * inv * inv
            for col, (a, b) in enumerate(VOIGT_PAIRS):
                term = s * d[:, :, a] * d[:, :, b]
                if a == b:
                    term -= inv3
                block6[idx, col] = term.sum(axis=1)
    return energy, forces, block6


def voigt_to_blocks(block6, dim):
    """Expand (N, 6) xx, yy, zz, xy, xz, yz entries to (N, dim, dim) blocks."""
    out = np.empty((len(block6), 3, 3))
    for col, (a, b) in enumerate(VOIGT_PAIRS):
        out[:, a, b] = out[:, b, a] = block6[:, col]
    return out[:, :dim, :dim]
