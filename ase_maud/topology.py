"""Whether a scene can have a finite minimum at all, from its spring graph.

Repulsion between two spring components decays like 1/L, so a component with
no fixed atom is pushed away from every other component for ever: the scene
then has no finite minimum (stationary points such as saddles may remain).
A single free component, alone, is bounded (up to rigid motion), and so is
every component that holds a fixed atom.
"""

import numpy as np
from ase.constraints import FixAtoms, FixCartesian
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components


def spring_components(natoms, springs):
    """Label of the spring-graph component of every atom, shape (natoms,)."""
    springs = np.asarray(springs, dtype=int).reshape(-1, 2)
    graph = coo_matrix((np.ones(len(springs)), springs.T),
                       shape=(natoms, natoms))
    return connected_components(graph, directed=False)[1]


def fixed_atoms(atoms):
    """Boolean mask of atoms held in all three directions by a constraint."""
    held = np.zeros((len(atoms), 3), dtype=bool)
    for c in atoms.constraints:
        if isinstance(c, FixAtoms):
            held[c.index] = True
        elif isinstance(c, FixCartesian):
            held[c.index] |= np.asarray(c.mask, dtype=bool)
    return held.all(axis=1)


def unbounded_components(atoms, springs):
    """Components (lists of atom indices) that would fly away for ever.

    Empty when the scene can have a finite minimum: one free component alone,
    or every component anchored by a fixed atom.
    """
    labels = spring_components(len(atoms), springs)
    fixed = fixed_atoms(atoms)
    groups = [np.flatnonzero(labels == k) for k in range(labels.max() + 1)]
    if len(groups) < 2:
        return []
    return [g.tolist() for g in groups if not fixed[g].any()]


def describe_unbounded(components, limit=3):
    """One sentence naming the free components (the first few atoms each)."""
    shown = ['[' + ', '.join(map(str, g[:limit])) + (', ...' if len(g) > limit
                                                     else '') + ']'
             for g in components[:limit]]
    more = f' and {len(components) - limit} more' if len(components) > limit else ''
    return (f'no finite minimum: {len(components)} spring component(s) with '
            f'no fixed atom ({", ".join(shown)}{more}) repel the rest for '
            'ever; fix an atom in each or tie them together with springs')
