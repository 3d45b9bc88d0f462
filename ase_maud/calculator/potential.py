"""The Maud potential as one value: its springs and constants, its force
densities and loads, its units, its exact spring Hessian and its whole Hessian.

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

from contextlib import nullcontext
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from ase import Atoms
from numpy.typing import ArrayLike

from ase_maud import backends
from ase_maud.backends import direct
from ase_maud.calculator.compiled_sums import SceneArrays, flat_entries, spring_sums
from ase_maud.checks import check, check_each, check_indices
from ase_maud.physics import pair_law as physics
from ase_maud.physics import topology
from ase_maud.physics.spring_list import check_range, check_springs

#: Relative tolerance on the spread of z for a ``dim=2`` scene.
PLANE_TOLERANCE = 1e-10


@dataclass(frozen=True, eq=False)
class MaudPotential:
    """``E = sum_{i<j} a**3 Q / L_ij + sum_{s=(i,j) in springs} Q q_s L_ij**2 / 2
    - sum_i F_i . r_i``.

    ``springs``: (K, 2) atom index pairs (checked: :func:`.springs.check_springs`);
    ``a``: a length; ``Q``: a force per length; ``dim``: 2 (points on a plane
    ``z = const``, 2x2 blocks) or 3; ``q``: each spring's force density
    multiplier of ``Q``, (K,) nonzero, negative for a member in compression
    (:attr:`compressed`; None: every ``q_s = 1``); ``loads``:
    constant nodal loads ``F``, (N, 3) or, for ``dim=2``, (N, 2), force units
    (None: none; in 2D their z must be 0). Loads change the energy and
    forces, never a Hessian. ``a = 0`` switches the repulsion off: springs
    and loads alone, the force-density method (:attr:`repulsive`). Energies
    count each pair once; forces have ASE's sign, ``f = -dE/dr``. Frozen: a
    change is a new potential (the spring Hessian it caches stays valid).

    Parameters
    ----------
    springs : array-like of shape (K, 2)
        Atom index pairs tied by a spring, each pair once.
    a : float, default 1.0
        The repulsion's length (>= 0; 0: no repulsion).
    Q : float, default 1.0
        The spring constant, force per length (> 0).
    dim : {2, 3}, default 3
        The dimension of the scene.
    q : array-like of shape (K,) or None, default None
        Each spring's force density multiplier of ``Q`` (positive).
    loads : array-like of shape (N, dim) or (N, 3), or None, default None
        Constant nodal loads ``F`` in ``Q a``.

    Raises
    ------
    ValueError
        A spring list that is not index pairs, a duplicate or self-spring
        (named); ``a``, ``Q``, ``dim`` or ``q`` outside their rules; ``q``
        not one value per spring; loads of another shape or, for ``dim=2``,
        with a z component.
    """

    springs: np.ndarray
    a: float = 1.0
    Q: float = 1.0
    dim: int = 3
    q: np.ndarray | None = None
    loads: np.ndarray | None = None
    _cache: dict = field(default_factory=dict, init=False, repr=False)

    def __post_init__(self) -> None:
        springs = check_springs(self.springs)
        springs.flags.writeable = False
        object.__setattr__(self, 'springs', springs)
        for name in ('a', 'Q', 'dim'):
            object.__setattr__(self, name, check(name, getattr(self, name)))
        for name, value in (('q', self._checked_q()), ('loads', self._checked_loads())):
            if value is not None:
                value.flags.writeable = False
            object.__setattr__(self, name, value)

    def _checked_q(self) -> np.ndarray | None:
        if self.q is None:
            return None
        q = check_each('q', self.q, 'spring')
        if q.shape != (len(self.springs),):
            raise ValueError(f'q must hold one value per spring, shape '
                             f'({len(self.springs)},), got shape {q.shape}')
        return q

    def _checked_loads(self) -> np.ndarray | None:
        if self.loads is None:
            return None
        given = check_each('loads', self.loads, 'atom')
        if given.ndim != 2 or given.shape[1] not in (self.dim, 3):
            shapes = '(N, 3) or (N, 2)' if self.dim == 2 else '(N, 3)'
            raise ValueError(f'loads must have shape {shapes} (one force per atom), '
                             f'got shape {given.shape}')
        loads = np.zeros((len(given), 3))
        loads[:, :given.shape[1]] = given
        if self.dim == 2 and loads[:, 2].any():
            k = int(np.flatnonzero(loads[:, 2])[0])
            raise ValueError(f'loads of atom {k} has z = {float(loads[k, 2])!r}: a dim=2 '
                             'scene takes loads in its plane (z = 0)')
        return loads

    @property
    def repulsive(self) -> bool:
        """Whether the points repel: ``a > 0``. At ``a = 0`` nothing is
        computed in reduced units (there are none) and no backend is called."""
        return self.a > 0

    @property
    def compressed(self) -> np.ndarray:
        """The indices of the springs with ``q_s < 0`` (members in compression,
        compas_fd's negative force densities). Where there are any, the energy
        is no longer convex in the springs: its equilibria are stationary
        points (an arch's is a maximum at ``a = 0``), not minima."""
        if self.q is None:
            return np.zeros(0, dtype=int)
        return np.flatnonzero(self.q < 0)

    @property
    def stiffnesses(self) -> float | np.ndarray:
        """Each spring's constant ``Q q_s`` in units of ``Q``: ``q``, or 1
        (a number) if no ``q`` was given."""
        return 1.0 if self.q is None else self.q

    def check_loads(self, natoms: int) -> None:
        """Raise ValueError if the loads are not one per atom of ``natoms``."""
        if self.loads is not None and len(self.loads) != natoms:
            raise ValueError(f'loads has {len(self.loads)} rows, one per atom, but '
                             f'the atoms are {natoms}')

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
        # x / a overflows only for a < 1 (numpy's error state costs more than x / a at small N)
        with np.errstate(over='ignore') if self.a < 1.0 else nullcontext():
            if given.ndim == 2 and given.shape[1] == 3:
                scaled = given / self.a
            else:
                scaled = np.zeros((len(given), 3))
                np.divide(given, self.a, out=scaled[:, :given.shape[1]])
        if not np.isfinite(scaled).all():
            bad = np.flatnonzero(~np.isfinite(scaled).all(axis=1))[0]
            raise ValueError(f'atom {bad} at {given[bad].tolist()} is beyond the '
                             f'float64 range in units of a = {self.a!r}; choose a '
                             'nearer the size of the scene')
        if self.dim == 2:
            scaled[:, 2] = 0.0
        return scaled

    def checked_positions(self, atoms: Atoms) -> np.ndarray:
        """``atoms``' positions, validated for this potential.

        Raises ValueError naming the problem: no atoms, periodic boundaries, a spring
        index beyond the last atom, loads not one per atom, a non-finite
        position, or (``dim=2``) a point off the plane of the others.
        """
        if atoms.pbc.any():
            raise ValueError(f'periodic boundaries are not supported (pbc='
                             f'{atoms.pbc.tolist()}): 1/L needs an Ewald sum;'
                             ' set atoms.pbc = False')
        natoms = len(atoms)
        if natoms == 0:
            raise ValueError('no atoms: a scene needs at least one point')
        self.check_size(natoms)   # the rest was checked when made
        positions = atoms.get_positions()
        if not np.isfinite(positions).all():
            bad = np.flatnonzero(~np.isfinite(positions).all(axis=1))[0]
            raise ValueError(f'atom {bad} has a non-finite position '
                             f'{positions[bad].tolist()}')
        if self.dim == 2 and natoms > 1:
            z = positions[:, 2]
            extent = max(np.ptp(positions[:, :2]), self.a)
            off = np.abs(z - z[0])
            if off.max() > PLANE_TOLERANCE * extent:
                k = int(np.argmax(off))
                raise ValueError(f'dim=2 needs every point on one plane z = '
                                 f'const: atom {k} has z = {z[k]}, atom 0 '
                                 f'has z = {z[0]} (ASE drivers move z: hold it '
                                 'with ase_maud.scenes.builders.keep_on_plane(atoms))')
        return positions

    def check_size(self, natoms: int) -> None:
        """Raise ValueError if a spring names an atom beyond ``natoms`` or
        the loads are not one per atom (:func:`.springs.check_range`,
        :meth:`check_loads`)."""
        self._springs_within(natoms)
        self.check_loads(natoms)

    # -- the springs: exact, constant ----------------------------------------

    def spring_laplacian(self, natoms: int) -> sp.csr_matrix:
        """The spring graph's Laplacian weighted by ``q``, ``sum_s q_s (e_i -
        e_j)(e_i - e_j)^T`` (``D - A`` if every ``q_s = 1``), (natoms,
        natoms), kept; the springs' Hessian is ``Q`` times it, times ``I_dim``.

        Parameters
        ----------
        natoms : int
            The number of points.

        Returns
        -------
        scipy.sparse.csr_matrix of shape (natoms, natoms)
            The weighted Laplacian (dimensionless: ``q`` weights).

        Raises
        ------
        ValueError
            A spring names a point beyond ``natoms - 1``.
        """
        return self._kept(('laplacian', natoms), lambda: physics.spring_laplacian(
            self._springs_within(natoms), natoms, self.stiffnesses))

    def spring_terms(self, scaled: np.ndarray) -> tuple[float, np.ndarray]:
        """Energy and forces (N, 3) of the springs at ``scaled`` positions
        (units of ``a``), at ``a = Q = 1``: :func:`.physics.spring_terms`'s
        law, ``Q q L**2 / 2`` and ``-Q q d``, summed spring by spring in one
        compiled pass (:func:`.compiled_sums.spring_sums`)."""
        return spring_sums(np.ascontiguousarray(scaled, dtype=float),
                           *self._spring_arrays(len(scaled)))

    def _spring_arrays(self, natoms: int) -> tuple[np.ndarray, np.ndarray]:
        """The springs (K, 2) int64 and their ``q`` (K,) as the compiled sums
        take them, kept per N."""
        return self._kept(('spring sums', natoms), lambda: (
            np.ascontiguousarray(self._springs_within(natoms), dtype=np.int64),
            np.broadcast_to(np.asarray(self.stiffnesses, float), len(self.springs)).copy()))

    def scene_arrays(self, natoms: int) -> SceneArrays:
        """What :func:`.compiled_sums.scene_terms` takes for a scene of ``natoms`` points
        (kept per N): the law's arrays, as the calculator's own sums use them."""
        springs, q = self._spring_arrays(natoms)
        self.check_loads(natoms)
        loads = np.zeros((natoms, 3)) if self.loads is None else self.loads
        return SceneArrays(springs, q, loads, *self._entries(natoms), float(self.a),
                           float(self.Q), self.dim)

    def spring_hessian(self, natoms: int) -> sp.csr_matrix:
        """The springs' exact, constant Hessian ``Q (L_q (x) I_dim)``
        (:meth:`spring_laplacian`), shape (dim N, dim N), coordinates point
        by point; built once per N."""
        return self._kept(('hessian', natoms), lambda: physics.spring_hessian(
            self._springs_within(natoms), natoms, self.Q * self.stiffnesses, self.dim))

    def spring_components(self, natoms: int) -> np.ndarray:
        """The spring graph's component of every atom, (N,) labels
        (:func:`.topology.spring_components`); found once per N."""
        return self._kept(('components', natoms), lambda: topology.spring_components(
            natoms, self._springs_within(natoms)))

    def _springs_within(self, natoms: int) -> np.ndarray:
        """The springs, once :func:`.springs.check_range` has found none
        beyond ``natoms`` atoms (looked for only if the highest index,
        kept, is not below ``natoms``)."""
        if natoms <= self._kept('highest index', lambda: int(self.springs.max(initial=-1))):
            check_range(self.springs, natoms)
        return self.springs

    def _kept(self, key: tuple | str, build):
        if key not in self._cache:
            self._cache[key] = build()
        return self._cache[key]

    # -- the whole Hessian --------------------------------------------------

    def hessian(self, positions: np.ndarray, backend: str = 'auto') -> np.ndarray:
        """The dense Hessian ``d2E/dr dr``, shape (dim N, dim N), units of
        ``Q``: ``-B_ij`` off the diagonal, the nodal block ``K_ii = sum_j
        B_ij`` on it (:mod:`.physics`); the repulsion's part by ``backend``
        (:func:`.backends.exact_choice`).

        Parameters
        ----------
        positions : ndarray of shape (N, 3) or (N, dim)
            The points, in the unit of ``a``.
        backend : str, default 'auto'
            The repulsion's exact backend (``'auto'``, ``'numba'``, ``'numpy'``).

        Returns
        -------
        ndarray of shape (dim N, dim N)
            The Hessian in ``Q``.

        Raises
        ------
        ValueError
            A point whose ``x / a`` overflows, or an unknown backend.
        """
        n = self.dim * len(positions)
        unit = (backends.exact_choice(backend).backend.hessian(self.reduced(positions),
                                                               self.dim)[2]
                if self.repulsive else np.zeros((n, n)))   # a = 0: the springs alone
        return self.whole_hessian(unit)

    def hessian_block(self, positions: np.ndarray, index: np.ndarray) -> np.ndarray:
        """The rows and columns of :meth:`hessian` on the coordinates of the
        points ``index`` (n,), shape (dim n, dim n), units of ``Q``, without
        the whole: the repulsion's part in O(n N), compiled
        (:func:`.direct.repulsion_hessian_block`: :func:`.physics.repulsion_hessian_block`
        to round-off), the springs' from their entries (the last block kept: a
        run asks for the same points at every step). A ValueError names a bad
        index, the closest pair of points, or an overflow."""
        index = check_indices(index, len(positions))
        block = self._spring_block(len(positions), index).copy()
        if self.repulsive:
            block += self.Q * direct.repulsion_hessian_block(
                self.reduced(positions), index, self.dim)
        if not np.isfinite(block).all():
            if self.repulsive:
                physics.raise_on_closest(self.reduced(positions), self.a)
            raise ValueError(f'the Hessian overflows float64 at Q = {self.Q!r}: '
                             'choose units nearer the scene')
        return block

    def _spring_block(self, natoms: int, index: np.ndarray) -> np.ndarray:
        """The springs' dense Hessian on the points ``index`` (dim n, dim n), the last kept."""
        key = (natoms, index.tobytes())
        if (kept := self._cache.get('spring block')) is None or kept[0] != key:   # no sparse slice
            coords = (self.dim * index[:, None] + np.arange(self.dim)).ravel()
            kept = key, physics.entries_block(*self._entries(natoms), self.dim * natoms, coords)
            self._cache['spring block'] = kept
        return kept[1]

    def _entries(self, n: int) -> tuple[np.ndarray, np.ndarray]:   # the springs' Hessian's, per N
        def entries():
            springs, q = self._spring_arrays(n)
            return flat_entries(springs, self.Q * q, self.dim, n)
        return self._kept(('hessian entries', n), entries)

    def whole_hessian(self, repulsion: np.ndarray) -> np.ndarray:
        """The dense Hessian from the unit repulsion's (dim N, dim N): ``Q``
        times it, plus the springs' (whose entries are kept in a flat index
        once per N, not converted at every call); ``repulsion`` is overwritten."""
        flat, data = self._entries(len(repulsion) // self.dim)
        repulsion *= self.Q
        repulsion.ravel()[flat] += data
        return repulsion

    def hvp(self, positions: np.ndarray, v: ArrayLike) -> np.ndarray:
        """``H v`` without forming ``H``: ``(H v)_i = sum_j B_ij (v_i - v_j)``.

        ``v`` has shape (N, dim) (a displacement of every point) or
        (m, N, dim) (m of them, one pass over the pairs); the result has its
        shape, in units of ``Q`` times ``v``. O(N) memory per vector; the
        repulsion's part by the registry's Hessian-vector backend
        (:func:`.backends.repulsion_hvp`).

        Parameters
        ----------
        positions : ndarray of shape (N, 3) or (N, dim)
            The points, in the unit of ``a``.
        v : array-like of shape (N, dim) or (m, N, dim)
            One displacement of every point, or m of them.

        Returns
        -------
        ndarray of the shape of ``v``
            ``H v`` in ``Q`` times the unit of ``v`` (the change of
            ``-f`` per unit move along ``v``).

        Raises
        ------
        ValueError
            ``v`` of another shape, or a point whose ``x / a`` overflows.
        """
        n, dim = len(positions), self.dim
        v = np.asarray(v, dtype=float)
        block = v.reshape(-1, n, dim)
        u = np.zeros((len(block), n, 3))
        u[:, :, :dim] = block
        hv = (self.Q * backends.repulsion_hvp(self.reduced(positions), u)[:, :, :dim]
              if self.repulsive else np.zeros(block.shape))
        hv += (self.spring_hessian(n) @ block.reshape(len(block), -1).T
               ).T.reshape(hv.shape)
        return hv.reshape(v.shape)

    def unbounded_components(self, atoms: Atoms) -> list[list[int]]:
        """Spring components of ``atoms`` proved to fly away for ever
        (:func:`.topology.unbounded_components`); empty if there are none."""
        return topology.unbounded_components(
            atoms, self.spring_components(len(atoms)), self.dim)

    def minimum_proved(self, atoms: Atoms) -> bool:
        """True if ``atoms`` are proved to have a finite minimum, however far
        out (:func:`.topology.minimum_proved`): then a run that spreads far is
        on its way there, not diverging.

        Parameters
        ----------
        atoms : Atoms
            The scene, with its constraints.

        Returns
        -------
        bool
            True if every constraint is a ``FixAtoms`` or ``FixCartesian`` and
            every spring component is held along each direction (or there is
            one component whose loads sum to zero there); False if nothing
            is proved.

        Raises
        ------
        ValueError
            A spring names an atom beyond the last one.
        """
        return topology.minimum_proved(atoms, self.spring_components(len(atoms)),
                                       self.loads, self.dim)

    def no_equilibrium(self, atoms: Atoms, minimum: bool = True) -> str | None:
        """Why ``atoms`` can have no finite equilibrium, in words, or None if
        nothing is proved: loads with a net sum along a direction nothing
        holds (:func:`.topology.net_load`: no stationary point at all), or,
        for a ``minimum``, spring components that fly away
        (:meth:`unbounded_components`).

        Parameters
        ----------
        atoms : Atoms
            The scene, with its constraints.
        minimum : bool, default True
            Also report spring components that fly away (a minimum is
            sought); False: only a net load (no stationary point at all).

        Returns
        -------
        str or None
            One sentence saying what is wrong and what to fix (the message
            of :class:`~ase_maud.NoEquilibriumError`), or None.

        Raises
        ------
        ValueError
            A spring names an atom beyond the last one.
        """
        total = topology.net_load(atoms, self.loads, self.dim)
        if total is not None:
            return topology.describe_net_load(total)
        components = self.unbounded_components(atoms) if minimum else []
        return topology.describe_unbounded(components) if components else None
