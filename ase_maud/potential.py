"""The Maud potential as one value: its springs and constants, its units, its
exact spring Hessian and its whole Hessian.

:class:`MaudPotential` is what every consumer of the potential takes (the
calculator, the Hessian and its products, analysis, modes, the stiffness
models) instead of reading a calculator's parameters. The pair law itself is
:mod:`ase_maud.physics`; the sum of the repulsion over every pair is a
backend's (:mod:`ase_maud.backends`).

Reduced units. Everything is computed for the scene measured in ``a``
(``x' = x / a``) at ``a = Q = 1`` and scaled back: ``E = a**2 Q e(x')``,
``F = a Q f(x')``, stiffness and Hessian ``Q k(x')``, so no power of ``a`` is
formed and every result is finite wherever it is representable.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike

from . import backends, physics
from .checks import check
from .springs import check_range, check_springs


@dataclass(frozen=True, eq=False)
class MaudPotential:
    """``E = sum_{i<j} a**3 Q / L_ij + sum_{(i,j) in springs} Q L_ij**2 / 2``.

    ``springs``: (K, 2) atom index pairs (checked: :func:`.springs.check_springs`);
    ``a``: a length; ``Q``: a force per length; ``dim``: 2 (points on a plane
    ``z = const``, 2x2 blocks) or 3. Energies count each pair once; forces
    have ASE's sign, ``f = -dE/dr``. Frozen: a change is a new potential (the
    spring Hessian it caches stays valid).
    """

    springs: np.ndarray
    a: float = 1.0
    Q: float = 1.0
    dim: int = 3
    _cache: dict = field(default_factory=dict, init=False, repr=False)

    def __post_init__(self) -> None:
        springs = check_springs(self.springs)
        springs.flags.writeable = False
        object.__setattr__(self, 'springs', springs)
        for name in ('a', 'Q', 'dim'):
            object.__setattr__(self, name, check(name, getattr(self, name)))

    # -- units --------------------------------------------------------------

    @property
    def energy_unit(self) -> float:
        """``a**2 Q``: the energy of the reduced potential's unit."""
        return self.a * self.a * self.Q

    @property
    def force_unit(self) -> float:
        """``a Q``."""
        return self.a * self.Q

    def reduced(self, positions: ArrayLike) -> np.ndarray:
        """The positions (N, 3), or (N, dim), in units of ``a``: ``x / a``
        (N, 3), with ``z = 0`` for ``dim=2``; a ValueError names an atom whose
        ``x / a`` overflows."""
        given = np.asarray(positions, dtype=float)
        positions = np.zeros((len(given), 3))
        positions[:, :given.shape[1]] = given
        with np.errstate(over='ignore'):
            scaled = positions / self.a
        bad = np.flatnonzero(~np.isfinite(scaled).all(axis=1))
        if bad.size:
            raise ValueError(f'atom {bad[0]} at {positions[bad[0]].tolist()} is '
                             f'beyond the float64 range in units of a = {self.a!r}; '
                             'choose a nearer the size of the scene')
        if self.dim == 2:
            scaled[:, 2] = 0.0
        return scaled

    # -- the springs: exact, constant ----------------------------------------

    def spring_laplacian(self, natoms: int) -> sp.csr_matrix:
        """The spring graph's Laplacian ``D - A`` (natoms, natoms), kept."""
        return self._kept(('laplacian', natoms), lambda: physics.spring_laplacian(
            self._springs_within(natoms), natoms))

    def spring_hessian(self, natoms: int) -> sp.csr_matrix:
        """The springs' exact, constant Hessian ``Q (L (x) I_dim)``, shape
        (dim N, dim N), coordinates point by point; built once per N."""
        return self._kept(('hessian', natoms), lambda: physics.spring_hessian(
            self._springs_within(natoms), natoms, self.Q, self.dim))

    def spring_energy_forces(self, positions: np.ndarray) -> tuple[float, np.ndarray]:
        """The springs' energy and forces (N, 3) at ``positions`` (length units)."""
        check_range(self.springs, len(positions))
        energy, forces = physics.spring_terms(self.reduced(positions), self.springs, 1.0)
        return self.energy_unit * energy, self.force_unit * forces

    def _springs_within(self, natoms: int) -> np.ndarray:
        check_range(self.springs, natoms)
        return self.springs

    def _kept(self, key: tuple, build):
        if key not in self._cache:
            self._cache[key] = build()
        return self._cache[key]

    # -- the whole Hessian --------------------------------------------------

    def hessian(self, positions: np.ndarray) -> np.ndarray:
        """The dense Hessian ``d2E/dr dr``, shape (dim N, dim N), units of
        ``Q``: ``-B_ij`` off the diagonal, the nodal block ``K_ii = sum_j
        B_ij`` on it (:mod:`.physics`); the repulsion's part by the
        registry's Hessian backend (:func:`.backends.repulsion_hessian`)."""
        n = len(positions)
        hess = self.Q * backends.repulsion_hessian(self.reduced(positions), self.dim)
        rows, cols, values = self._kept(('entries', n), lambda: physics.spring_hessian_entries(
            self._springs_within(n), n, self.Q, self.dim))
        np.add.at(hess, (rows, cols), values)
        return hess

    def hvp(self, positions: np.ndarray, v: ArrayLike) -> np.ndarray:
        """``H v`` without forming ``H``: ``(H v)_i = sum_j B_ij (v_i - v_j)``.

        ``v`` has shape (N, dim) (a displacement of every point) or
        (m, N, dim) (m of them, one pass over the pairs); the result has its
        shape, in units of ``Q`` times ``v``. O(N) memory per vector; the
        repulsion's part by the registry's Hessian-vector backend
        (:func:`.backends.repulsion_hvp`).
        """
        n, dim = len(positions), self.dim
        v = np.asarray(v, dtype=float)
        block = v.reshape(-1, n, dim)
        u = np.zeros((len(block), n, 3))
        u[:, :, :dim] = block
        hv = self.Q * backends.repulsion_hvp(self.reduced(positions), u)[:, :, :dim]
        hv += (self.spring_hessian(n) @ block.reshape(len(block), -1).T
               ).T.reshape(hv.shape)
        return hv.reshape(v.shape)
