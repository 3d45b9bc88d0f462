"""The spring graph of a net: supports by rule, and whether a scene can
have a finite minimum at all, from its spring graph and its loads.

Supports by rule: :func:`boundary_vertices` (a mesh's boundary: the points
on edges of exactly one face), :func:`outer_rim` (its outer loop alone) and
:func:`leaf_vertices` (a network's leaves: points on exactly one spring);
:func:`support_excursion` says how far a form strays beyond its supports.

Finite minima: a spring component free to translate in 3D beside other components feels
their repulsion as a sum of 1/L terms, a harmonic function of its translation:
it has no local minimum there (Earnshaw's theorem), so the scene has no finite
minimum (stationary points such as saddles may remain). This is proved only
for points free in 3D: in a ``dim=2`` scene, or for a component with any atom
held by a constraint (to a plane or a line, say), 1/L is not harmonic in the
directions left free and repulsion can hold it (a 2D ring about a point). A
single free component, alone, is bounded up to rigid motion.

Loads: springs and repulsion are internal forces (they sum to zero), so a
scene that nothing holds in some direction has no equilibrium at all unless
its loads sum to zero in that direction: it drifts for ever
(:func:`net_load`).

Proved minima (:func:`minimum_proved`): the springs' energy is quadratic and
positive in the points' positions relative to their component, the repulsion
positive, the loads linear; so when every component is held in every
direction (each direction by some atom of it) the energy grows without bound
far out and has a finite minimum, however far the loads push it. A single
component may instead be free along a direction if its loads sum to zero
there (it is then flat along it).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numba
import numpy as np
from ase import Atoms
from ase.constraints import FixAtoms, FixCartesian
from numpy.typing import ArrayLike

from ase_maud.checks import check_each
from ase_maud.physics.spring_list import check_springs


def spring_components(natoms: int, springs: ArrayLike) -> np.ndarray:
    """Label of the spring-graph component of every atom, shape (natoms,),
    int32: the components numbered 0, 1, ... in the order of their lowest
    atom index (SciPy's ``connected_components(directed=False)``'s labels),
    an atom on no spring alone. ``springs``: (K, 2) pairs of atom indices
    below ``natoms``, in any order, repeated or not; a ValueError names the
    first outside that range. Found by union-find in one compiled pass
    (:func:`_component_labels`): through a SciPy graph a scene of tens of
    points paid more for the graph than for the search."""
    springs = np.ascontiguousarray(np.asarray(springs, dtype=np.int64).reshape(-1, 2))
    if len(springs) and (springs.min() < 0 or springs.max() >= natoms):
        check_springs(springs, natoms)   # names the first, and raises
    return _component_labels(natoms, springs)


@numba.njit(cache=True)
def _component_labels(natoms: int, springs: np.ndarray) -> np.ndarray:
    """:func:`spring_components`'s labels: each spring joins the trees of its
    ends under the lower root (so a root is its component's lowest atom),
    then the atoms, in order, number their roots as first met."""
    parent = np.arange(natoms)
    for s in range(springs.shape[0]):
        a, b = _root(parent, springs[s, 0]), _root(parent, springs[s, 1])
        if a < b:
            parent[b] = a
        elif b < a:
            parent[a] = b
    labels = np.empty(natoms, dtype=np.int32)
    count = 0
    for atom in range(natoms):
        root = _root(parent, atom)
        if root == atom:
            labels[atom] = count
            count += 1
        else:
            labels[atom] = labels[root]
    return labels


@numba.njit(cache=True)
def _root(parent: np.ndarray, atom: int) -> int:
    """The root of ``atom``'s tree in ``parent``, halving the path there."""
    while parent[atom] != atom:
        parent[atom] = parent[parent[atom]]
        atom = parent[atom]
    return atom


def boundary_edges(faces: Iterable[Sequence[int]]) -> np.ndarray:
    """The edges of a mesh that belong to exactly one face, (E, 2) sorted
    pairs of point indices.

    ``faces`` are rings of point indices (each ring closed from its last
    point to its first). An edge is the unordered pair of its ends, so the
    faces' orientations need not agree; an edge of three or more faces (a
    non-manifold edge) is not on the boundary.
    """
    pairs = face_edges(faces)
    _, first, count = unique_pairs(pairs)
    once = np.sort(first[count == 1])
    edges = np.sort(pairs[once], axis=1)
    return edges[np.lexsort((edges[:, 1], edges[:, 0]))]


def face_edges(faces: Iterable[Sequence[int]]) -> np.ndarray:
    """Every edge of every face, (E, 2), in order: each ring closed from its
    last point to its first; numpy does the work, ring size by ring size."""
    if isinstance(faces, np.ndarray) and faces.ndim == 2:
        groups = [faces]
    else:
        by_size: dict[int, list[Sequence[int]]] = {}
        for face in faces:
            by_size.setdefault(len(face), []).append(face)
        groups = [np.asarray(rings, dtype=np.int64) for rings in by_size.values()]
    pairs = [np.zeros((0, 2), dtype=np.int64)]
    for ring in groups:
        ring = np.asarray(ring, dtype=np.int64)
        pairs.append(np.stack([ring, np.roll(ring, -1, axis=1)], axis=-1).reshape(-1, 2))
    return np.concatenate(pairs)


def unique_pairs(pairs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The undirected pairs of (E, 2) ``pairs`` once each: the index in
    ``pairs`` of each one's first copy (ascending by the pair) and how many
    copies it has, and the inverse (for each pair, its unique one). One
    sort of an int64 key, several times faster than ``np.unique(axis=0)``."""
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    if not len(pairs):
        empty = np.zeros(0, dtype=np.int64)
        return empty, empty, empty
    low, high = np.minimum(pairs[:, 0], pairs[:, 1]), np.maximum(pairs[:, 0], pairs[:, 1])
    keys = low * (int(high.max()) + 1) + high
    order = np.argsort(keys, kind='stable')   # stable: a pair's first copy leads
    ordered = keys[order]
    starts = np.flatnonzero(np.r_[True, ordered[1:] != ordered[:-1]])
    first = order[starts]
    count = np.diff(np.r_[starts, len(keys)])
    inverse = np.empty(len(keys), dtype=np.int64)
    inverse[order] = np.repeat(np.arange(len(starts)), count)
    return inverse, first, count


def boundary_vertices(faces: Iterable[Sequence[int]]) -> np.ndarray:
    """Sorted indices of the points on a mesh's boundary: the ends of the
    edges that belong to exactly one face (:func:`boundary_edges`), each
    once."""
    pairs = face_edges(faces)
    _, first, count = unique_pairs(pairs)
    return np.unique(pairs[first[count == 1]])


def outer_rim(faces: Iterable[Sequence[int]], positions: np.ndarray) -> np.ndarray:
    """Sorted indices of the points of a mesh's outer rim: of the loops of
    its boundary (:func:`boundary_edges`, joined where they share a point),
    the one of largest extent (the diagonal of its points' bounding box,
    ``positions`` (N, 3)): a hole's rim is left free. Empty for a closed
    mesh."""
    edges = boundary_edges(faces)
    if not len(edges):
        return np.zeros(0, dtype=int)
    points, local = np.unique(edges, return_inverse=True)
    loops = spring_components(len(points), local.reshape(-1, 2))
    extent = [np.linalg.norm(np.ptp(positions[points[loops == k]], axis=0))
              for k in range(loops.max() + 1)]
    return points[loops == int(np.argmax(extent))]


def mean_spring_length(positions: np.ndarray, springs: ArrayLike) -> float:
    """The mean length of the springs ((K, 2) pairs, K >= 1), in the
    positions' unit."""
    i, j = np.asarray(springs, dtype=int).reshape(-1, 2).T
    return float(np.linalg.norm(positions[i] - positions[j], axis=1).mean())


def leaf_vertices(natoms: int, springs: ArrayLike) -> np.ndarray:
    """Sorted indices of a network's leaves: the points on exactly one
    spring (of ``springs``, (K, 2) pairs each once)."""
    springs = np.asarray(springs, dtype=int).reshape(-1, 2)
    return np.flatnonzero(np.bincount(springs.ravel(), minlength=natoms) == 1)


def support_excursion(atoms: Atoms) -> tuple[float, float]:
    """How far (length units) the free points reach outside the bounding box
    of the fixed ones (:func:`fixed_atoms`), and that box's diagonal; (0, 0)
    if nothing is fixed. A point inside the box is 0 away; outside, its
    distance to the box's nearest point."""
    fixed = fixed_atoms(atoms)
    if not fixed.any() or fixed.all():
        return 0.0, 0.0
    low, high = atoms.positions[fixed].min(axis=0), atoms.positions[fixed].max(axis=0)
    free = atoms.positions[~fixed]
    beyond = np.maximum(low - free, 0.0) + np.maximum(free - high, 0.0)
    return float(np.linalg.norm(beyond, axis=1).max()), float(np.linalg.norm(high - low))


#: A net load counts as zero below this fraction of the sum of the loads'
#: sizes (their rounding).
NET_LOAD_RTOL = 1e-9


def held_directions(atoms: Atoms) -> np.ndarray:
    """Boolean (N, 3) mask of the directions of each atom that a FixAtoms or
    FixCartesian holds."""
    held = np.zeros((len(atoms), 3), dtype=bool)
    for c in atoms.constraints:
        if isinstance(c, FixAtoms):
            held[c.index] = True
        elif isinstance(c, FixCartesian):
            held[c.index] |= np.asarray(c.mask, dtype=bool)
    return held


def fixed_atoms(atoms: Atoms) -> np.ndarray:
    """Boolean mask of atoms held in all three directions by a constraint."""
    return held_directions(atoms).all(axis=1)


def free_point_loads(atoms: Atoms, load: Sequence[float]) -> np.ndarray:
    """Loads (N, 3): ``load`` (3 numbers, force units) on every point that
    no constraint holds in all three directions, 0 on the others."""
    load = check_each('loads', load, 'component')
    if load.shape != (3,):
        raise ValueError(f'a load on every free point needs 3 numbers (x y z), '
                         f'got shape {load.shape}')
    return np.where(fixed_atoms(atoms)[:, None], 0.0, load)


def net_load(atoms: Atoms, loads: np.ndarray | None, dim: int = 3) -> np.ndarray | None:
    """The sum of ``loads`` (N, 3) over the atoms in each of the first
    ``dim`` directions in which no constraint holds any atom (0 in the
    others), if it is not zero beyond :data:`NET_LOAD_RTOL`: then the scene
    has no equilibrium, it drifts. None if it is zero, if there are no loads,
    or if a constraint other than FixAtoms and FixCartesian could hold the
    scene."""
    if loads is None or any(not isinstance(c, (FixAtoms, FixCartesian))
                            for c in atoms.constraints):
        return None
    free = ~held_directions(atoms).any(axis=0)
    free[dim:] = False
    with np.errstate(over='ignore'):   # loads summing beyond float64: the calculator says
        total = np.where(free, loads.sum(axis=0), 0.0)
        scale = np.abs(loads).sum(axis=0)
    if np.all(np.abs(total) <= NET_LOAD_RTOL * scale):
        return None
    return total


def minimum_proved(atoms: Atoms, labels: np.ndarray, loads: np.ndarray | None,
                   dim: int = 3) -> bool:
    """True if the scene is proved to have a finite minimum (module
    docstring): every constraint a FixAtoms or FixCartesian, and either
    every spring component (``labels``: :func:`spring_components`) held
    along each of the first ``dim`` directions by one of its atoms, or one
    component whose loads sum to zero along the directions nothing holds
    (:func:`net_load`). False: not proved (which does not mean there is
    none)."""
    if any(not isinstance(c, (FixAtoms, FixCartesian)) for c in atoms.constraints):
        return False
    if labels.max(initial=0) == 0:
        return net_load(atoms, loads, dim) is None
    held = held_directions(atoms)[:, :dim]
    return all(held[labels == k].any(axis=0).all() for k in range(labels.max() + 1))


def describe_net_load(total: np.ndarray) -> str:
    """One sentence on a net load (:func:`net_load`) and what to do."""
    axes = ', '.join(axis for axis, value in zip('xyz', total, strict=True) if value)
    return (f'no finite equilibrium: nothing holds the scene along {axes} and its '
            f'loads sum to {np.array2string(total, precision=6)} there, so it '
            'drifts for ever; fix some points (FixAtoms, read_net(fixed=...), '
            '--fixed) or make the loads sum to zero')


def constrained_atoms(atoms: Atoms) -> np.ndarray:
    """Boolean mask of atoms touched by any constraint, in any direction.

    A constraint of a kind other than FixAtoms and FixCartesian marks the
    atoms its ``get_indices()`` names, or all atoms if it has no such method.
    """
    touched = np.zeros(len(atoms), dtype=bool)
    for c in atoms.constraints:
        try:
            touched[c.get_indices()] = True
        except (AttributeError, NotImplementedError):
            touched[:] = True
    return touched


def unbounded_components(atoms: Atoms, labels: np.ndarray,
                         dim: int = 3) -> list[list[int]]:
    """Components (lists of atom indices) proved to fly away for ever, of
    the spring components ``labels`` (:func:`spring_components`).

    Empty unless ``dim == 3`` and there are several spring components: then
    the components with no constrained atom (:func:`constrained_atoms`).
    """
    if dim != 3 or labels.max(initial=0) < 1:
        return []
    held = constrained_atoms(atoms)
    groups = [np.flatnonzero(labels == k) for k in range(labels.max() + 1)]
    return [g.tolist() for g in groups if not held[g].any()]


def describe_unbounded(components: Sequence[Sequence[int]], limit: int = 3) -> str:
    """One sentence naming the free components (the first few atoms each)."""
    shown = ['[' + ', '.join(map(str, g[:limit])) + (', ...' if len(g) > limit
                                                     else '') + ']'
             for g in components[:limit]]
    more = f' and {len(components) - limit} more' if len(components) > limit else ''
    return (f'no finite minimum: {len(components)} spring component(s) with '
            f'no fixed atom ({", ".join(shown)}{more}) repel the rest for '
            'ever; fix an atom in each or tie them together with springs')


def unsupported(atoms: Atoms, springs: np.ndarray, dim: int = 3) -> str | None:
    """Why the supports of ``atoms`` (its constraints) do not make the
    force-density equilibrium of ``springs`` ((K, 2) pairs) unique, in
    words, or None if they do: every spring component (a point without
    springs is one) must hold a point fixed in every direction of the first
    ``dim``, and no point may be held in some of them only (the z a
    ``dim=2`` net's points are held in does not count)."""
    directions = held_directions(atoms)[:, :dim]
    held = directions.all(axis=1)
    partly = np.flatnonzero(directions.any(axis=1) & ~held)
    if partly.size:
        return (f'point {partly[0]} is held in some directions only: the '
                'force-density solve takes supports held in every direction')
    components = spring_components(len(atoms), springs)
    supported = np.zeros(components.max(initial=-1) + 1, dtype=bool)
    supported[components[held]] = True
    loose = np.flatnonzero(~supported[components])
    if loose.size:
        return (f'point {loose[0]} is on a spring component with no support: its '
                'force-density equilibrium is not unique (fix a point of each component)')
    return None


#: ``a`` of a net read from a file that stores none, as a fraction of its
#: mean spring length (:func:`default_a`; benchmarks/a_rule.py measures it).
A_PER_MEAN_SPRING = 0.3


def default_a(atoms: Atoms, springs: np.ndarray) -> float:
    """``a`` of a net that comes without one (its supports set).

    ``0``, the force-density equilibrium of its springs and loads (the
    repulsion off: none of the out-of-balance of the members and loads is
    left to it), where the supports make that equilibrium unique
    (:func:`~ase_maud.physics.topology.unsupported`: a support held in every
    direction on every spring component). Else the repulsion is what holds
    the net and sets its spacing: :data:`A_PER_MEAN_SPRING` times its mean
    spring length, the largest fraction of 0.1, 0.2, 0.3, 0.4, 0.5, 0.7, 1
    with which each of ten compas sample nets (32 to 4900 points), its
    boundary (leaves) fixed, relaxes within the bounding box of its supports
    (docs/dev/bench/a_rule.md).

    Parameters
    ----------
    atoms : Atoms
        The net's points, with its supports as constraints.
    springs : ndarray of shape (K, 2)
        Its springs (0-based index pairs).

    Returns
    -------
    float
        ``a`` in the unit of the positions: 0, or
        :data:`A_PER_MEAN_SPRING` times the mean spring length.

    Raises
    ------
    ValueError
        A spring names a point beyond the last one.
    """
    if unsupported(atoms, springs) is None:
        return 0.0
    return A_PER_MEAN_SPRING * mean_spring_length(atoms.positions, springs)
