"""MaudCalculator: points that all repel, some tied by zero-length springs.

Energy, each pair counted once (the specification's P double-counts: P = 2E)::

    E = sum_{i<j} a**3 Q / L_ij  +  sum_{s=(i,j) in springs} Q q_s L_ij**2 / 2
        - sum_i F_i . r_i

with ``q_s`` each spring's force density multiplier (default 1) and ``F_i``
constant nodal loads (default none).

``a`` is a length and ``Q`` a force per length, in the user's units. Forces
follow ASE's sign, ``f = -dE/dr``. The property ``stiffness`` holds the nodal
blocks ``K_mm = d2E/dr_m2`` (N, dim, dim), the Hessian's diagonal blocks.

The potential itself, its reduced units (everything is computed at ``a = Q
= 1`` for the scene measured in ``a`` and scaled back) and its exact spring
Hessian are :attr:`MaudCalculator.potential`, a
:class:`~ase_maud.calculator.potential.MaudPotential`; the sum over pairs is a backend's
(:mod:`ase_maud.backends`). Where a result is not representable, a ValueError
names the atoms (or ``a`` and ``Q``), never a NaN.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np
import scipy.sparse as sp
from ase import Atoms
from ase.calculators.calculator import all_changes
from numpy.typing import ArrayLike

from ase_maud import backends
from ase_maud.backends.base import diagonal_blocks
from ase_maud.calculator.locked import LockedCalculator
from ase_maud.calculator.potential import MaudPotential
from ase_maud.checks import all_finite, check
from ase_maud.physics import pair_law as physics
from ase_maud.physics.pair_law import raise_on_closest


class MaudCalculator(LockedCalculator):
    """ASE calculator for the Maud potential.

    Parameters
    ----------
    springs : array-like of shape (K, 2)
        Atom index pairs tied by a spring. Each pair at most once (in either
        order); a duplicate, a self-spring or an index out of range is a
        ``ValueError`` that names the spring.
    a : float
        Length in the repulsion ``a**3 Q / L`` (default 1). ``0`` switches
        the repulsion off: springs and loads alone, the force-density method
        (:attr:`last_backend` ``'none'``).
    Q : float
        Spring constant, force per length (default 1).
    q : array-like of shape (K,), optional
        Each spring's force density multiplier of ``Q``, finite and nonzero,
        in the order of ``springs``: spring ``s`` has energy ``Q q_s L**2 /
        2`` and pulls with ``Q q_s L`` (the force density of compas_fd is
        ``Q q_s``); a negative ``q_s`` pushes (compression), and a net with
        one has equilibria that are stationary points, not minima (Maud then
        takes ``target='stationary'``). Default None: every ``q_s = 1``. The springs' Hessian
        stays constant, ``Q`` times the ``q``-weighted Laplacian.
    loads : array-like of shape (N, 3), optional
        Constant nodal loads ``F_i`` in force units (self-weight, say): the
        energy gains ``-sum_i F_i . r_i``, the forces ``+F_i``; no Hessian or
        nodal block changes. ``(N, 2)`` for ``dim=2`` (in-plane; a z
        component must be 0). One row per atom, checked when the atoms are.
        Default None: no loads.
    dim : 2 or 3
        ``2``: every point lies on one plane ``z = const`` (checked to a
        relative :data:`~ase_maud.calculator.potential.PLANE_TOLERANCE`),
        forces have ``z = 0`` exactly and the blocks are 2x2. ``3``
        (default): 3x3 blocks.
    backend : str
        The repulsion kernel, a name in the registry :mod:`.backends`:
        ``auto`` (default) picks per call the cheapest backend that meets
        ``tol`` for this N, dim and property set: the exact ``numba`` direct
        sum below a measured crossover, the FMM above it (with ``fmm_eps``
        derived from ``tol``; the direct sum if fmm3dpy is not installed).
        Explicit: ``numba`` (compiled direct sum, parallel over numba's
        threads), ``numpy`` (the slow reference) or ``fmm`` (FMM3D at
        ``fmm_eps``, O(N)).
    **kwargs
        The backends' parameters (:mod:`.backends`; each checked whichever
        backend is chosen): ``tol`` (``auto``: the force error allowed,
        relative to the largest repulsive force; default
        :data:`~.backends.auto.DEFAULT_TOL`, 1e-8; 0: the exact direct sum),
        ``crossover`` (``auto``: the points from which the FMM is used
        whatever ``tol``; None: the measured
        :data:`~ase_maud.backends.auto.CROSSOVER`), ``fmm_eps`` (the ``fmm``
        backend's force error allowed relative to the largest force, default
        1e-6; FMM3D gets :data:`~ase_maud.backends.fmm.LIBRARY_EPS`'s), and ASE's.

    Raises
    ------
    ValueError
        When set (at construction or by :meth:`set`): a spring list that is
        not index pairs, a duplicate or self-spring (the spring named);
        ``a`` not >= 0 or ``Q`` not positive and finite; ``q`` not one
        positive finite value per spring; ``loads`` of another shape or, for
        ``dim=2``, with a z component; an unknown parameter. At a call:
        periodic boundaries, no atoms, a non-finite position, two points at
        one position or closer than about ``1e-100 a``, a ``dim=2`` point off
        the plane, a spring index beyond the last atom, loads not one row
        per atom, results that overflow float64.

    Notes
    -----
    Units: positions in the unit of ``a`` (the calculator works in units of
    ``a`` inside), energies in ``Q a^2``, forces in ``Q a`` with
    ASE's sign ``f = -dE/dr``, stiffness blocks and Hessians in ``Q``; the
    energy counts each pair once.

    Accuracy per run (``calc.set(tol=...)``, :attr:`last_backend`,
    :attr:`last_tolerance`, :attr:`last_force_scale`, :attr:`last_energy_error`),
    threads and memory: docs/calculator.md. Only what is asked is computed:
    ``energy``/``forces`` never build the blocks, ``stiffness`` computes all
    three in one pass, ``hessian`` (dense, small scenes) comes with the
    energy and forces.
    """

    #: Results :meth:`take` hands to :meth:`calculate` (None: compute them).
    _taken: tuple[dict[str, Any], float] | None = None

    implemented_properties = ['energy', 'free_energy', 'forces', 'stiffness',
                              'hessian']
    # springs default to a tuple: Calculator.todict compares each parameter
    # with its default by ``!=``, which fails on an ndarray default. The
    # potential's parameters, then the backends' (from their registry).
    default_parameters = {'springs': (), 'a': 1.0, 'Q': 1.0, 'dim': 3, 'q': None,
                          'loads': None, 'backend': 'auto',
                          **backends.parameter_defaults()}
    #: The parameters that make the potential (the rest choose how to sum it).
    potential_parameters = ('springs', 'a', 'Q', 'dim', 'q', 'loads')
    discard_results_on_any_change = True
    nolabel = True

    #: Largest number of atoms for which :meth:`get_hessian` builds the dense
    #: (dim N)**2 matrix: 3000 atoms in 3D is an 81e6-entry, 648 MB array.
    max_hessian_atoms = 3000
    #: :meth:`hessian_rows` takes the Hessian's block on the atoms with a free
    #: coordinate where more than this fraction of the atoms are held.
    block_min_held = 0.5

    #: Parameters that change the accuracy of the next calls, not the
    #: potential: results that meet the new ``tol`` stay.
    accuracy_parameters = frozenset({'tol', 'crossover'})

    def __init__(self, springs: ArrayLike = (), a: float = 1.0,
                 Q: float = 1.0, dim: int = 3, q: ArrayLike | None = None,
                 loads: ArrayLike | None = None, backend: str = 'auto',
                 **kwargs: Any) -> None:
        self.potential: MaudPotential = MaudPotential(np.zeros((0, 2), int))
        self.last_backend: str | None = None
        self.last_tolerance: float | None = None
        self.last_force_scale: float | None = None
        self.last_energy_error: float | None = None
        super().__init__(springs=springs, a=a, Q=Q, dim=dim, q=q, loads=loads,
                         backend=backend, **kwargs)

    def set(self, **kwargs: Any) -> dict[str, Any]:
        """Set parameters; invalid values raise ValueError and are not kept.

        Any change discards the results, except a change of ``tol`` or
        ``crossover`` alone that the results held already meet
        (:attr:`last_tolerance` ``<=`` the new ``tol``). One thread at a
        time, as :meth:`get_property`.
        """
        with self._lock:
            return self._set(**kwargs)

    def _set(self, **kwargs: Any) -> dict[str, Any]:
        unknown = sorted(set(kwargs) - set(self.default_parameters))
        if unknown:
            raise ValueError(f'MaudCalculator takes no parameter {unknown[0]!r}; '
                             f'its parameters are {", ".join(self.default_parameters)}')
        merged = {**self.parameters, **kwargs}
        if set(kwargs) & set(self.potential_parameters):
            potential = MaudPotential(**{name: merged[name]
                                         for name in self.potential_parameters})
            backends.check_parameters(merged)
            self.potential = potential
            kwargs.update({name: getattr(potential, name) for name in kwargs
                           if name in self.potential_parameters})
        else:
            backends.check_parameters(merged)
        if (kwargs and set(kwargs) <= self.accuracy_parameters
                and self.last_tolerance is not None
                and self.last_tolerance <= kwargs.get(
                    'tol', self.parameters['tol'])):
            changed = {key: value for key, value in kwargs.items()
                       if self.parameters.get(key) != value}
            self.parameters.update(kwargs)
            return changed
        return super().set(**kwargs)

    @property
    def tolerance(self) -> float:
        """``tol``: the force error allowed of the next calls
        (:class:`ase_maud.calculator.accuracy.ToleranceAware`)."""
        return self.parameters['tol']

    def set_tolerance(self, tol: float) -> None:
        """Set ``tol`` for the next calls (:class:`ase_maud.calculator.accuracy.ToleranceAware`):
        :meth:`set` with ``tol`` alone, without its checks of the other
        parameters when the results held already meet it.

        Parameters
        ----------
        tol : float
            The force error allowed of the next calls, relative to the
            largest repulsive force (``Q a``); 0 asks for the exact direct sum.

        Returns
        -------
        None
            The calls from now on are asked for ``tol``; held results that
            meet it stay.

        Raises
        ------
        ValueError
            ``tol`` not a number in [0, 1).
        """
        if self.last_tolerance is not None and self.last_tolerance <= tol:
            self.parameters['tol'] = check('tol', tol)
        else:
            self.set(tol=tol)

    def reset(self) -> None:
        """Clear the results and what is known of their accuracy."""
        super().reset()
        self.last_backend = self.last_tolerance = None
        self.last_force_scale = self.last_energy_error = None

    @property
    def springs(self) -> np.ndarray:
        """The (K, 2) int array of sprung pairs."""
        return self.potential.springs

    @property
    def dim(self) -> int:
        """2 (points on a plane z = const, 2x2 blocks) or 3."""
        return self.potential.dim

    @property
    def length_scale(self) -> float:
        """The length ``a`` of the repulsion ``a**3 Q / L`` (a dimer with
        one spring rests at ``L = a``)."""
        return self.potential.a

    def check_atoms(self, atoms: Atoms) -> np.ndarray:
        """Validate ``atoms`` for this potential; return its positions
        (:meth:`MaudPotential.checked_positions`: a ValueError names the
        problem)."""
        return self.potential.checked_positions(atoms)

    def take(self, atoms: Atoms, energy: float, forces: np.ndarray, hessian: np.ndarray,
             force_scale: float) -> None:
        """Hold the results of ``atoms``' positions that a loop on arrays
        computed by this calculator's law in one compiled pass
        (:func:`.compiled_sums.scene_terms`, exact: what :meth:`calculate` gives
        for ``'hessian'``): the energy, forces (N, 3), Hessian (dim N, dim N)
        and the largest repulsion force (``a Q``), finite. It is one call of
        :meth:`calculate`, which holds them (and counts as any call)."""
        with self._lock:
            self._taken = {'energy': float(energy), 'forces': forces, 'hessian': hessian,
                           'free_energy': float(energy)}, force_scale
            try:
                self.results = {}
                self.calculate(atoms, ['hessian'], ['positions'])
            finally:
                self._taken = None

    def calculate(self, atoms: Atoms | None = None,
                  properties: Sequence[str] = ('energy',),
                  system_changes: Sequence[str] = all_changes) -> None:
        if atoms is not None:
            self._hold(atoms, system_changes)
        if self._taken is not None:   # computed by :meth:`take`'s caller
            self.results, self.last_force_scale = self._taken
            self.last_backend = (backends.exact_choice(self.parameters['backend']).backend.name
                                 if self.potential.repulsive else 'none')
            self.last_tolerance = self.last_energy_error = 0.0
            return
        positions = self.check_atoms(self.atoms)
        potential = self.potential
        dim, a, Q = potential.dim, potential.a, potential.Q
        want_blocks = 'stiffness' in properties
        want_hessian = 'hessian' in properties
        if want_hessian:
            self.check_hessian_size(len(positions))
        if potential.repulsive:
            scaled = potential.reduced(positions)
            if want_hessian:   # energy, forces and Hessian in one pass, exact
                choice = backends.exact_choice(self.parameters['backend'])
                e_rep, f_rep, h_rep = choice.backend.hessian(scaled, dim)
                block6 = diagonal_blocks(h_rep, dim) if want_blocks else None
            else:
                (e_rep, f_rep, block6), choice = backends.evaluate(
                    self.parameters, scaled, dim, want_blocks)
            backend, tolerance, error = (choice.backend.name, choice.tolerance,
                                         choice.energy_tolerance)
            e_unit, f_unit = potential.energy_unit, potential.force_unit
        else:   # a = 0: springs and loads alone, in the user's units (x' = x), times Q
            n = dim * len(positions)
            scaled, e_rep, f_rep, backend, tolerance, error = positions, 0.0, 0.0, 'none', 0.0, 0.0
            h_rep = np.zeros((n, n)) if want_hessian else None
            e_unit = f_unit = Q
        e_spr, f_spr = potential.spring_terms(scaled)
        results = {'energy': e_unit * (e_rep + e_spr), 'forces': f_unit * (f_rep + f_spr)}
        if potential.loads is not None:
            with np.errstate(over='ignore', invalid='ignore'):   # said below
                e_load, f_load = physics.load_terms(positions, potential.loads)
            if not np.isfinite(e_load):
                raise ValueError(f'the energy of the loads, -sum p.x, overflows float64 '
                                 f'(loads up to {np.abs(potential.loads).max():.3g} force '
                                 f'units, positions up to {np.abs(positions).max():.3g}): '
                                 'choose units nearer the scene')
            results['energy'] += e_load
            results['forces'] += f_load
        if want_blocks:
            blocks = (backends.voigt_to_blocks(block6, dim) if potential.repulsive
                      else np.zeros((len(positions), dim, dim)))
            blocks += physics.spring_nodal_blocks(self.springs, len(positions),
                                                  potential.stiffnesses, dim)
            results['stiffness'] = Q * blocks
        if want_hessian:
            results['hessian'] = potential.whole_hessian(h_rep)
        bad = [name for name, value in results.items() if not all_finite(value)]
        if bad:
            if potential.repulsive:
                raise_on_closest(scaled, a)   # 1/L, 1/L**2 or the Hessian's 1/L**3
            raise ValueError(f'the {", ".join(bad)} overflow float64 at a = '
                             f'{a!r}, Q = {Q!r} (energies scale as a^2 Q, '
                             'forces as a Q): choose units nearer the scene')
        if dim == 2:
            results['forces'][:, 2] = 0.0
        results['energy'] = float(results['energy'])
        # results of a call at other positions are gone by now (ASE clears
        # them without reset): only those still held count
        held = (self.last_tolerance, self.last_energy_error) if self.results else (0.0, 0.0)
        self.results.update(results, free_energy=results['energy'])
        self.last_backend = backend
        self.last_tolerance = max(held[0] or 0.0, tolerance)
        # the energy's error (an exact sum's is 0, also where e_rep is inf)
        self.last_energy_error = max(held[1] or 0.0, e_unit * abs(e_rep) * error if error else 0.0)
        self.last_force_scale = potential.force_unit * (
            math.sqrt((f_rep * f_rep).sum(axis=1).max(initial=0.0))
            if potential.repulsive else 0.0)

    def __getattr__(self, name: str) -> Any:
        """0.1's scene proofs, now :attr:`potential`'s (a FutureWarning until 0.3)."""
        if name not in ('minimum_proved', 'no_equilibrium', 'unbounded_components'):
            raise AttributeError(f'MaudCalculator has no attribute {name!r}')
        warnings.warn(f'MaudCalculator.{name} is now calc.potential.{name}', FutureWarning, 2)
        return getattr(self.__dict__['potential'], name)

    def get_stiffness(self, atoms: Atoms | None = None) -> np.ndarray:
        """Nodal blocks ``K_mm``, shape (N, dim, dim), units of ``Q``.

        Parameters
        ----------
        atoms : Atoms or None, default None
            The scene (None: the atoms of the last call).

        Returns
        -------
        ndarray of shape (N, dim, dim)
            ``K_mm = d2E / dr_m dr_m``, the diagonal blocks of the Hessian, in
            ``Q`` (the repulsion's blocks are traceless in 3D).

        Raises
        ------
        ValueError
            Atoms the calculator refuses (see :class:`MaudCalculator`).
        """
        return self.get_property('stiffness', atoms)

    def get_hessian(self, atoms: Atoms | None = None) -> np.ndarray:
        """The full analytic Hessian ``d2E/dr dr``, shape (dim N, dim N), of
        a small scene (at most :attr:`max_hessian_atoms` atoms).

        Parameters
        ----------
        atoms : Atoms or None, default None
            The scene; None takes the atoms the calculator last computed.

        Returns
        -------
        ndarray of shape (dim N, dim N)
            The dense symmetric Hessian in ``Q``, rows and columns ordered
            atom by atom (x, y[, z] of atom 0, then atom 1, ...), constrained
            atoms included.

        Raises
        ------
        ValueError
            More than :attr:`max_hessian_atoms` atoms (the message names the
            O(N)-memory alternatives), or atoms the calculator refuses.
        """
        if atoms is not None:
            self.check_hessian_size(len(atoms))
        return self.get_property('hessian', atoms)

    def get_hessian_block(self, atoms: Atoms, indices: ArrayLike) -> np.ndarray:
        """The rows and columns of :meth:`get_hessian` on the coordinates of
        the atoms ``indices`` (n distinct indices), shape (dim n, dim n),
        units of ``Q``, at ``atoms``' positions: computed anew in O(n N)
        time and O(n**2) memory without the whole Hessian (whatever N), and
        not kept in :attr:`results`. A ValueError names a bad index.

        Parameters
        ----------
        atoms : Atoms
            The scene.
        indices : array-like of int
            The atoms whose coordinates make the block's rows and columns,
            in the order given.

        Returns
        -------
        ndarray of shape (dim n, dim n)
            The block of the Hessian, in ``Q``.

        Raises
        ------
        ValueError
            A bad or repeated index, atoms the calculator refuses, or a
            block that overflows float64.
        """
        self.potential.check_size(len(atoms))
        return self.potential.hessian_block(self.check_atoms(atoms), indices)

    def hessian_rows(self, atoms: Atoms, free: np.ndarray) -> np.ndarray | None:
        """The atoms with a free coordinate (``free``: mask (N, dim)) where
        :meth:`get_hessian_block` on them is cheaper than :meth:`get_hessian`:
        the other atoms are more than :attr:`block_min_held` of them (a
        Filter's region, a net held at most points); else None, and always
        for a subclass, whose ``calculate`` may give another Hessian."""
        rows = np.flatnonzero(free.any(axis=1))
        cheaper = len(rows) < (1.0 - self.block_min_held) * len(atoms)
        return rows if cheaper and type(self) is MaudCalculator else None

    def check_hessian_size(self, natoms: int, what: str = 'get_hessian') -> None:
        """Raise ValueError, naming the O(N)-memory alternatives, if a dense
        Hessian of ``natoms`` atoms exceeds :attr:`max_hessian_atoms`."""
        if natoms > self.max_hessian_atoms:
            raise ValueError(
                f'{what}: {natoms} atoms exceed max_hessian_atoms = {self.max_hessian_atoms} '
                f'(the dense matrix would hold {(self.dim * natoms)**2:.2e} entries); use '
                'Hessian-vector products (calc.potential.hvp, or ase_maud.analysis.stationary.'
                "hessian_operator and classify(atoms, method='iterative') for the lowest "
                'modes) instead')

    def get_spring_hessian(self, atoms: Atoms | None = None) -> sp.csr_matrix:
        """The springs' exact, constant Hessian ``Q (L_q (x) I_dim)`` (``L_q``
        the Laplacian weighted by ``q``), shape
        (dim N, dim N), kept by :attr:`potential` (built once per number of
        atoms). A spring index beyond the last atom is a ValueError.

        Parameters
        ----------
        atoms : Atoms or None, default None
            The scene (None: the atoms of the last call); only its number of
            atoms is used.

        Returns
        -------
        scipy.sparse.csr_matrix of shape (dim N, dim N)
            The springs' part of the Hessian, in ``Q`` (the repulsion's is
            not in it).

        Raises
        ------
        ValueError
            A spring names an atom beyond the last one.
        """
        atoms = atoms if atoms is not None else self.atoms
        return self.potential.spring_hessian(len(atoms))

