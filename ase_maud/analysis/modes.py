"""Modes of a Maud scene through phonopy and through ASE's VibrationsData.

Conventions, fixed here once:

- Force constants are phonopy's ``fc[i, j, a, b] = d2E / du_ia du_jb``
  (shape (N, N, 3, 3), units of ``Q``), i.e. the Hessian
  ``H[3 i + a, 3 j + b]``; phonopy's own finite differences use the same
  sign (``fc = -dF_j / du_i``), which :func:`finite_difference_force_constants`
  lets the tests check.
- Masses are 1 unless given: the potential has no inertia, and with unit masses
  the squared frequencies are the Hessian's eigenvalues, the numbers
  :func:`ase_maud.analysis.stationary.classify` counts. Pass ``masses=atoms.get_masses()``
  for the dynamics of massive points.
- Frequencies are angular, ``omega = sqrt(lambda / m)`` in units of
  ``sqrt(Q / mass)`` (no ``2 pi``, no THz), negative for an imaginary one.
- A ``dim=2`` scene is treated with the same potential in 3D: on a plane the
  in-plane and out-of-plane motions decouple, so the in-plane block is exactly
  the ``dim=2`` Hessian and the extra modes are those of points free to leave
  the plane (their stability is what a 2D calculator cannot see).
- Everything here is dense, (3N)**2 numbers: each function refuses more than
  ``MaudCalculator.max_hessian_atoms`` atoms with a ValueError naming the
  O(N)-memory alternatives (Hessian-vector products, the iterative
  :func:`ase_maud.analysis.stationary.classify`).
- Phonopy sees the scene centred in a cubic box with :data:`BOX_MARGIN`
  extents of empty space on each side, with no symmetry and the box as its
  own primitive cell; at Gamma every phase factor is 1, so no periodic image
  enters.
- Fixed points are held, by one rule (:func:`free_indices`, ASE's for
  :class:`~ase.vibrations.VibrationsData`): the modes are those of the free
  points, the Hessian's block of their coordinates (a fixed point is an
  infinite mass). :func:`gamma_modes` gives phonopy the free points only;
  :func:`finite_difference_force_constants` (a check of the analytic
  constants) keeps every point.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from ase import Atoms
from ase.calculators.calculator import Calculator
from ase.constraints import FixCartesian
from ase.vibrations import VibrationsData
from numpy.typing import ArrayLike
from phonopy import Phonopy
from phonopy.structure.atoms import PhonopyAtoms
from scipy.spatial import cKDTree

#: Empty space on each side of the scene in phonopy's box, in extents (the
#: scene's largest width, at least ``a``).
BOX_MARGIN = 4.0


def calculator_3d(calc: Calculator, **changes: Any) -> Calculator:
    """A ``dim=3`` MaudCalculator with the parameters of ``calc``."""
    return type(calc)(**{**calc.parameters, 'dim': 3, **changes})


def force_constants(atoms: Atoms) -> np.ndarray:
    """The analytic force constants of the 3D potential, shape (N, N, 3, 3)."""
    n = len(atoms)
    hessian = calculator_3d(atoms.calc).get_hessian(atoms)
    return hessian.reshape(n, 3, n, 3).transpose(0, 2, 1, 3)


def free_indices(atoms: Atoms) -> np.ndarray:
    """The points the modes move: ASE's rule (any point under FixAtoms or
    FixCartesian is left out, :meth:`VibrationsData.indices_from_constraints`),
    except that the z mask :func:`ase_maud.scenes.builders.keep_on_plane` puts on a
    planar (``dim=2``) scene is not counted: its points keep all three
    coordinates, as the 3D Hessian does."""
    planar = getattr(atoms.calc, 'dim', 3) == 2
    copy = atoms.copy()
    copy.set_constraint([c for c in atoms.constraints if not (
        planar and isinstance(c, FixCartesian)
        and list(c.mask) == [False, False, True])])
    return np.asarray(VibrationsData.indices_from_constraints(copy), dtype=int)


def phonopy_cell(atoms: Atoms, masses: ArrayLike | None = None,
                 points: np.ndarray | None = None) -> PhonopyAtoms:
    """Phonopy's unit cell: the scene's ``points`` (default all) centred in a
    large cubic box.

    Every point is labelled 'H' (phonopy needs an element; ``masses``, default
    1, one per point given, is what counts).
    """
    points = np.arange(len(atoms)) if points is None else points
    positions = atoms.get_positions()[points]
    extent = max(np.ptp(positions, axis=0).max(), atoms.calc.length_scale)
    side = (1 + 2 * BOX_MARGIN) * extent
    centred = positions - positions.mean(axis=0) + side / 2
    masses = np.ones(len(points)) if masses is None else masses
    return PhonopyAtoms(symbols=['H'] * len(points), positions=centred,
                        cell=side * np.eye(3), masses=masses)


def make_phonopy(atoms: Atoms, masses: ArrayLike | None = None,
                 points: np.ndarray | None = None) -> Phonopy:
    """A Phonopy object for the scene's ``points`` (default all), without
    force constants (refused above ``max_hessian_atoms``: phonopy's force
    constants are dense).

    Frequencies come out angular in ``sqrt(Q / mass)`` (unit conversion 1).

    Parameters
    ----------
    atoms : Atoms
        The scene, with a :class:`~ase_maud.MaudCalculator`.
    masses : array-like of shape (n,) or None, default None
        One mass per point of ``points`` (None: 1 each).
    points : ndarray of int or None, default None
        The points phonopy sees (None: all).

    Returns
    -------
    phonopy.Phonopy
        The scene in a cubic box, no symmetry, no force constants yet.

    Raises
    ------
    ValueError
        More atoms than ``MaudCalculator.max_hessian_atoms``.
    """
    atoms.calc.check_hessian_size(len(atoms), 'make_phonopy')
    phonon = Phonopy(phonopy_cell(atoms, masses, points),
                     supercell_matrix=np.eye(3, dtype=int),
                     primitive_matrix='P', is_symmetry=False)
    phonon.unit_conversion_factor = 1.0
    return phonon


def gamma_modes(atoms: Atoms, masses: ArrayLike | None = None,
                ) -> tuple[np.ndarray, np.ndarray, Phonopy]:
    """Phonopy's frequencies and modes from the analytic force constants,
    the fixed points held (:func:`free_indices`: ``n`` free points of N).

    Returns ``(frequencies, modes, phonon)``: frequencies (3n,) ascending,
    signed (see the module docstring); modes (3n, N, 3), real, unit, the
    eigenvectors of the mass-weighted Hessian of the free points (zero on
    the fixed ones); the Phonopy object of the free points, with its force
    constants set, for anything else phonopy offers. ``masses``: one per
    point (N), default 1.

    Parameters
    ----------
    atoms : Atoms
        The scene, with a :class:`~ase_maud.MaudCalculator` and its fixed
        points as constraints.
    masses : array-like of shape (N,) or None, default None
        One mass per point (None: 1 each, so that the squared frequencies
        are the Hessian's eigenvalues in ``Q``).

    Returns
    -------
    frequencies : ndarray of shape (3n,)
        Angular, ascending, in ``sqrt(Q / mass)``; negative for an imaginary
        one (an unstable mode).
    modes : ndarray of shape (3n, N, 3)
        Real unit eigenvectors of the mass-weighted Hessian of the free
        points, zero on the fixed ones.
    phonon : phonopy.Phonopy
        The free points' Phonopy object, its force constants set.

    Raises
    ------
    ValueError
        More atoms than ``MaudCalculator.max_hessian_atoms``, or atoms the
        calculator refuses.
    """
    free = free_indices(atoms)
    masses = None if masses is None else np.asarray(masses, dtype=float)[free]
    phonon = make_phonopy(atoms, masses, free)
    phonon.force_constants = force_constants(atoms)[np.ix_(free, free)]
    qpoints = phonon.run_qpoints([[0, 0, 0]], with_eigenvectors=True)
    frequencies = qpoints.frequencies[0]
    vectors = qpoints.eigenvectors[0].T
    big = vectors[np.arange(len(vectors)), np.abs(vectors).argmax(axis=1)]
    modes = np.zeros((len(vectors), len(atoms), 3))
    modes[:, free] = (vectors * np.conj(big / np.abs(big))[:, None]).real.reshape(
        len(vectors), len(free), 3)
    return frequencies, modes, phonon


def finite_difference_force_constants(atoms: Atoms,
                                      distance: float | None = None) -> np.ndarray:
    """Phonopy's own force constants, from forces of displaced copies.

    Phonopy displaces every point by ``distance`` (default ``1e-4`` times the
    shortest pair distance) along +-x, +-y, +-z; a ``dim=3`` MaudCalculator
    with the exact direct sum (``tol=0``, whatever ``atoms`` uses)
    gives the forces; phonopy fits the force constants (N, N, 3, 3). The
    central differences leave errors of order ``distance**2``.
    """
    atoms.calc.check_hessian_size(len(atoms),
                                  'finite_difference_force_constants')
    if distance is None:
        nearest = cKDTree(atoms.positions).query(atoms.positions, k=2)[0]
        distance = 1e-4 * nearest[:, 1].min()
    phonon = make_phonopy(atoms)
    phonon.generate_displacements(distance=distance, is_plusminus=True)
    probe = atoms.copy()
    probe.calc = calculator_3d(atoms.calc, backend='auto', tol=0.0)
    forces = []
    for cell in phonon.supercells_with_displacements:
        probe.positions = cell.positions  # the box shifts every point alike
        forces.append(probe.get_forces(apply_constraint=False))
    phonon.forces = forces
    phonon.produce_force_constants(show_drift=False)
    return phonon.force_constants


def vibrations(atoms: Atoms, masses: ArrayLike | None = None) -> VibrationsData:
    """The same modes as an ASE :class:`~ase.vibrations.VibrationsData`, the
    fixed points held (:func:`free_indices`). ``masses`` (default 1) are set
    on the copy the object keeps; its energies assume ASE's units (eV,
    Angstrom, amu).

    Parameters
    ----------
    atoms : Atoms
        A scene whose calculator is a :class:`~ase_maud.MaudCalculator`;
        its constraints say which points are fixed.
    masses : array-like or None, default None
        Per point, N of them; None sets 1 on each.

    Returns
    -------
    ase.vibrations.VibrationsData
        The Hessian block of the free points (``Q``), on a copy of the atoms.

    Raises
    ------
    ValueError
        More atoms than ``MaudCalculator.max_hessian_atoms``, or atoms the
        calculator refuses.
    """
    copy = atoms.copy()
    copy.set_masses(np.ones(len(atoms)) if masses is None else masses)
    indices = free_indices(atoms)
    dofs = (3 * indices[:, None] + np.arange(3)).ravel()
    hessian = calculator_3d(atoms.calc).get_hessian(atoms)
    return VibrationsData.from_2d(copy, hessian[np.ix_(dofs, dofs)], indices.tolist())
