"""The force-density method: the equilibrium of a net's springs and loads
alone (``a = 0``), by one sparse linear solve.

With the repulsion off, the forces at the free points are linear in the
positions, ``f_free = -Q (L_ff x_f + L_fs x_s) + F_f`` (``L`` the springs'
Laplacian weighted by ``q``, ``s`` the supports), so the equilibrium is
``Q L_ff x_f = F_f - Q L_fs x_s``: one factorisation of ``L_ff`` serves every
coordinate (Schek's force-density method; compas_fd's ``fd_numpy``). It is
the limit of Maud's minimum as ``a -> 0`` (docs/theory.md).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse.linalg as spla
from ase import Atoms

from ase_maud.calculator.maud_calculator import MaudCalculator
from ase_maud.physics.topology import held_directions, unsupported

__all__ = ['force_density_positions', 'solve_force_density', 'unsupported']


def solve_force_density(atoms: Atoms) -> None:
    """Move the free points of the net ``atoms`` to the equilibrium of its
    springs and loads (:func:`force_density_positions`), the supports held."""
    atoms.set_positions(force_density_positions(atoms), apply_constraint=False)


def force_density_positions(atoms: Atoms) -> np.ndarray:
    """The positions (N, 3) of the net ``atoms`` at the equilibrium of its
    springs and loads (its calculator's ``springs``, ``Q``, ``q`` and
    ``loads``; the repulsion ignored, whatever ``a``), the supports where
    they are; ``atoms`` is not changed.

    Supports are the points held in all three directions; a ValueError
    where :func:`unsupported` says why they do not make the equilibrium
    unique (a point held in some directions only: relax with
    :class:`~ase_maud.Maud` instead). A ``dim=2`` net stays on its plane.
    """
    calc = atoms.calc
    if not isinstance(calc, MaudCalculator):
        raise ValueError('the force-density solve needs a net with a MaudCalculator '
                         f'attached, got {type(calc).__name__}')
    potential = calc.potential
    why = unsupported(atoms, potential.springs, potential.dim)
    if why is not None:
        raise ValueError(why)
    natoms = len(atoms)
    held = held_directions(atoms)[:, :potential.dim].all(axis=1)
    positions = atoms.get_positions()
    free = np.flatnonzero(~held)
    if not free.size:
        return positions
    laplacian = potential.spring_laplacian(natoms).tocsr()
    loads = np.zeros((natoms, 3)) if potential.loads is None else potential.loads
    right = loads[free] / potential.Q - laplacian[free][:, held] @ positions[held]
    # L_ff is symmetric positive definite: a symmetric ordering, no pivoting
    factors = spla.splu(laplacian[free][:, free].tocsc(), permc_spec='MMD_AT_PLUS_A',
                        diag_pivot_thresh=0.0, options={'SymmetricMode': True})
    with np.errstate(over='ignore', invalid='ignore'):
        solved = factors.solve(right[:, :potential.dim])
    if not np.isfinite(right).all() or not np.isfinite(solved).all():
        row = free[np.flatnonzero(~np.isfinite(solved).all(axis=1))[0]] \
            if not np.isfinite(solved).all() else free[0]
        raise ValueError(f'the force-density equilibrium overflows (point {row} at '
                         f'{solved[np.searchsorted(free, row)].tolist()}): the loads, '
                         'supports and force densities are beyond the range of floats; '
                         'scale them')
    positions[free, :potential.dim] = solved
    return positions
