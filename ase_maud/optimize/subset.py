"""ASE's ``Filter`` (a subset of the atoms) for the stiffness models.

``Maud(Filter(atoms, indices=free))`` moves only the filter's atoms; its
coordinates and forces are theirs, (n, 3). The stiffness models work on whole
scenes, so they are given a :class:`SubsetView`: a copy of the atoms that
shares their calculator, follows their positions and holds the atoms the
filter leaves out with ``FixAtoms``, which is what leaving them out means. A
:class:`SubsetSolver` takes the filter's forces to the whole scene (zero on
the atoms left out) and the move back to the filter's atoms.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from ase import Atoms
from ase.constraints import FixAtoms
from ase.filters import Filter

from ase_maud.optimize.models.base import DampedSolver, ModeSolver, Solver
from ase_maud.physics.neighbours import NearestDistances


class SubsetView:
    """The whole scene behind ``subset`` (an ASE :class:`~ase.filters.Filter`)
    as the stiffness models see it (module docstring); ``index``: the
    filter's atoms, in its order."""

    def __init__(self, subset: Filter):
        atoms = subset.atoms
        self.atoms = atoms
        self.index = np.arange(len(atoms))[np.asarray(subset.index)]
        left_out = np.setdiff1d(np.arange(len(atoms)), self.index)
        self.view = atoms.copy()
        self.view.calc = atoms.calc
        if left_out.size:
            self.view.set_constraint([*self.view.constraints, FixAtoms(indices=left_out)])

    def current(self) -> Atoms:
        """The view at the atoms' current positions."""
        self.view.arrays['positions'][:] = self.atoms.positions
        self.view.calc = self.atoms.calc   # the user may have set another one
        return self.view

    def solver(self, whole: Solver) -> SubsetSolver:
        return subset_solver(whole, self.index, len(self.atoms))

    def nearest(self) -> SubsetNearest:
        return SubsetNearest(self)


class SubsetNearest(NearestDistances):
    """Nearest-neighbour distances over the whole scene: for the filter's
    positions (n, 3), those of its atoms (the step bound keeps them clear of
    the atoms left out too); for the whole scene's, all of them."""

    def __init__(self, subset: SubsetView):
        super().__init__()
        self.subset = subset

    def __call__(self, x: np.ndarray) -> np.ndarray:
        index, natoms = self.subset.index, len(self.subset.atoms)
        if len(x) == natoms:
            return super().__call__(x)
        whole = self.subset.atoms.positions.copy()
        whole[index] = x
        return super().__call__(whole)[index]


class SubsetSolver(Solver):
    """``whole``'s move for forces on the ``index`` atoms of ``natoms``."""

    def __init__(self, whole: Solver, index: np.ndarray, natoms: int):
        self.whole, self.index, self.natoms = whole, index, natoms

    def _scene(self, rows: np.ndarray) -> np.ndarray:
        """The filter's rows (n, 3) as the scene's (N, 3), zero elsewhere."""
        scene = np.zeros((self.natoms, 3))
        scene[self.index] = rows
        return scene

    def solve(self, forces: np.ndarray) -> np.ndarray:
        return self.whole.solve(self._scene(forces))[self.index]


class _SubsetDamped(SubsetSolver, DampedSolver):
    """A :class:`SubsetSolver` of a :class:`~ase_maud.optimize.models.base.DampedSolver`."""

    @property
    def definite(self) -> bool:
        return self.whole.definite

    @property
    def scale(self) -> float:
        return self.whole.scale

    def dot(self, move: np.ndarray) -> np.ndarray:
        return self.whole.dot(self._scene(move))[self.index]

    def damped(self, forces: np.ndarray) -> Callable[[float], np.ndarray | None]:
        moves = self.whole.damped(self._scene(forces))

        def move(mu: float) -> np.ndarray | None:
            whole = moves(mu)
            return None if whole is None else whole[self.index]
        return move


class _SubsetModes(SubsetSolver, ModeSolver):
    """A :class:`SubsetSolver` of a :class:`~ase_maud.optimize.models.base.ModeSolver`
    (its modes are zero on the atoms the filter leaves out, which it holds)."""

    def eigenpairs(self, count: int, guess: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        scene = None if guess is None else np.array([self._scene(g) for g in guess])
        values, modes = self.whole.eigenpairs(count, scene)
        return values, modes[:, self.index]

    def curvature(self, move: np.ndarray) -> np.ndarray:
        return self.whole.curvature(self._scene(move))[self.index]


class _SubsetEigen(_SubsetDamped, _SubsetModes):
    """A :class:`SubsetSolver` of a solver with both interfaces."""


def subset_solver(whole: Solver, index: np.ndarray, natoms: int) -> SubsetSolver:
    """``whole`` seen through a filter's ``index`` atoms, with the same
    interfaces (:class:`~ase_maud.optimize.models.base.DampedSolver`,
    :class:`~ase_maud.optimize.models.base.ModeSolver`, both, or neither)."""
    kinds = {(True, True): _SubsetEigen, (True, False): _SubsetDamped,
             (False, True): _SubsetModes, (False, False): SubsetSolver}
    return kinds[isinstance(whole, DampedSolver), isinstance(whole, ModeSolver)](
        whole, index, natoms)
