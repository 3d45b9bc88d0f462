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

from typing import Any

import numpy as np
from ase import Atoms
from ase.constraints import FixAtoms
from ase.filters import Filter

from .neighbours import NearestDistances
from .stiffness import Solver


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
        return SubsetSolver(whole, self.index, len(self.atoms))

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
    """``whole``'s move for forces on the ``index`` atoms of ``natoms``; the
    optional parts of a solver the step uses where ``whole`` has them
    (``dot``, ``shifted_solve``, ``values``) pass through, mapped alike."""

    def __init__(self, whole: Solver, index: np.ndarray, natoms: int):
        self.whole, self.index, self.natoms = whole, index, natoms

    def _scene(self, rows: np.ndarray) -> np.ndarray:
        """The filter's rows (n, 3) as the scene's (N, 3), zero elsewhere."""
        scene = np.zeros((self.natoms, 3))
        scene[self.index] = rows
        return scene

    def solve(self, forces: np.ndarray) -> np.ndarray:
        return self.whole.solve(self._scene(forces))[self.index]

    def __getattr__(self, name: str) -> Any:
        inner = getattr(self.whole, name)   # AttributeError if whole has none
        if name == 'dot':
            return lambda move: inner(self._scene(move))[self.index]
        if name == 'shifted_solve':
            def shifted_solve(forces: np.ndarray) -> Any:
                moves = inner(self._scene(forces))
                return lambda shifts: moves(shifts)[:, self.index]
            return shifted_solve
        return inner
