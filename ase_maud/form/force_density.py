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

__all__ = ['force_density_positions', 'free_factors', 'solve_force_density',
           'supported_net', 'unsupported']


def solve_force_density(atoms: Atoms) -> None:
    """Move the free points of the net ``atoms`` to the equilibrium of its
    springs and loads (:func:`force_density_positions`), the supports held.

    Parameters
    ----------
    atoms : Atoms
        The net, with a :class:`~ase_maud.MaudCalculator` (its springs, ``Q``,
        ``q``, loads) and its supports as constraints; moved in place.

    Returns
    -------
    None
        ``atoms`` are moved in place.

    Raises
    ------
    ValueError
        As :func:`force_density_positions`: no MaudCalculator, or supports
        that leave the equilibrium not unique.
    """
    atoms.set_positions(force_density_positions(atoms), apply_constraint=False)


def force_density_positions(atoms: Atoms) -> np.ndarray:
    """The positions (N, 3) of the net ``atoms`` at the equilibrium of its
    springs and loads (its calculator's ``springs``, ``Q``, ``q`` and
    ``loads``; the repulsion ignored, whatever ``a``), the supports where
    they are; ``atoms`` is not changed.

    Negative force densities (compression) are taken as compas_fd takes
    them: the equilibrium is then a stationary point of the energy (of an
    arch: its maximum), still one linear solve; a ValueError where they make
    the system singular.

    Supports are the points held in all three directions; a ValueError
    where :func:`unsupported` says why they do not make the equilibrium
    unique (a point held in some directions only: relax with
    :class:`~ase_maud.Maud` instead). A ``dim=2`` net stays on its plane.

    Parameters
    ----------
    atoms : Atoms
        The net, with a :class:`~ase_maud.MaudCalculator` and its supports as
        constraints (``FixAtoms``, or ``FixCartesian`` of every direction).

    Returns
    -------
    ndarray of shape (N, 3)
        The positions at ``Q L_ff x_f = F_f - Q L_fs x_s``, in the unit of
        the given positions; the supports where they are.

    Raises
    ------
    ValueError
        ``atoms.calc`` is not a MaudCalculator, or the supports do not make
        the equilibrium unique (a spring component with no support, a point
        held in some directions only: the message says which).
    """
    potential, held = supported_net(atoms, 'the force-density solve')
    natoms = len(atoms)
    positions = atoms.get_positions()
    free = np.flatnonzero(~held)
    if not free.size:
        return positions
    laplacian = potential.spring_laplacian(natoms).tocsr()
    loads = np.zeros((natoms, 3)) if potential.loads is None else potential.loads
    right = loads[free] / potential.Q - laplacian[free][:, held] @ positions[held]
    factors = free_factors(laplacian[free][:, free], bool(len(potential.compressed)))
    with np.errstate(over='ignore', invalid='ignore'):
        solved = factors.solve(right[:, :potential.dim])
    if not np.isfinite(right).all() or not np.isfinite(solved).all():
        if np.isfinite(right).all() and len(potential.compressed):
            raise ValueError(_SINGULAR)
        row = free[np.flatnonzero(~np.isfinite(solved).all(axis=1))[0]] \
            if not np.isfinite(solved).all() else free[0]
        raise ValueError(f'the force-density equilibrium overflows (point {row} at '
                         f'{solved[np.searchsorted(free, row)].tolist()}): the loads, '
                         'supports and force densities are beyond the range of floats; '
                         'scale them')
    positions[free, :potential.dim] = solved
    return positions


def supported_net(atoms: Atoms, what: str):
    """The MaudPotential of the net ``atoms`` and its supports (a boolean
    (N,) mask: held in every direction of its plane or space), or a
    ValueError saying why ``what`` cannot be made on it (no MaudCalculator;
    supports that leave the equilibrium not unique, :func:`unsupported`)."""
    calc = atoms.calc
    if not isinstance(calc, MaudCalculator):
        raise ValueError(f'{what} needs a net with a MaudCalculator attached, got '
                         f'{type(calc).__name__}')
    potential = calc.potential
    why = unsupported(atoms, potential.springs, potential.dim)
    if why is not None:
        raise ValueError(why)
    return potential, held_directions(atoms)[:, :potential.dim].all(axis=1)


_SINGULAR = ('the force densities make the free points\' matrix singular (members in '
             'compression, q < 0, balance those in tension): the net has no unique '
             'equilibrium; change a q')


def free_factors(matrix, compressed: bool):
    """The sparse LU factors of the free points' block ``L_ff`` of the
    q-weighted Laplacian. With every ``q > 0`` it is symmetric positive
    definite: a symmetric ordering, no pivoting. With members in compression
    (``compressed``) it is symmetric but indefinite or negative definite (an
    arch): partial pivoting. A ValueError where it is singular."""
    matrix = matrix.tocsc()
    try:
        if not compressed:
            return spla.splu(matrix, permc_spec='MMD_AT_PLUS_A', diag_pivot_thresh=0.0,
                             options={'SymmetricMode': True})
        return spla.splu(matrix)
    except RuntimeError as error:   # SuperLU: 'Factor is exactly singular'
        raise ValueError(_SINGULAR) from error
