"""MaudCalculator: points that all repel, some tied by zero-length springs.

Energy, each pair counted once (the specification's P double-counts: P = 2E)::

    E = sum_{i<j} a**3 Q / L_ij  +  sum_{(i,j) in springs} Q L_ij**2 / 2

``a`` is a length and ``Q`` a force per length, in whatever units the user
works in (ASE's eV and Angstrom if the scene is mixed with other ASE tools).
Forces follow ASE's sign, ``f = -dE/dr``. The property ``stiffness`` holds the
nodal blocks ``K_mm = d2E/dr_m2`` (N, dim, dim), the Hessian's diagonal blocks:
the stiffness at point m with every other point held fixed.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from numbers import Integral, Real
from typing import Any

import numpy as np
import scipy.sparse as sp
from ase import Atoms
from ase.calculators.calculator import Calculator, all_changes
from numpy.typing import ArrayLike

from . import backends, physics, topology
from .hessian import dense_hessian
from .springs import check_range, check_springs

#: Relative tolerance on the spread of z for a ``dim=2`` scene.
PLANE_TOLERANCE = 1e-10


class MaudCalculator(Calculator):
    """ASE calculator for the Maud potential.

    Parameters
    ----------
    springs : array-like of shape (K, 2)
        Atom index pairs tied by a spring. Each pair at most once (in either
        order); a duplicate, a self-spring or an index out of range is a
        ``ValueError`` that names the spring.
    a : float
        Length in the repulsion ``a**3 Q / L`` (default 1).
    Q : float
        Spring constant, force per length (default 1).
    dim : 2 or 3
        ``2``: every point lies on one plane ``z = const`` (checked to a
        relative :data:`PLANE_TOLERANCE`), forces have ``z = 0`` exactly and
        the blocks are 2x2. ``3`` (default): 3x3 blocks.
    backend : str
        The repulsion kernel, a name in the registry :mod:`.backends`: the
        direct sums ``numba`` (default, compiled, parallel over
        ``NUMBA_NUM_THREADS``) and ``numpy`` (the slow reference), or
        ``fmm``, FMM3D's fast multipole method (O(N), faster from a few
        thousand points, approximate to ``fmm_eps``; needs
        ``pip install 'ase-maud[fmm]'``, parallel over ``OMP_NUM_THREADS``).
    fmm_eps : float in (0, 1)
        Requested relative precision of the multipole sums of the ``fmm``
        backend (default 1e-6); ignored by the direct sums. Forces cannot be
        relaxed much below ``fmm_eps`` times the typical repulsive force.

    Notes
    -----
    Only what is asked is computed: ``energy``/``forces`` never build the
    blocks; asking for ``stiffness`` computes all three in one pass; asking
    for ``hessian`` (the dense (dim N, dim N) matrix, small scenes only) adds
    it to the energy and forces of the same call.
    """

    implemented_properties = ['energy', 'free_energy', 'forces', 'stiffness',
                              'hessian']
    # springs default to a tuple: Calculator.todict compares each parameter
    # with its default by ``!=``, which fails on an ndarray default.
    default_parameters = {'springs': (), 'a': 1.0, 'Q': 1.0, 'dim': 3,
                          'backend': 'numba', 'fmm_eps': 1e-6}
    discard_results_on_any_change = True
    nolabel = True

    #: Largest number of atoms for which :meth:`get_hessian` builds the dense
    #: (dim N)**2 matrix: 3000 atoms in 3D is an 81e6-entry, 648 MB array.
    max_hessian_atoms = 3000

    def __init__(self, springs: ArrayLike = (), a: float = 1.0,
                 Q: float = 1.0, dim: int = 3, backend: str = 'numba',
                 fmm_eps: float = 1e-6, **kwargs: Any) -> None:
        self._spring_hessian: tuple[tuple, sp.csr_matrix] | None = None
        super().__init__(springs=springs, a=a, Q=Q, dim=dim, backend=backend,
                         fmm_eps=fmm_eps, **kwargs)

    def set(self, **kwargs: Any) -> dict[str, Any]:
        """Set parameters; invalid values raise ValueError and are not kept."""
        if 'springs' in kwargs:
            kwargs['springs'] = check_springs(kwargs['springs'])
        _check_parameters({**self.parameters, **kwargs})
        return super().set(**kwargs)

    @property
    def springs(self) -> np.ndarray:
        """The (K, 2) int array of sprung pairs."""
        return self.parameters['springs']

    @property
    def dim(self) -> int:
        """2 (points on a plane z = const, 2x2 blocks) or 3."""
        return self.parameters['dim']

    @property
    def length_scale(self) -> float:
        """The length ``a`` of the repulsion ``a**3 Q / L`` (a dimer with
        one spring rests at ``L = a``)."""
        return self.parameters['a']

    def check_state(self, atoms: Atoms, tol: float = 1e-15) -> list[str]:
        """What changed since the last calculation, compared exactly.

        ASE's default compares positions within an absolute ``tol``, which
        misses every move of a scene whose ``a`` is below about 1e-10 and
        costs several ``isclose`` calls per property request; the potential
        depends only on the positions (and the number of points), so those,
        the cell and pbc are compared exactly, whatever the scale.
        """
        old = self.atoms
        if old is None or len(old) != len(atoms):
            return list(all_changes)
        changes = []
        if not np.array_equal(old.positions, atoms.positions):
            changes.append('positions')
        if not np.array_equal(old.numbers, atoms.numbers):
            changes.append('numbers')
        if not np.array_equal(old.cell.array, atoms.cell.array):
            changes.append('cell')
        if not np.array_equal(old.pbc, atoms.pbc):
            changes.append('pbc')
        return changes

    def check_atoms(self, atoms: Atoms) -> np.ndarray:
        """Validate ``atoms`` for this potential; return its positions.

        Raises ValueError naming the problem: periodic boundaries, a spring
        index beyond the last atom, a non-finite position, or (``dim=2``) a
        point off the plane of the others.
        """
        if np.any(atoms.pbc):
            raise ValueError(f'periodic boundaries are not supported (pbc='
                             f'{atoms.pbc.tolist()}): 1/L needs an Ewald sum;'
                             ' set atoms.pbc = False')
        natoms = len(atoms)
        check_range(self.springs, natoms)   # the rest was checked by set
        positions = atoms.get_positions()
        bad = np.flatnonzero(~np.isfinite(positions).all(axis=1))
        if bad.size:
            raise ValueError(f'atom {bad[0]} has a non-finite position '
                             f'{positions[bad[0]].tolist()}')
        if self.parameters['dim'] == 2 and natoms > 1:
            z = positions[:, 2]
            extent = max(np.ptp(positions[:, :2]), self.parameters['a'])
            off = np.abs(z - z[0])
            if off.max() > PLANE_TOLERANCE * extent:
                k = int(np.argmax(off))
                raise ValueError(f'dim=2 needs every point on one plane z = '
                                 f'const: atom {k} has z = {z[k]}, atom 0 '
                                 f'has z = {z[0]}')
        return positions

    def calculate(self, atoms: Atoms | None = None,
                  properties: Sequence[str] = ('energy',),
                  system_changes: Sequence[str] = all_changes) -> None:
        super().calculate(atoms, properties, system_changes)
        positions = self.check_atoms(self.atoms)
        p = self.parameters
        dim, c = p['dim'], p['a']**3 * p['Q']
        want_blocks = 'stiffness' in properties
        flat = positions.copy()
        if dim == 2:
            flat[:, 2] = 0.0
        backend = backends.get(p['backend'])
        e_rep, f_rep, block6 = backend.evaluate(flat, want_blocks,
                                                **backend.options(p))
        if not np.isfinite(e_rep):
            raise_on_coincident(flat)
        e_spr, f_spr = physics.spring_terms(flat, self.springs, p['Q'])
        energy = c * e_rep + e_spr
        forces = c * f_rep + f_spr
        if dim == 2:
            forces[:, 2] = 0.0
        self.results['energy'] = self.results['free_energy'] = energy
        self.results['forces'] = forces
        if want_blocks:
            blocks = c * backends.voigt_to_blocks(block6, dim)
            blocks += physics.spring_nodal_blocks(self.springs, len(flat),
                                                  p['Q'], dim)
            self.results['stiffness'] = blocks
        if 'hessian' in properties:
            self._check_hessian_size(len(flat))
            self.results['hessian'] = dense_hessian(
                flat, self.springs, p['a'], p['Q'], dim,
                spring_part=self.get_spring_hessian(self.atoms))

    def get_stiffness(self, atoms: Atoms | None = None) -> np.ndarray:
        """Nodal blocks ``K_mm``, shape (N, dim, dim), units of ``Q``."""
        return self.get_property('stiffness', atoms)

    def get_hessian(self, atoms: Atoms | None = None) -> np.ndarray:
        """The full analytic Hessian ``d2E/dr dr``, shape (dim N, dim N).

        For analysis of small scenes only; refuses more than
        :attr:`max_hessian_atoms` atoms with a ValueError.
        """
        if atoms is not None:
            self._check_hessian_size(len(atoms))
        return self.get_property('hessian', atoms)

    def _check_hessian_size(self, natoms: int) -> None:
        if natoms > self.max_hessian_atoms:
            raise ValueError(
                f'get_hessian: {natoms} atoms exceed max_hessian_atoms = '
                f'{self.max_hessian_atoms} (the dense matrix would hold '
                f'{(self.parameters["dim"] * natoms)**2:.2e} entries); use'
                ' Hessian-vector products (ase_maud.hessian) instead')

    def get_spring_hessian(self, atoms: Atoms | None = None) -> sp.csr_matrix:
        """The springs' exact, constant Hessian ``Q (L (x) I_dim)``, shape
        (dim N, dim N) (:func:`.physics.spring_hessian`).

        It depends on the springs, the number of atoms, ``Q`` and ``dim``
        only, not on the positions: it is built once and kept until one of
        them changes. A spring index beyond the last atom is a ValueError.
        """
        atoms = atoms if atoms is not None else self.atoms
        natoms = len(atoms)
        check_range(self.springs, natoms)
        p = self.parameters
        key = (self.springs.tobytes(), self.springs.shape, natoms, p['Q'],
               p['dim'])
        if self._spring_hessian is None or self._spring_hessian[0] != key:
            matrix = physics.spring_hessian(self.springs, natoms, p['Q'],
                                            p['dim'])
            self._spring_hessian = key, matrix
        return self._spring_hessian[1]

    def unbounded_components(self, atoms: Atoms) -> list[list[int]]:
        """Spring components of ``atoms`` proved to fly away for ever
        (:func:`.topology.unbounded_components`); empty if there are none."""
        return topology.unbounded_components(atoms, self.springs, self.dim)


def _check_parameters(p: Mapping[str, Any]) -> None:
    """Raise ValueError unless a, Q, dim, the backend and the backends'
    parameters (:func:`.backends.check_parameters`) in ``p`` are valid."""
    for name in ('a', 'Q'):
        value = p[name]
        if not (isinstance(value, Real) and np.isfinite(value)
                and value > 0):
            raise ValueError(f'{name} must be a positive finite number, '
                             f'got {value!r}')
    if not (isinstance(p['dim'], Integral) and p['dim'] in (2, 3)):
        raise ValueError(f"dim must be 2 or 3, got {p['dim']!r}")
    backends.check_parameters(p)


def raise_on_coincident(positions: np.ndarray) -> None:
    """Raise ValueError naming two points at the same position."""
    order = np.lexsort(positions.T[::-1])
    same = np.all(positions[order[1:]] == positions[order[:-1]], axis=1)
    if np.any(same):
        k = int(np.argmax(same))
        i, j = sorted((int(order[k]), int(order[k + 1])))
        raise ValueError(f'atoms {i} and {j} are at the same position '
                         f'{positions[i].tolist()}: the repulsion a^3 Q / L '
                         'is infinite there')
    raise FloatingPointError('the repulsion overflowed: points closer than '
                             'the float64 range allows')
