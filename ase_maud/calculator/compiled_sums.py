"""The Maud law's sums on arrays, compiled: the springs' energy and forces
(:func:`spring_sums`), their Hessian's entries (:func:`flat_entries`) and a
small scene's energy, forces and Hessian in one pass (:func:`scene_terms`,
for a loop on arrays), in the units of :class:`.MaudPotential`, which keeps
their arrays (:meth:`.MaudPotential.scene_arrays`).
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from ase_maud.backends import direct


class SceneArrays(NamedTuple):
    """The arrays of a scene's law (:meth:`.MaudPotential.scene_arrays`):
    the springs (K, 2) int64 and their ``q`` (K,), the loads (N, 3) (zero
    if none), the springs' Hessian's flat entries and values
    (:func:`flat_entries`, times ``Q``), ``a``, ``Q`` and ``dim``."""

    springs: np.ndarray
    q: np.ndarray
    loads: np.ndarray
    flat: np.ndarray
    data: np.ndarray
    a: float
    Q: float
    dim: int


@numba.njit(cache=True)
def scene_terms(x: np.ndarray, law: SceneArrays) -> tuple[float, np.ndarray, np.ndarray, float]:
    """The energy, forces (N, 3) and dense Hessian (dim N, dim N) at the
    positions ``x`` (N, 3, user units) of the scene whose ``law`` is given,
    in one compiled pass, and the largest repulsion force (``a Q``): what
    :meth:`MaudCalculator.calculate <ase_maud.MaudCalculator.calculate>`
    gives for ``'hessian'`` by an exact backend, the same sums in the same
    order (:func:`.direct.repulsion_hessian`, :func:`spring_sums`, the
    loads, :meth:`.MaudPotential.whole_hessian`'s entries), for a loop on
    arrays. Results may be non-finite (coincident points, overflow): the
    caller asks the calculator, which names the problem."""
    n, dim, a, Q = x.shape[0], law.dim, law.a, law.Q
    if a > 0:
        scaled = x / a
        if dim == 2:
            scaled[:, 2] = 0.0
        e_rep, f_rep, hessian = direct.repulsion_hessian(scaled, dim)
        e_unit, f_unit = a * a * Q, a * Q
        force_max = 0.0
        for i in range(n):
            force_max = max(force_max, np.sqrt(f_rep[i, 0] ** 2 + f_rep[i, 1] ** 2
                                               + f_rep[i, 2] ** 2))
    else:   # a = 0: springs and loads alone, in the user's units, times Q
        scaled, e_rep, f_rep = x, 0.0, np.zeros((n, 3))
        hessian = np.zeros((dim * n, dim * n))
        e_unit = f_unit = Q
        force_max = 0.0
    e_spr, f_spr = spring_sums(scaled, law.springs, law.q)
    energy = e_unit * (e_rep + e_spr)
    forces = f_unit * (f_rep + f_spr)
    e_load = 0.0
    for i in range(n):
        for k in range(3):
            e_load += law.loads[i, k] * x[i, k]
    energy -= e_load
    forces += law.loads
    hessian *= Q
    flat_hessian = hessian.reshape(-1)
    for e in range(law.flat.shape[0]):
        flat_hessian[law.flat[e]] += law.data[e]
    if dim == 2:
        forces[:, 2] = 0.0
    return energy, forces, hessian, a * Q * force_max


@numba.njit(cache=True)
def spring_sums(x: np.ndarray, springs: np.ndarray,
                 q: np.ndarray) -> tuple[float, np.ndarray]:
    """``sum_s q_s |d_s|**2 / 2`` and the forces (N, 3): ``-q_s d_s`` on
    ``i`` and ``+q_s d_s`` on ``j`` of every spring ``s = (i, j)``, ``d_s =
    x_i - x_j`` (:func:`.physics.spring_terms`'s law; ``x`` (N, 3))."""
    forces = np.zeros((x.shape[0], 3))
    energy = 0.0
    for s in range(springs.shape[0]):
        i, j = springs[s, 0], springs[s, 1]
        for k in range(3):
            d = x[i, k] - x[j, k]
            pull = q[s] * d
            energy += 0.5 * d * pull
            forces[i, k] -= pull
            forces[j, k] += pull
    return energy, forces


@numba.njit(cache=True)
def flat_entries(springs: np.ndarray, weights: np.ndarray, dim: int,
                  natoms: int) -> tuple[np.ndarray, np.ndarray]:
    """The entries of the springs' Hessian ``L_w (x) I_dim`` (``w`` the
    springs' ``weights``: :func:`.physics.spring_hessian_entries`'s matrix)
    as flat indices into a dense (dim N, dim N) array, each once, and their
    values, row by row: an atom's diagonal (the sum of its springs' ``w``)
    and its sprung pairs' ``-w`` (summed over the pair's springs, if it is
    listed more than once, in either order). The springs of an atom are
    summed where it is their first end, in their order, then where it is
    their second: the order in which ``np.bincount`` sums those entries as
    listed, so the values are the same to the last bit; no sort."""
    count = springs.shape[0]
    starts = np.zeros(natoms + 1, dtype=np.int64)   # each atom's springs, in that order
    for s in range(count):
        starts[springs[s, 0] + 1] += 1
        starts[springs[s, 1] + 1] += 1
    for atom in range(natoms):
        starts[atom + 1] += starts[atom]
    other = np.empty(2 * count, dtype=np.int64)
    weight = np.empty(2 * count)
    fill = starts[:natoms].copy()
    for end in range(2):
        for s in range(count):
            atom = springs[s, end]
            other[fill[atom]] = springs[s, 1 - end]
            weight[fill[atom]] = weights[s]
            fill[atom] += 1
    rows = np.empty(natoms + 2 * count, dtype=np.int64)   # the entries, atom by atom
    columns = np.empty(len(rows), dtype=np.int64)
    sums = np.zeros(len(rows))
    slot = np.full(natoms, -1, dtype=np.int64)   # a column's entry (this row's if > diagonal)
    entries = 0
    for row in range(natoms):
        if starts[row] == starts[row + 1]:
            continue
        diagonal = entries
        rows[diagonal], columns[diagonal] = row, row
        entries += 1
        for p in range(starts[row], starts[row + 1]):
            sums[diagonal] += weight[p]
            column = other[p]
            if slot[column] <= diagonal:
                slot[column] = entries
                rows[entries], columns[entries] = row, column
                entries += 1
            sums[slot[column]] += -weight[p]
    size = dim * natoms
    flat = np.empty(dim * entries, dtype=np.int64)
    data = np.empty(dim * entries)
    for e in range(entries):
        for axis in range(dim):
            flat[dim * e + axis] = (dim * rows[e] + axis) * size + dim * columns[e] + axis
            data[dim * e + axis] = sums[e]
    return flat, data
