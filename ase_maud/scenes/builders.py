"""Scenes for the Maud potential: seeded starts with their springs and fixings.

Every builder is ``builder(size=<default>, seed=0, a=1.0, Q=1.0)`` and returns
an :class:`ase.Atoms` (``pbc=False``, no cell) with a :class:`MaudCalculator`
attached and the scene's fixed points held by
:class:`ase.constraints.FixAtoms`; the planar scenes (``dim=2``) also hold
every other point's z by :func:`keep_on_plane`, so that ASE's drivers
(BasinHopping, MD, NEB) keep them on their plane. Positions are drawn in units of ``a`` from
``numpy.random.default_rng(seed)`` and multiplied by ``a`` last, so one seed
gives the same shape at every ``a``. Starts are near the scale of the
equilibrium but not at it, and no two points start closer than
:data:`MIN_DISTANCE` ``a``.
"""

from __future__ import annotations

import numpy as np
from ase import Atoms
from ase.build import molecule as g2_molecule
from ase.collections import g2
from ase.constraints import FixAtoms
from ase.neighborlist import NeighborList, natural_cutoffs
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components, laplacian
from scipy.spatial import Delaunay, cKDTree

from ase_maud.calculator.maud_calculator import MaudCalculator
from ase_maud.checks import as_whole
from ase_maud.physics.dofs import keep_on_plane
from ase_maud.physics.topology import free_point_loads

#: Closest start of two points, in units of ``a``.
MIN_DISTANCE = 0.2
#: The load on each free point of :func:`weighted_net`, in units of ``a Q``.
WEIGHT = 0.5


def _scene(positions, springs, a, Q, dim=3, fixed=(), symbols=None):
    """Atoms at ``a * positions`` with the calculator and fixed indices set
    (and, for ``dim=2``, every point kept on its plane)."""
    calc = MaudCalculator(springs, a=a, Q=Q, dim=dim)   # checks a and Q first
    atoms = Atoms(symbols, positions=a * np.asarray(positions), pbc=False)
    atoms.calc = calc
    if len(fixed):
        atoms.set_constraint(FixAtoms(indices=fixed))
    if dim == 2:
        keep_on_plane(atoms)
    return atoms


def _count(size, least, scene):
    """``size`` as an int, or ValueError if it is not a whole number
    ``>= least``."""
    whole = as_whole(size)
    if whole is None or whole < least:
        raise ValueError(f'{scene} needs an integer size >= {least}, '
                         f'got {size!r}')
    return whole


def _path(n):
    """Springs (i, i+1) along n points."""
    return np.column_stack([np.arange(n - 1), np.arange(1, n)])


def _cycle(points):
    """Springs tying each of ``points`` to the next, the last to the first."""
    return np.column_stack([points, np.roll(points, -1)])


def _rim(rng, n, hub, dim):
    """n points on a circle in the plane z = 0, each coordinate of the first
    ``dim`` moved by up to a fifth of the spacing.

    The radius is the equilibrium of the perfect circle with springs between
    neighbours (and, if ``hub``, from each point to a hub at the centre),
    ``a = Q = 1``: ``R**3 = (S / 4 + h) / (4 sin(pi/n)**2 + h)``,
    ``S = sum_k 1 / sin(pi k / n)``, ``h = 1`` with the hub, else 0
    (design.md, section 2, for the ring).
    """
    s = np.sin(np.pi * np.arange(1, n) / n)
    h = float(hub)
    radius = ((np.sum(1 / s) / 4 + h) / (4 * s[0]**2 + h)) ** (1 / 3)
    phi = 2 * np.pi * np.arange(n) / n
    positions = radius * np.column_stack([np.cos(phi), np.sin(phi),
                                          np.zeros(n)])
    positions[:, :dim] += rng.uniform(-0.2, 0.2, (n, dim)) * 2 * radius * s[0]
    return positions


def _grid(n):
    """Unit n x n grid centred on the origin at z = 0.

    Returns positions (n*n, 3), the springs between grid neighbours and a
    boolean mask of the boundary points.
    """
    c = np.arange(n) - (n - 1) / 2
    x, y = np.meshgrid(c, c, indexing='ij')
    positions = np.column_stack([x.ravel(), y.ravel(), np.zeros(n * n)])
    idx = np.arange(n * n).reshape(n, n)
    springs = np.concatenate([
        np.column_stack([idx[:, :-1].ravel(), idx[:, 1:].ravel()]),
        np.column_stack([idx[:-1].ravel(), idx[1:].ravel()])])
    edge = np.zeros((n, n), dtype=bool)
    edge[[0, -1], :] = edge[:, [0, -1]] = True
    return positions, springs, edge.ravel()


def _ball(rng, n, dim=3):
    """n points uniform in the ball (dim 3) or disc (dim 2, z = 0) of one
    point per unit volume (area), redrawing any point closer than
    MIN_DISTANCE to an earlier one."""
    radius = {2: n / np.pi, 3: 3 * n / (4 * np.pi)}[dim] ** (1 / dim)

    def draw(m):
        v = rng.normal(size=(m, dim))
        r = radius * rng.uniform(size=(m, 1)) ** (1 / dim)
        positions = np.zeros((m, 3))
        positions[:, :dim] = r * v / np.linalg.norm(v, axis=1, keepdims=True)
        return positions

    return _separated(draw(n), lambda p: draw(len(p)))


def _jitter(rng):
    """A redraw for :func:`_separated`: each coordinate moved by up to
    MIN_DISTANCE."""
    return lambda p: p + rng.uniform(-MIN_DISTANCE, MIN_DISTANCE, p.shape)


def _separated(positions, redraw):
    """``positions`` with every point closer than MIN_DISTANCE to an earlier
    one replaced by ``redraw(its positions)``, until none is."""
    while True:
        pairs = cKDTree(positions).query_pairs(MIN_DISTANCE,
                                               output_type='ndarray')
        if not len(pairs):
            return positions
        close = np.unique(pairs[:, 1])
        positions[close] = redraw(positions[close])


def dimer(size: int = 2, seed: int = 0, a: float = 1.0, Q: float = 1.0) -> Atoms:
    """Two points tied by one spring: equilibrium length ``a``.

    ``size`` is ignored. Starts at a random orientation and a length between
    1.2 a and 2 a. Nothing fixed.
    """
    rng = np.random.default_rng(seed)
    d = rng.normal(size=3)
    d *= rng.uniform(1.2, 2.0) / np.linalg.norm(d)
    return _scene([-d / 2, d / 2], [(0, 1)], a, Q)


def ring(size: int = 24, seed: int = 0, a: float = 1.0, Q: float = 1.0) -> Atoms:
    """``size`` points on a plane (dim=2), each sprung to its two neighbours.

    Starts on the circle of the equilibrium radius (design.md, about
    size a / 4) with each coordinate moved in-plane by up to a fifth of the
    spacing. Nothing fixed.
    """
    n = _count(size, 3, 'ring')
    rng = np.random.default_rng(seed)
    return _scene(_rim(rng, n, hub=False, dim=2), _cycle(np.arange(n)), a, Q,
                  dim=2)


def chain(size: int = 30, seed: int = 0, a: float = 1.0, Q: float = 1.0) -> Atoms:
    """``size`` points in 3D sprung in a line, the ends fixed size a / 3 apart.

    Interior points start on the straight line, evenly spaced, then moved
    off it by up to 0.3 a in y and z; the repulsion buckles the chain.
    """
    n = _count(size, 3, 'chain')
    rng = np.random.default_rng(seed)
    positions = np.zeros((n, 3))
    positions[:, 0] = np.linspace(0, n / 3, n)
    positions[1:-1, 1:] = rng.uniform(-0.3, 0.3, (n - 2, 2))
    return _scene(positions, _path(n), a, Q, fixed=[0, n - 1])


def net2d(size: int = 8, seed: int = 0, a: float = 1.0, Q: float = 1.0) -> Atoms:
    """A size x size square net of spacing a on a plane (dim=2).

    Springs tie grid neighbours; the boundary points are fixed and the
    interior starts moved in-plane by up to 0.3 a per coordinate.
    """
    n = _count(size, 3, 'net2d')
    rng = np.random.default_rng(seed)
    positions, springs, edge = _grid(n)
    positions[~edge, :2] += rng.uniform(-0.3, 0.3, ((n - 2)**2, 2))
    return _scene(positions, springs, a, Q, dim=2, fixed=np.flatnonzero(edge))


def net3d(size: int = 6, seed: int = 0, a: float = 1.0, Q: float = 1.0) -> Atoms:
    """A free size x size square net in 3D, springs between grid neighbours.

    Starts flat at spacing a with every coordinate moved by up to 0.25 a.
    Nothing fixed: the springs hold the net together.
    """
    n = _count(size, 2, 'net3d')
    rng = np.random.default_rng(seed)
    positions, springs, _ = _grid(n)
    positions += rng.uniform(-0.25, 0.25, positions.shape)
    return _scene(positions, springs, a, Q)


def hanging_net(size: int = 8, seed: int = 0, a: float = 1.0, Q: float = 1.0) -> Atoms:
    """Form finding: a size x size net in 3D with its boundary on a saddle.

    Boundary points sit at spacing a on the hyperbolic paraboloid
    z = h (x**2 - y**2), h = 1 / (size a), so edge midpoints are about
    size a / 4 off the plane; they are fixed. Springs tie grid neighbours;
    the interior starts flat, each coordinate moved by up to 0.3 a.
    """
    n = _count(size, 3, 'hanging_net')
    rng = np.random.default_rng(seed)
    positions, springs, edge = _grid(n)
    x, y = positions[edge, 0], positions[edge, 1]
    positions[edge, 2] = (x**2 - y**2) / n
    positions[~edge] += rng.uniform(-0.3, 0.3, ((n - 2)**2, 3))
    return _scene(positions, springs, a, Q, fixed=np.flatnonzero(edge))


def weighted_net(size: int = 8, seed: int = 0, a: float = 1.0, Q: float = 1.0) -> Atoms:
    """:func:`hanging_net` under its weight: a load of :data:`WEIGHT` ``a Q``
    in -z on every free point (``loads``), so that it hangs below its
    saddle boundary; the default scene of ``ase-maud relax``."""
    atoms = hanging_net(size, seed, a, Q)
    atoms.calc.set(loads=free_point_loads(atoms, [0.0, 0.0, -WEIGHT * a * Q]))
    return atoms


def random_graph(size: int = 30, seed: int = 0, a: float = 1.0, Q: float = 1.0) -> Atoms:
    """``size`` points in 3D on a random connected spring graph.

    A random spanning tree (each point, in random order, tied to a random
    earlier one) plus random extra springs, about 1.5 size springs in all.
    Starts from the graph's spectral layout (the three lowest non-trivial
    eigenvectors of its Laplacian, scaled to a mean spring length of a), every
    coordinate moved by up to 0.1 a (and points closer than MIN_DISTANCE
    moved apart): untangled, so the start lies in one clear basin. Nothing
    fixed.
    """
    n = _count(size, 2, 'random_graph')
    rng = np.random.default_rng(seed)
    order = rng.permutation(n)
    parent = order[rng.integers(0, np.arange(1, n))]
    springs = {(min(i, j), max(i, j)) for i, j in zip(order[1:].tolist(),
                                                      parent.tolist(), strict=True)}
    while len(springs) < min(round(1.5 * n), n * (n - 1) // 2):
        i, j = sorted(rng.choice(n, 2, replace=False).tolist())
        springs.add((i, j))
    springs = np.array(sorted(springs))
    return _scene(_spectral_layout(springs, n, rng), springs, a, Q)


def _spectral_layout(springs, n, rng):
    """Spectral layout of a connected graph, mean edge length 1, jittered,
    points closer than MIN_DISTANCE pushed apart at random."""
    lap = laplacian(coo_matrix((np.ones(len(springs)), springs.T),
                               shape=(n, n)), symmetrized=True).toarray()
    vectors = np.linalg.eigh(lap)[1][:, 1:4]
    positions = np.zeros((n, 3))
    positions[:, :vectors.shape[1]] = vectors
    edge = positions[springs[:, 0]] - positions[springs[:, 1]]
    positions /= np.linalg.norm(edge, axis=1).mean()
    positions += rng.uniform(-0.1, 0.1, positions.shape)
    return _separated(positions, _jitter(rng))


def all_pairs(size: int = 10, seed: int = 0, a: float = 1.0, Q: float = 1.0) -> Atoms:
    """A cluster of ``size`` points in 3D with every pair sprung.

    Starts uniform in a ball of one point per a**3. Nothing fixed.
    """
    n = _count(size, 2, 'all_pairs')
    rng = np.random.default_rng(seed)
    springs = np.column_stack(np.triu_indices(n, 1))
    return _scene(_ball(rng, n), springs, a, Q)


def all_pairs2d(size: int = 10, seed: int = 0, a: float = 1.0, Q: float = 1.0) -> Atoms:
    """A cluster of ``size`` points on a plane (dim=2) with every pair sprung.

    Starts uniform in a disc of one point per a**2. Nothing fixed.
    """
    n = _count(size, 2, 'all_pairs2d')
    rng = np.random.default_rng(seed)
    springs = np.column_stack(np.triu_indices(n, 1))
    return _scene(_ball(rng, n, dim=2), springs, a, Q, dim=2)


def tree(size: int = 30, seed: int = 0, a: float = 1.0, Q: float = 1.0) -> Atoms:
    """``size`` points in 3D on a random spring tree, the root (point 0)
    fixed.

    Point i > 0 hangs from point i - 1 with probability 1/2 (the branch
    grows), else from a random earlier point (a new branch), so the tree has
    long branches whose bending is collective. Each point starts a unit
    distance from its parent in a random direction (points closer than
    MIN_DISTANCE moved apart at random): a crumpled tree that the repulsion
    unfolds.
    """
    n = _count(size, 2, 'tree')
    rng = np.random.default_rng(seed)
    parents = np.zeros(n, dtype=int)
    positions = np.zeros((n, 3))
    for i in range(1, n):
        parents[i] = i - 1 if rng.uniform() < 0.5 else rng.integers(i)
        step = rng.normal(size=3)
        positions[i] = positions[parents[i]] + step / np.linalg.norm(step)
    springs = np.column_stack([parents[1:], np.arange(1, n)])
    return _scene(_separated(positions, _jitter(rng)), springs, a, Q,
                  fixed=[0])


def wheel(size: int = 16, seed: int = 0, a: float = 1.0, Q: float = 1.0) -> Atoms:
    """A hub (point 0) sprung to each of ``size`` rim points in 3D, each rim
    point also sprung to its two rim neighbours.

    The hub starts at the origin and the rim on the circle of the planar
    equilibrium radius in z = 0 (see :func:`_rim`), every rim coordinate
    moved by up to a fifth of the spacing. Nothing fixed. The spokes crowd
    the rim (planar spacing 0.76 a at 16 rim points, 0.27 a at 100), which
    buckles out of the plane: large wheels have many nearby minima.
    """
    n = _count(size, 3, 'wheel')
    rng = np.random.default_rng(seed)
    rim = np.arange(1, n + 1)
    springs = np.concatenate([np.column_stack([np.zeros(n, dtype=int), rim]),
                              _cycle(rim)])
    positions = np.concatenate([np.zeros((1, 3)),
                                _rim(rng, n, hub=True, dim=3)])
    return _scene(positions, springs, a, Q)


def molecule(size: str = 'C6H6', seed: int = 0, a: float = 1.0, Q: float = 1.0) -> Atoms:
    """The bond graph of a molecule from ``ase.build.molecule``.

    ``size`` is the molecule's name (any of ``ase.collections.g2`` with two
    atoms or more). Bonds are ASE's: ``NeighborList`` on ``natural_cutoffs``.
    Positions are scaled so that the mean bond length is a, then each
    coordinate is moved by up to 0.1 a. Nothing fixed.
    """
    if size not in g2.names:
        raise ValueError(f'molecule needs the name of a molecule of '
                         f"ase.collections.g2 (such as 'C6H6' or 'H2O'), got {size!r}")
    mol = g2_molecule(size)
    if len(mol) < 2:
        raise ValueError(f'molecule {size!r} has a single atom: no springs')
    rng = np.random.default_rng(seed)
    nl = NeighborList(natural_cutoffs(mol), self_interaction=False,
                      bothways=False)
    nl.update(mol)
    bonds = nl.get_connectivity_matrix().tocoo()
    springs = np.column_stack([bonds.row, bonds.col])
    positions = mol.positions
    bond = positions[bonds.row] - positions[bonds.col]
    positions = positions / np.linalg.norm(bond, axis=1).mean()
    positions += rng.uniform(-0.1, 0.1, positions.shape)
    return _scene(positions, springs, a, Q, symbols=mol.symbols)


def cage(size: int = 8, seed: int = 0, a: float = 1.0, Q: float = 1.0) -> Atoms:
    """A known saddle: one free point inside a fixed ring, on its axis.

    ``size`` fixed points on a circle of radius a in the plane z = 0, two
    fixed anchors on the axis at z = +-2a, and a free point sprung to both
    anchors. The centre is a stationary point of index 1 for size >= 4: stable
    in the plane, unstable along the axis (zz stiffness
    ``Q (2 - size + 1/2)`` at a = Q = 1); the minima lie on the axis on either
    side. The free point starts within 0.05 a of the centre.
    """
    n = _count(size, 3, 'cage')
    rng = np.random.default_rng(seed)
    angle = 2 * np.pi * np.arange(n) / n
    ring_points = np.column_stack([np.cos(angle), np.sin(angle), np.zeros(n)])
    anchors = [[0, 0, 2.0], [0, 0, -2.0]]
    free = rng.uniform(-0.05, 0.05, (1, 3))
    positions = np.concatenate([ring_points, anchors, free])
    springs = [(n + 2, n), (n + 2, n + 1)]
    return _scene(positions, springs, a, Q, fixed=np.arange(n + 2))


def hub_net(size: int = 48, seed: int = 0, a: float = 1.0, Q: float = 1.0) -> Atoms:
    """A cable net with a hub: ``size`` rings of ``size + 2`` points around a
    centre point, springs along the rings and along the spokes (the centre
    sprung to the first ring), the outer ring fixed on a wave ``z = 0.2 size
    cos(2 phi)``.

    The rings start a apart in the plane z = 0, the first at the radius where
    its points are a apart, every free coordinate moved by up to 0.3 a (none
    closer than MIN_DISTANCE); ``size`` 48 gives 2401 points. The hub gathers
    ``size + 2`` spokes: stiff there, soft at the rim.
    """
    rings = _count(size, 2, 'hub_net')
    spokes = rings + 2
    rng = np.random.default_rng(seed)
    phi = 2 * np.pi * np.arange(spokes) / spokes
    first = spokes / (2 * np.pi)
    radius = np.repeat(first + np.arange(rings), spokes)
    angle = np.tile(phi, rings)
    positions = np.zeros((1 + rings * spokes, 3))
    positions[1:, 0], positions[1:, 1] = radius * np.cos(angle), radius * np.sin(angle)
    index = 1 + np.arange(rings * spokes).reshape(rings, spokes)
    springs = np.concatenate([
        np.column_stack([np.zeros(spokes, dtype=int), index[0]]),
        np.column_stack([index.ravel(), np.roll(index, -1, axis=1).ravel()]),
        np.column_stack([index[:-1].ravel(), index[1:].ravel()])])
    fixed = index[-1]
    positions[fixed, 2] = 0.2 * rings * np.cos(2 * phi)
    free = np.setdiff1d(np.arange(len(positions)), fixed)
    positions[free] += rng.uniform(-0.3, 0.3, (len(free), 3))
    return _scene(_separated(positions, _jitter(rng)), springs, a, Q, fixed=fixed)


def disc(size: int = 3000, seed: int = 0, a: float = 1.0, Q: float = 1.0) -> Atoms:
    """A membrane: ``size`` points in a disc of one point per a**2, sprung
    along the edges of their Delaunay triangulation, the boundary circle
    fixed on a wave ``z = 0.15 R sin(3 phi)``.

    The boundary holds ``2 pi R`` points at spacing a (R the disc's radius);
    the interior points are drawn uniformly (none closer than MIN_DISTANCE),
    flat, each z moved by up to 0.3 a.
    """
    n = _count(size, 13, 'disc')   # the rim takes 2 pi R points: 12 of 12, 0 free
    rng = np.random.default_rng(seed)
    radius = np.sqrt(n / np.pi)
    rim = max(int(2 * np.pi * radius), 3)
    phi = 2 * np.pi * np.arange(rim) / rim
    boundary = np.column_stack([radius * np.cos(phi), radius * np.sin(phi), np.zeros(rim)])
    inner = _ball(rng, n - rim, dim=2) * (radius - 0.5) / radius
    positions = np.concatenate([boundary, inner])
    positions[:rim, 2] = 0.15 * radius * np.sin(3 * phi)
    positions[rim:, 2] = rng.uniform(-0.3, 0.3, n - rim)
    triangles = Delaunay(positions[:, :2]).simplices
    edges = np.sort(np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]],
                                    triangles[:, [0, 2]]]), axis=1)
    return _scene(positions, np.unique(edges, axis=0), a, Q, fixed=np.arange(rim))


def neighbour_graph(size: int = 2000, seed: int = 0, a: float = 1.0,
                    Q: float = 1.0) -> Atoms:
    """``size`` points uniform in a ball of one point per a**3, each sprung to
    its 3 nearest neighbours (the graph made connected by tying each other
    component's point nearest to the largest one to its nearest point
    there). Nothing fixed: the repulsion blows the ball up to many times its
    start size, the springs hold it: the repulsion dominates.
    """
    n = _count(size, 5, 'neighbour_graph')
    rng = np.random.default_rng(seed)
    positions = _ball(rng, n)
    near = cKDTree(positions).query(positions, k=4)[1][:, 1:]
    springs = np.unique(np.sort(np.column_stack([np.repeat(np.arange(n), 3),
                                                 near.ravel()]), axis=1), axis=0)
    labels = connected_components(coo_matrix((np.ones(len(springs)), springs.T),
                                             shape=(n, n)), directed=False)[1]
    largest = np.flatnonzero(labels == np.bincount(labels).argmax())
    tree = cKDTree(positions[largest])
    ties = []
    for label in set(labels.tolist()) - {labels[largest[0]]}:
        members = np.flatnonzero(labels == label)
        distance, nearest = tree.query(positions[members])
        k = int(np.argmin(distance))
        ties.append(sorted((int(members[k]), int(largest[nearest[k]]))))
    springs = np.concatenate([springs, np.array(ties, dtype=int).reshape(-1, 2)])
    return _scene(positions, springs, a, Q)


