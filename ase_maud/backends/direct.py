"""The ``numba`` backend: compiled, parallel direct sums over every pair.

The unit repulsion of :mod:`ase_maud.physics` (energy ``1 / L``, force on
``i`` ``d / L**3``, pair block ``3 d d^T / L**5 - I / L**3``, with
``d = r_i - r_j``), summed over every unordered pair, is written out here in
scalar code for speed; the tests compare it element-wise with the physics.
Memory is O(threads * N): nothing of size N x N is ever formed. Each unordered
pair is visited once and both points get their share, in a blocked loop that
the compiler vectorises (:func:`_make_numba_kernel`; ``benchmarks/kernel_throughput.py``
measures it against a plain loop over every ordered pair).

Both kernels here, the sums and the Hessian-vector product
(:func:`repulsion_hvp`), take the pair law from one inlined function,
:func:`pair_law`; they live in one file so that numba's cache, which checks
only the file of the function it compiled, sees every change to it.
"""

from __future__ import annotations

import numba
import numpy as np

from ase_maud.backends.base import Backend, Result


@numba.njit(inline='always')
def pair_law(inv: float) -> tuple[float, float]:
    """The unit pair law's radial factors at ``inv = 1 / L``:
    ``(1 / L**3, 3 / L**2)``. The force on ``i`` is ``d / L**3`` and the pair
    block ``(3 d d^T / L**2 - I) / L**3`` (:mod:`ase_maud.physics`)."""
    inv2 = inv * inv
    return inv2 * inv, 3.0 * inv2


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


#: Points per tile of the blocked loop. A tile's coordinates, accumulators and
#: reciprocal distances (at most 12 rows of TILE doubles, 24 KiB) stay in a
#: 32 KiB L1 cache; 512 is slower (rows 4 KiB apart alias in the cache).
TILE = 256


def _make_numba_kernel(with_blocks, parallel):
    """Compile the direct sum, with or without the nodal blocks, on numba's
    threads or (``parallel=False``) on the caller's alone.

    ``with_blocks`` is a closure constant, so numba removes the block code from
    the energy-and-forces variant instead of testing it in the inner loop.

    The points are cut into tiles of :data:`TILE`; tile ``a`` meets tiles
    ``b >= a`` (within the diagonal tile, only ``j > i``). Tile ``b``'s
    coordinates and its share of every pair sum are copied into a buffer of
    contiguous rows, and each row ``i`` of tile ``a`` makes two passes over it:
    the first computes ``1 / L`` (sqrt and division, the slow instructions,
    alone in their loop), the second everything else, adding the pair terms to
    row ``i``'s running sums and to tile ``b``'s buffer. Both inner loops
    vectorise: their indices are unsigned (numba does not wrap them as negative
    indices) and the buffer rows are one array. Only ``xx``, ``yy`` of the
    diagonal of a block are summed: each pair block is traceless, so ``zz =
    -(xx + yy)`` for the sums too.

    ``kernel(x, y, z, energy, acc)`` runs ``energy.size`` chunks: tile rows
    ``k`` and ``ntiles-1-k`` (which hold ``ntiles+1`` tile pairs together) go
    to the same chunk, so every thread gets the same amount of work; chunk
    ``t`` adds its energy to ``energy[t]`` and its sums to ``acc[t]`` (rows
    fx, fy, fz and, with blocks, kxx, kyy, kxy, kxz, kyz), summed by
    :func:`direct_sum` (no races, O(threads * N) memory). ``nogil``: Python
    threads that each sum a scene of their own (a band's images) run at once.
    ``error_model='numpy'``:
    a division by zero (coincident points) gives inf instead of raising, and
    the check for it would keep the loops from vectorising.
    """
    nacc = 8 if with_blocks else 3  # fx fy fz [kxx kyy kxy kxz kyz]
    inv_row = 3 + nacc  # buffer rows: x y z, the nacc sums, 1 / L

    # ``parallel`` is read in the body so that it is a closure variable:
    # numba's cache keys a closure by its code and closure values, not by its
    # compile options, and would otherwise give both variants one entry.
    @numba.njit(parallel=parallel, fastmath=True, error_model='numpy', cache=True,
                nogil=True)
    def kernel(x, y, z, energy, acc):
        n, nchunks = x.size, energy.size
        assert parallel or nchunks == 1
        ntiles = (n + TILE - 1) // TILE
        for t in numba.prange(nchunks):
            out = acc[t]
            buf = np.empty((inv_row + 1, TILE))
            e = 0.0
            for k in range(t, (ntiles + 1) // 2, nchunks):
                for r in range(2):
                    a = k if r == 0 else ntiles - 1 - k
                    if r == 1 and a == k:
                        continue  # odd ntiles: the middle tile row is visited once
                    for b in range(a, ntiles):
                        j0 = b * TILE
                        m = min(TILE, n - j0)
                        for jj in range(m):
                            buf[0, jj] = x[j0 + jj]
                            buf[1, jj] = y[j0 + jj]
                            buf[2, jj] = z[j0 + jj]
                            for c in range(3, inv_row):
                                buf[c, jj] = 0.0
                        for i in range(a * TILE, min(a * TILE + TILE, n)):
                            xi, yi, zi = x[i], y[i], z[i]
                            # j > i: in the diagonal tile from i + 1, else all of it
                            lo, hi = np.uint64(max(i + 1 - j0, 0)), np.uint64(m)
                            for jj in range(lo, hi):
                                dx = xi - buf[0, jj]
                                dy = yi - buf[1, jj]
                                dz = zi - buf[2, jj]
                                buf[inv_row, jj] = 1.0 / np.sqrt(dx * dx + dy * dy + dz * dz)
                            gx = gy = gz = 0.0
                            bxx = byy = bxy = bxz = byz = 0.0
                            for jj in range(lo, hi):
                                dx = xi - buf[0, jj]
                                dy = yi - buf[1, jj]
                                dz = zi - buf[2, jj]
                                inv = buf[inv_row, jj]
                                inv3, three_inv2 = pair_law(inv)
                                e += inv
                                px, py, pz = dx * inv3, dy * inv3, dz * inv3
                                gx += px
                                gy += py
                                gz += pz
                                buf[3, jj] -= px
                                buf[4, jj] -= py
                                buf[5, jj] -= pz
                                if with_blocks:
                                    sx, sy = three_inv2 * dx, three_inv2 * dy
                                    qxx = sx * px - inv3
                                    qyy = sy * py - inv3
                                    qxy, qxz, qyz = sx * py, sx * pz, sy * pz
                                    bxx += qxx
                                    byy += qyy
                                    bxy += qxy
                                    bxz += qxz
                                    byz += qyz
                                    buf[6, jj] += qxx
                                    buf[7, jj] += qyy
                                    buf[8, jj] += qxy
                                    buf[9, jj] += qxz
                                    buf[10, jj] += qyz
                            out[0, i] += gx
                            out[1, i] += gy
                            out[2, i] += gz
                            if with_blocks:
                                out[3, i] += bxx
                                out[4, i] += byy
                                out[5, i] += bxy
                                out[6, i] += bxz
                                out[7, i] += byz
                        for c in range(nacc):
                            for jj in range(m):
                                out[c, j0 + jj] += buf[3 + c, jj]
            energy[t] = e

    return kernel


#: The kernels by (with blocks, parallel).
_KERNELS = {(blocks, parallel): _make_numba_kernel(blocks, parallel)
            for blocks in (False, True) for parallel in (False, True)}


def direct_sum(x: np.ndarray, y: np.ndarray, z: np.ndarray, nchunks: int,
               want_blocks: bool) -> Result:
    """The compiled sum over ``nchunks`` chunks (any number, whatever the
    thread count), from coordinate arrays; see :mod:`.base` for the result.

    The buffers are made and summed here, outside the compiled kernel: in a
    parallel numba function every array expression is a parallel region of its
    own, whose start and end cost a thread wake-up each on a busy machine.
    Chunks beyond the ``(ntiles + 1) // 2`` that have work are not made, and a
    scene of one chunk (up to ``2 TILE`` points) runs on the caller's thread
    alone: a parallel region waits for every thread, and on a machine whose
    other cores are busy that wait is many times a small scene's sum.
    """
    n = x.size
    nchunks = max(1, min(nchunks, (-(-n // TILE) + 1) // 2))
    energy = np.zeros(nchunks)
    acc = np.zeros((nchunks, 8 if want_blocks else 3, n))
    _KERNELS[want_blocks, nchunks > 1](x, y, z, energy, acc)
    total = acc.sum(axis=0)
    if not want_blocks:
        return energy.sum(), total.T.copy(), None
    kxx, kyy, kxy, kxz, kyz = total[3:]
    block6 = np.stack([kxx, kyy, -(kxx + kyy), kxy, kxz, kyz], axis=1)  # traceless
    return energy.sum(), total[:3].T.copy(), block6


def evaluate(positions: np.ndarray, want_blocks: bool = False) -> Result:
    """Unit repulsion by the compiled direct sum; see :mod:`.base`."""
    p = np.ascontiguousarray(positions, dtype=float)
    return direct_sum(p[:, 0].copy(), p[:, 1].copy(), p[:, 2].copy(),
                      numba.get_num_threads(), want_blocks)


def hvp(positions: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Unit repulsion part of ``H v`` at ``positions`` (N, 3) for ``v``
    (m, N, 3), by :func:`repulsion_hvp` on numba's threads."""
    x = np.ascontiguousarray(np.asarray(positions, dtype=float).T)
    u = np.ascontiguousarray(np.asarray(v, dtype=float).transpose(0, 2, 1))
    return repulsion_hvp(x, u, numba.get_num_threads()).transpose(0, 2, 1)


@numba.njit(parallel=True, fastmath=True, error_model='numpy', cache=True)
def repulsion_hvp(x: np.ndarray, v: np.ndarray, nchunks: int) -> np.ndarray:
    """Unit repulsion part of ``H v``: ``sum_j B_ij (v_i - v_j)`` with c = 1.

    ``x`` (3, N) positions, ``v`` (m, 3, N) vectors, ``B_ij`` the pair block.
    Each unordered pair is visited once (``B_ji = B_ij``): ``w = B_ij (v_i -
    v_j)`` goes to ``i`` and ``-w`` to ``j``. The geometry of row ``i`` is
    computed once into buffers (``1 / L`` in a loop of its own, the square
    root and division alone, as :func:`_make_numba_kernel` does) and reused for all
    m vectors; unsigned loop indices and ``error_model='numpy'`` let the
    loops vectorise. Rows go round-robin to ``nchunks``
    chunks, each with buffers of its own; the chunks are summed at the end.
    """
    m, n = v.shape[0], x.shape[1]
    out = np.zeros((nchunks, m, 3, n))
    for t in numba.prange(nchunks):
        geo = np.empty((5, n))
        for i in range(t, n, nchunks):
            xi, yi, zi = x[0, i], x[1, i], x[2, i]
            lo, hi = np.uint64(i + 1), np.uint64(n)
            for j in range(lo, hi):
                dx = xi - x[0, j]
                dy = yi - x[1, j]
                dz = zi - x[2, j]
                geo[0, j] = dx
                geo[1, j] = dy
                geo[2, j] = dz
                geo[4, j] = 1.0 / np.sqrt(dx * dx + dy * dy + dz * dz)
            for j in range(lo, hi):
                inv3, three_inv2 = pair_law(geo[4, j])
                geo[3, j] = three_inv2
                geo[4, j] = inv3
            for k in range(m):
                ox, oy, oz = out[t, k, 0], out[t, k, 1], out[t, k, 2]
                vx, vy, vz = v[k, 0], v[k, 1], v[k, 2]
                vxi, vyi, vzi = vx[i], vy[i], vz[i]
                ax = ay = az = 0.0
                for j in range(lo, hi):
                    dx, dy, dz = geo[0, j], geo[1, j], geo[2, j]
                    ex = vxi - vx[j]
                    ey = vyi - vy[j]
                    ez = vzi - vz[j]
                    s = geo[3, j] * (dx * ex + dy * ey + dz * ez)
                    c = geo[4, j]
                    ax, ay, az = share(ax, ay, az, ox, oy, oz, j, c * (s * dx - ex),
                                       c * (s * dy - ey), c * (s * dz - ez), -1.0)
                ox[i] += ax
                oy[i] += ay
                oz[i] += az
    return out.sum(axis=0)


def hessian(positions: np.ndarray, dim: int) -> tuple[float, np.ndarray, np.ndarray]:
    """The unit repulsion's energy, forces (N, 3) and dense Hessian (dim N,
    dim N) at ``positions`` (N, 3), in one pass over the pairs
    (:func:`repulsion_hessian`): what a Newton step on a small scene needs."""
    return repulsion_hessian(np.ascontiguousarray(positions, dtype=float), dim)


@numba.njit(fastmath=True, error_model='numpy', cache=True)
def repulsion_hessian(x: np.ndarray, dim: int) -> tuple[float, np.ndarray, np.ndarray]:
    """Energy ``sum 1 / L``, forces ``sum d / L**3`` and the Hessian: ``-B_ij``
    off the diagonal and ``sum_j B_ij`` on it; every pair once, one thread
    (for the small scenes a dense Hessian is for). Coincident points give
    non-finite results, never an error (the calculator names them)."""
    n = x.shape[0]
    h = np.zeros((n * dim, n * dim))
    f = np.zeros((n, 3))
    e = 0.0
    d = np.empty(3)
    for i in range(n):
        for j in range(i + 1, n):
            for k in range(3):
                d[k] = x[i, k] - x[j, k]
            inv = 1.0 / np.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
            inv3, three_inv2 = pair_law(inv)
            e += inv
            for k in range(3):
                f[i, k] += d[k] * inv3
                f[j, k] -= d[k] * inv3
            for a in range(dim):
                for b in range(dim):
                    block = three_inv2 * d[a] * d[b] * inv3
                    if a == b:
                        block -= inv3
                    h[i * dim + a, j * dim + b] = -block
                    h[j * dim + a, i * dim + b] = -block
                    h[i * dim + a, i * dim + b] += block
                    h[j * dim + a, j * dim + b] += block
    return e, f, h


#: The compiled direct sum (what ``auto`` runs below its crossover).
BACKEND = Backend(
    name='numba', evaluate=evaluate, cost='N^2', hvp=hvp, hessian=hessian,
    summary='compiled direct sum over every pair, parallel over '
    'NUMBA_NUM_THREADS')


@numba.njit(error_model='numpy', cache=True)
def repulsion_hessian_block(x: np.ndarray, index: np.ndarray, dim: int) -> np.ndarray:
    """:func:`ase_maud.physics.pair_law.repulsion_hessian_block` compiled: the
    unit repulsion's Hessian on the coordinates of the points ``index`` (n,)
    of ``x`` (N, 3), shape (dim n, dim n), in O(n N) time and O(n**2)
    memory, with the reference's arithmetic in its order (no fastmath: the
    length as ``norm``'s sum of squares, ``L**-3`` as ``pow``, each nodal
    block summed over the points in their order), so that a block is that
    function's to the last bit on a small scene, without its dozens of
    array calls. Coincident points give non-finite entries, never an error."""
    n, count = index.shape[0], x.shape[0]
    hessian = np.zeros((n, dim, n, dim))
    where = np.full(count, -1)
    for r in range(n):
        where[index[r]] = r
    d = np.empty(dim)
    for r in range(n):
        i = index[r]
        for j in range(count):
            if j == i:
                continue
            square = 0.0
            for a in range(dim):
                d[a] = x[i, a] - x[j, a]
                square += d[a] * d[a]
            inv = 1.0 / np.sqrt(square)
            inv3 = inv ** 3.0
            column = where[j]
            for a in range(dim):
                for b in range(dim):
                    block = 3.0 * inv * inv * (d[a] * d[b])
                    if a == b:
                        block -= 1.0
                    block = inv3 * block
                    hessian[r, a, r, b] += block
                    if column >= 0:
                        hessian[r, a, column, b] = -block
    return hessian.reshape(dim * n, dim * n)
