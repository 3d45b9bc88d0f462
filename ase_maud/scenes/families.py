"""Families of scenes drawn at random from a seed, for measurements nobody
tuned on: each draw picks its size (points, within ``sizes``), shape and
supports from its seed, so a method's constants are never set on the scenes
that judge it.

- :func:`sagging_net`: a rectangular net of a random aspect ratio (1 to 3)
  held on a random pattern (its four corners, its whole rim, two opposite
  edges, or three to eight points of its rim), sagging under a random
  self-weight on every free point.
- :func:`saddle_dome`: a square net whose rim is held on a saddle-shaped
  surface ``z = h (x**2 - y**2) / L**2`` (``h`` random), free inside: the
  repulsion buckles it.
- :func:`chord_ring`: a ring in the plane with chords from a random share
  (30 to 100 %) of its points to the point a random fraction (a sixth to a
  half) of the way round.
- :func:`knn_cluster`: points uniform in a ball, each tied to its 2 to 4
  nearest (drawn), the graph joined into one; nothing held.
- :func:`random_tree`: :func:`~ase_maud.scenes.builders.tree` of a random
  size.
- :func:`hub_net`: a polar cable net (rings and spokes, drawn) around a hub
  of one to twelve points, its outer ring held on a wave of a random height
  and order, under a random self-weight in half the draws (none in the
  others: the repulsion then sets its shape and crowds the points at the hub).

:data:`FAMILIES` holds them by name: ``draw(seed, sizes) -> Atoms``; every
scene has ``a = Q = 1`` and starts away from any symmetry (jittered).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from ase import Atoms
from ase.constraints import FixAtoms
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ase_maud.calculator.maud_calculator import MaudCalculator
from ase_maud.physics.dofs import keep_on_plane
from ase_maud.scenes.builders import tree

#: The default range of points a family draws from, ``[low, high]``.
SIZES = (300, 3000)
#: The support patterns of :func:`sagging_net`.
SUPPORTS = ('corners', 'rim', 'edges', 'points')


def _size(rng: np.random.Generator, sizes: tuple[int, int]) -> int:
    low, high = sizes
    if not 10 <= low <= high:
        raise ValueError(f'sizes must be two numbers of points 10 <= low <= high, got {sizes}')
    return int(rng.integers(low, high + 1))


def _grid(nx: int, ny: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Positions (nx ny, 3) of a unit grid at z = 0 centred on the origin,
    its springs between neighbours, and the grid index (nx, ny) of each point."""
    x, y = np.meshgrid(np.arange(nx) - (nx - 1) / 2, np.arange(ny) - (ny - 1) / 2,
                       indexing='ij')
    index = np.arange(nx * ny).reshape(nx, ny)
    springs = np.concatenate([np.column_stack([index[:, :-1].ravel(), index[:, 1:].ravel()]),
                              np.column_stack([index[:-1].ravel(), index[1:].ravel()])])
    positions = np.column_stack([x.ravel(), y.ravel(), np.zeros(nx * ny)])
    return positions, springs, index


def _scene(positions: np.ndarray, springs: np.ndarray, held: np.ndarray,
           loads: np.ndarray | None = None, dim: int = 3) -> Atoms:
    atoms = Atoms(positions=positions, pbc=False)
    atoms.calc = MaudCalculator(springs, dim=dim, loads=loads)
    if len(held):
        atoms.set_constraint(FixAtoms(np.unique(held)))
    if dim == 2:
        keep_on_plane(atoms)
    return atoms


def sagging_net(seed: int, sizes: tuple[int, int] = SIZES) -> Atoms:
    """A net of a random aspect ratio on random supports under self-weight
    (module docstring); free points moved by up to 0.2 a."""
    rng = np.random.default_rng(seed)
    n, aspect = _size(rng, sizes), rng.uniform(1.0, 3.0)
    nx = max(3, round(np.sqrt(n * aspect)))
    ny = max(3, round(n / nx))
    positions, springs, index = _grid(nx, ny)
    rim = np.unique(np.concatenate([index[0], index[-1], index[:, 0], index[:, -1]]))
    pattern = SUPPORTS[rng.integers(len(SUPPORTS))]
    held = {'corners': index[[0, 0, -1, -1], [0, -1, 0, -1]],
            'rim': rim,
            'edges': np.concatenate([index[0], index[-1]]),
            'points': rng.choice(rim, size=int(rng.integers(3, 9)), replace=False)}[pattern]
    free = np.setdiff1d(np.arange(len(positions)), held)
    positions[free] += rng.uniform(-0.2, 0.2, (len(free), 3))
    loads = np.zeros_like(positions)
    loads[free, 2] = -rng.uniform(0.01, 0.1)
    return _scene(positions, springs, held, loads)


def saddle_dome(seed: int, sizes: tuple[int, int] = SIZES) -> Atoms:
    """A square net with its rim held on ``z = h (x**2 - y**2) / L**2``
    (``h`` up to a quarter of the side ``L``), free points moved by up to
    0.2 a."""
    rng = np.random.default_rng(seed)
    side = max(4, round(np.sqrt(_size(rng, sizes))))
    positions, springs, index = _grid(side, side)
    half = (side - 1) / 2
    height = rng.uniform(0.05, 0.25) * side
    positions[:, 2] = height * (positions[:, 0]**2 - positions[:, 1]**2) / (2 * half) ** 2
    rim = np.unique(np.concatenate([index[0], index[-1], index[:, 0], index[:, -1]]))
    free = np.setdiff1d(np.arange(len(positions)), rim)
    positions[free] += rng.uniform(-0.2, 0.2, (len(free), 3))
    return _scene(positions, springs, rim)


def chord_ring(seed: int, sizes: tuple[int, int] = SIZES) -> Atoms:
    """A 2D ring of a random size with chords of a random density and reach
    (module docstring); every point moved by up to a fifth of the spacing."""
    rng = np.random.default_rng(seed)
    n = _size(rng, sizes)
    reach = int(rng.integers(max(2, n // 6), n // 2 + 1))
    share = rng.uniform(0.3, 1.0)
    radius = n / (2 * np.pi)
    phi = 2 * np.pi * np.arange(n) / n
    positions = np.column_stack([radius * np.cos(phi), radius * np.sin(phi), np.zeros(n)])
    positions[:, :2] += rng.uniform(-0.2, 0.2, (n, 2))
    start = np.flatnonzero(rng.uniform(size=n) < share)
    ring = np.column_stack([np.arange(n), (np.arange(n) + 1) % n])
    chords = np.column_stack([start, (start + reach) % n])
    springs = np.unique(np.sort(np.concatenate([ring, chords]), axis=1), axis=0)
    return _scene(positions, springs, np.array([], dtype=int), dim=2)


def knn_cluster(seed: int, sizes: tuple[int, int] = SIZES) -> Atoms:
    """Points uniform in a ball of one point per a**3, each tied to its k
    nearest (k drawn from 2 to 4), each other component tied to the largest
    by its nearest pair; nothing held."""
    rng = np.random.default_rng(seed)
    n, k = _size(rng, sizes), int(rng.integers(2, 5))
    radius = (3 * n / (4 * np.pi)) ** (1 / 3)
    direction = rng.normal(size=(n, 3))
    positions = (radius * rng.uniform(size=(n, 1)) ** (1 / 3) * direction
                 / np.linalg.norm(direction, axis=1, keepdims=True))
    near = cKDTree(positions).query(positions, k=k + 1)[1][:, 1:]
    springs = np.unique(np.sort(np.column_stack([np.repeat(np.arange(n), k), near.ravel()]),
                                axis=1), axis=0)
    labels = connected_components(coo_matrix((np.ones(len(springs)), springs.T),
                                             shape=(n, n)), directed=False)[1]
    largest = np.flatnonzero(labels == np.bincount(labels).argmax())
    to_largest = cKDTree(positions[largest])
    ties = []
    for label in set(labels.tolist()) - {labels[largest[0]]}:
        members = np.flatnonzero(labels == label)
        distance, nearest = to_largest.query(positions[members])
        i = int(np.argmin(distance))
        ties.append(sorted((int(members[i]), int(largest[nearest[i]]))))
    springs = np.concatenate([springs, np.array(ties, dtype=int).reshape(-1, 2)])
    return _scene(positions, springs, np.array([], dtype=int))


def random_tree(seed: int, sizes: tuple[int, int] = SIZES) -> Atoms:
    """:func:`~ase_maud.scenes.builders.tree` of a size drawn from ``sizes``."""
    rng = np.random.default_rng(seed)
    return tree(_size(rng, sizes), seed=int(rng.integers(2**31)))


def hub_net(seed: int, sizes: tuple[int, int] = SIZES) -> Atoms:
    """Rings of ``spokes`` points (about the square root of the size drawn,
    times 0.6 to 1.6, at least 8) a apart, the first at the radius where its
    points are a apart, around a hub of ``h`` points (1 to 12; a ring of them
    a apart, sprung around, for ``h`` > 1), each first-ring point sprung to
    the hub point nearest its angle; springs along the rings and spokes. The
    outer ring held on ``z = H cos(k phi)`` (``H`` up to 0.3 times the rings,
    ``k`` 0 to 3); in half the draws a self-weight (0.01 to 0.1) on every
    free point; free points moved by up to 0.2 a."""
    rng = np.random.default_rng(seed)
    n = _size(rng, sizes)
    spokes, hub = max(8, round(np.sqrt(n) * rng.uniform(0.6, 1.6))), int(rng.integers(1, 13))
    rings = max(2, (n - hub) // spokes)
    height, order = rng.uniform(0.0, 0.3) * rings, int(rng.integers(0, 4))
    weight = rng.uniform(0.01, 0.1) if rng.uniform() < 0.5 else 0.0
    phi = 2 * np.pi * np.arange(spokes) / spokes
    hub_radius = 0.5 / np.sin(np.pi / hub) if hub > 1 else 0.0   # hub points a apart
    radius = np.repeat(max(spokes / (2 * np.pi), hub_radius + 1) + np.arange(rings), spokes)
    angle = np.concatenate([2 * np.pi * np.arange(hub) / hub, np.tile(phi, rings)])
    radius = np.concatenate([np.full(hub, hub_radius), radius])
    positions = np.column_stack([radius * np.cos(angle), radius * np.sin(angle),
                                 np.zeros(len(angle))])
    index = hub + np.arange(rings * spokes).reshape(rings, spokes)
    around = (np.column_stack([np.arange(hub), (np.arange(hub) + 1) % hub]) if hub > 2
              else np.array([[0, 1]])[:hub - 1])   # h = 2: one spring; h = 1: none
    springs = np.concatenate([
        around, np.column_stack([np.round(phi / (2 * np.pi) * hub).astype(int) % hub, index[0]]),
        np.column_stack([index.ravel(), np.roll(index, -1, axis=1).ravel()]),
        np.column_stack([index[:-1].ravel(), index[1:].ravel()])])
    held = index[-1]
    positions[held, 2] = height * np.cos(order * phi)
    free = np.setdiff1d(np.arange(len(positions)), held)
    positions[free] += rng.uniform(-0.2, 0.2, (len(free), 3))
    loads = np.zeros_like(positions)
    loads[free, 2] = -weight
    return _scene(positions, springs, held, loads)


#: The families by name: ``draw(seed, sizes) -> Atoms``.
FAMILIES: dict[str, Callable[..., Atoms]] = {
    'sagging_net': sagging_net, 'saddle_dome': saddle_dome, 'chord_ring': chord_ring,
    'knn_cluster': knn_cluster, 'random_tree': random_tree, 'hub_net': hub_net}
