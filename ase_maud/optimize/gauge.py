"""A saddle search on a scene held at one point only: the free scene's.

A net without loads has an energy unchanged by a translation. Holding one
point then removes the translations and nothing else, so the held scene's
stationary points, and their indices, are the free scene's moved to put that
point back (the Hessian on the moves that keep the point is the free one's
on the moves modulo translation). The eigenvector following of a saddle
search is not: its modes are those of the Hessian restricted to the moves
that keep the point, which climb elsewhere (a ring of 8 held at one point
stretched without end where the free ring found its saddle in 25 steps).

So such a search follows the free scene's modes (:func:`free_view`: the
scene without the hold, its calculator shared), its forces completed with
the held point's (:func:`free_forces`: minus the sum of the others'), and
each move translated to keep the point where it is (:func:`held_move`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from ase import Atoms
from ase.constraints import FixAtoms, FixCartesian

from ase_maud.calculator.identify import potential_of


def gauge_point(atoms: Any) -> int | None:
    """The one point that holds ``atoms`` (Atoms with a MaudCalculator
    potential and no loads) if the scene is held there alone (FixAtoms of
    one point, and on a dim=2 scene the plane's z holds), else None."""
    potential = potential_of(atoms)
    if not isinstance(atoms, Atoms) or potential is None or (
            potential.loads is not None and np.any(potential.loads)):
        return None
    held = []
    for constraint in atoms.constraints:
        if isinstance(constraint, FixAtoms):
            held += constraint.index.tolist()
        elif not (isinstance(constraint, FixCartesian) and potential.dim == 2
                  and list(constraint.mask) == [False, False, True]):
            return None
    return held[0] if len(held) == 1 else None


def free_view(atoms: Atoms, point: int) -> Atoms:
    """``atoms`` without the hold of ``point`` (the plane's holds kept),
    sharing its calculator."""
    view = atoms.copy()
    view.set_constraint([c for c in atoms.constraints if not isinstance(c, FixAtoms)])
    view.calc = atoms.calc
    return view


def free_forces(forces: np.ndarray, point: int) -> np.ndarray:
    """``forces`` (N, 3) with the held ``point``'s completed: minus the sum
    of the others' (a net without loads exerts no net force)."""
    forces = forces.copy()
    forces[point] = 0.0
    forces[point] = -forces.sum(axis=0)
    return forces


def held_move(x: np.ndarray, start: np.ndarray, point: int) -> np.ndarray:
    """The positions ``x`` (N, 3) translated to leave ``point`` at ``start``'s."""
    return x - (x[point] - start[point])
