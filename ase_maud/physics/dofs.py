"""Which moves a scene has: the degrees of freedom its constraints leave
free, the rigid-body motions among them, orthonormal bases of the allowed
moves and of the rigid motions they allow, and the projection off those.

The one home of constraint geometry: the stiffness models, the step's
strategies and the analysis of stationary points all take it from here.
Coordinates are ordered point by point (x0, y0, z0, x1, ...), ``dim`` of
them per point (2 for a scene on a plane ``z = const``).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg
from ase import Atoms
from ase.constraints import FixAtoms, FixCartesian, FixedLine, FixedPlane


def free_dofs(atoms: Atoms, dim: int) -> np.ndarray:
    """Boolean (N, dim) mask of the degrees of freedom that FixAtoms and
    FixCartesian leave free (other constraints are not coordinate masks and
    are left to ASE)."""
    free = np.ones((len(atoms), 3))
    for constraint in atoms.constraints:
        if isinstance(constraint, (FixAtoms, FixCartesian)):
            constraint.adjust_forces(atoms, free)
    return free[:, :dim] != 0


def held_in_a_plane(atoms: Atoms) -> bool:
    """Whether the points FixAtoms and FixCartesian hold in every coordinate
    are at least three and not all on one line (a net held at its rim, say:
    a plane can be fitted to them)."""
    held = atoms.positions[~free_dofs(atoms, 3).any(axis=1)]
    return len(held) >= 3 and np.linalg.matrix_rank(held - held.mean(axis=0), tol=1e-9) >= 2


def column_null_space(matrix: np.ndarray, rcond: float) -> np.ndarray:
    """Orthonormal columns spanning the null space of ``matrix`` (m, r), its
    singular values below ``rcond`` times the largest taken for zero (as
    :func:`scipy.linalg.null_space`), from the thin SVD: r x r at most where
    SciPy's would form an m x m factor (m is every coordinate of a large
    scene, r at most 6 rigid-body modes)."""
    _, values, vh = np.linalg.svd(matrix, full_matrices=matrix.shape[0] < matrix.shape[1])
    rank = int(np.sum(values > rcond * values.max(initial=0.0)))
    return vh[rank:].T


def rigid_body_modes(positions: np.ndarray, free: np.ndarray, dim: int,
                     rcond: float = 1e-8) -> np.ndarray:
    """Orthonormal rigid-body modes on the free degrees of freedom.

    The translations and rotations about the centroid that leave every fixed
    degree of freedom at rest, restricted to the free ones: an array of
    shape (free.sum(), m), m <= 6 (3D) or 3 (2D). A rotation that moves the
    points less than ``rcond`` times the most moving one does not count: a
    collinear scene (to that precision) loses the rotation about its line.
    """
    x = positions[:, :dim] - positions[:, :dim].mean(axis=0)
    if dim == 3:
        rotations = np.array([np.cross(e, x).ravel() for e in np.eye(3)])
    else:
        rotations = np.column_stack([-x[:, 1], x[:, 0]]).reshape(1, -1)
    sizes = np.linalg.norm(rotations, axis=1)
    rotations = rotations[sizes > rcond * sizes.max()]
    rotations /= max(sizes.max(), np.finfo(float).tiny)
    translations = np.kron(np.ones(len(x)), np.eye(dim)) / np.sqrt(len(x))
    modes = np.vstack([translations, rotations]).T
    flat = free.ravel()
    if (~flat).any():
        modes = modes @ column_null_space(modes[~flat], rcond)
    return scipy.linalg.orth(modes[flat], rcond=rcond)


#: The constraints that project each atom's move onto a line, a plane or
#: nothing: the exact model represents them exactly (:func:`allowed_basis`).
PROJECTIONS = (FixAtoms, FixCartesian, FixedPlane, FixedLine)


def allowed_basis(atoms: Atoms, dim: int) -> np.ndarray:
    """Orthonormal columns (dim N, m) spanning the moves that FixAtoms,
    FixCartesian, FixedPlane and FixedLine allow (each is a projection of
    every atom's move onto a line, a plane or nothing); other constraints
    are left to ASE."""
    projector = np.zeros((len(atoms), 3, 3))  # P_i, column k = P_i e_k
    for k in range(3):
        unit = np.zeros((len(atoms), 3))
        unit[:, k] = 1.0
        for constraint in atoms.constraints:
            if isinstance(constraint, PROJECTIONS):
                constraint.adjust_forces(atoms, unit)
        projector[:, :, k] = unit
    values, vectors = np.linalg.eigh(projector[:, :dim, :dim])
    atom, column = np.nonzero(values > 0.5)   # eigenvalues are 0 or 1
    basis = np.zeros((dim * len(atoms), len(atom)))   # column j: atom[j]'s eigenvector
    rows = dim * atom[:, None] + np.arange(dim)
    basis[rows, np.arange(len(atom))[:, None]] = vectors[atom, :, column]
    return basis


def allowed_rigid_modes(positions: np.ndarray, dim: int,
                        basis: np.ndarray | None) -> np.ndarray:
    """Orthonormal columns (dim N, r) spanning the rigid-body motions
    (:func:`rigid_body_modes`: translations and rotations) that ``basis``
    allows (:func:`allowed_basis`; None: every move): all of them for a free
    scene, none once three non-collinear points are held. The moves of
    ``basis`` orthogonal to them are the internal moves, on which the
    Hessian has no zero modes of symmetry."""
    rigid = rigid_body_modes(positions, np.ones((len(positions), dim), bool), dim)
    if basis is None:
        return rigid
    outside = rigid - basis @ (basis.T @ rigid)
    return rigid @ column_null_space(outside, 1e-8)


def project_off(matrix: np.ndarray, modes: np.ndarray) -> np.ndarray:
    """``P matrix P`` in place, ``P = I - R R^T`` the projector off the
    orthonormal columns ``R`` = ``modes`` (n, r) of a symmetric ``matrix``
    ``M``: ``M - S R^T - R (S - R C)^T`` with ``S = M R``, ``C = R^T S``, one
    rank-2r product, O(n**2 r) and one n x n temporary, where a basis of
    their complement costs products of n**3."""
    side = matrix @ modes
    matrix -= np.hstack([side, modes]) @ np.hstack([modes, side - modes @ (modes.T @ side)]).T
    return matrix


def keep_on_plane(atoms: Atoms) -> Atoms:
    """Hold the z coordinate of every point of ``atoms`` that nothing holds
    yet (``FixCartesian(indices, mask=[False, False, True])``; True is fixed)
    and return ``atoms``.

    A ``MaudCalculator(dim=2)`` needs every point on one plane z = const.
    Maud's own steps never leave it (the z forces are exactly 0), but ASE's
    drivers move z by themselves: BasinHopping's random jumps, MD's thermal
    velocities, NEB's interpolation of images on different planes. With this
    constraint they keep every point's z. Call it again after adding points
    (it adds only what is missing); the existing constraints are kept.
    """
    held = np.zeros(len(atoms), dtype=bool)
    for constraint in atoms.constraints:
        if isinstance(constraint, FixAtoms):
            held[constraint.index] = True
        elif isinstance(constraint, FixCartesian) and constraint.mask[2]:
            held[constraint.index] = True
    if not held.all():
        atoms.set_constraint([*atoms.constraints,
                              FixCartesian(np.flatnonzero(~held),
                                           mask=[False, False, True])])
    return atoms
