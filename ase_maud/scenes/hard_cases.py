"""Hard cases for the Maud optimiser: scenes that stress its numerics.

Every builder is ``builder(size=<default>, seed=0, a=1.0, Q=1.0)`` like those
of :mod:`ase_maud.scenes`, and returns an :class:`ase.Atoms` with a
:class:`MaudCalculator` attached and its constraints set. Several of these
scenes have no finite minimum on purpose. docs/hard_cases.md gives, for each,
what a run does and why; tests/optimize/test_hard_cases.py asserts it. Hard cases that
are plain scenes at extreme sizes or scales (long chains, large all-pairs
clusters, ``a`` and ``Q`` far from 1) are built with :func:`scenes.build`.
"""

from __future__ import annotations

import numpy as np
from ase import Atoms
from ase.constraints import FixCartesian

from ase_maud.calculator.maud_calculator import MaudCalculator
from ase_maud.physics.topology import fixed_atoms
from ase_maud.scenes.builders import (
    _ball,
    _count,
    _path,
    _scene,
    all_pairs,
    hanging_net,
    keep_on_plane,
    net3d,
    ring,
)

#: Start distance of the close pair, in units of ``a``.
CLOSE = 1e-8

#: Points in each cluster of :func:`islands` and :func:`anchored_islands`.
ISLAND = 6

#: Fixed points per cluster of :func:`anchored_islands`.
ANCHORS = 3

#: Points in the dense cluster of :func:`stiff_soft`.
DENSE = 10


def close_pair(size: int = 8, seed: int = 0, a: float = 1.0, Q: float = 1.0) -> Atoms:
    """:func:`scenes.all_pairs` with atom 1 moved to ``CLOSE * a`` from atom 0.

    The repulsion between the two is ``1e8`` times its usual size, their
    forces ``1e16`` times; the scene still has the minimum of the cluster.
    """
    atoms = all_pairs(size, seed, a, Q)
    u = np.random.default_rng(seed).normal(size=3)
    atoms.positions[1] = atoms.positions[0] + CLOSE * a * u / np.linalg.norm(u)
    return atoms


def no_springs(size: int = 10, seed: int = 0, a: float = 1.0, Q: float = 1.0) -> Atoms:
    """``size`` free points in a ball, no springs: no finite minimum."""
    n = _count(size, 2, 'no_springs')
    return _scene(_ball(np.random.default_rng(seed), n), [], a, Q)


def islands(size: int = 3, seed: int = 0, a: float = 1.0, Q: float = 1.0) -> Atoms:
    """``size`` all-pairs clusters of :data:`ISLAND` points, 3 a apart along x,
    nothing fixed: the clusters repel each other for ever (no finite
    minimum)."""
    return _islands(size, seed, a, Q, anchored=False)


def anchored_islands(size: int = 3, seed: int = 0, a: float = 1.0, Q: float = 1.0) -> Atoms:
    """:func:`islands` with the first :data:`ANCHORS` points of each cluster
    fixed: bounded, and (three points holding each cluster) well conditioned.
    With one fixed point each, a cluster turns about it held only by the far
    repulsion of the others: bounded, but very soft."""
    return _islands(size, seed, a, Q, anchored=True)


def _islands(size: int, seed: int, a: float, Q: float, anchored: bool) -> Atoms:
    n = _count(size, 2, 'islands')
    rng = np.random.default_rng(seed)
    positions = np.concatenate([_ball(rng, ISLAND) + [3.0 * k, 0, 0]
                                for k in range(n)])
    one = np.column_stack(np.triu_indices(ISLAND, 1))
    springs = np.concatenate([one + ISLAND * k for k in range(n)])
    fixed = (ISLAND * np.arange(n)[:, None] + np.arange(ANCHORS)).ravel()
    if not anchored:
        fixed = ()
    return _scene(positions, springs, a, Q, fixed=fixed)


def loose_point(size: int = 6, seed: int = 0, a: float = 1.0, Q: float = 1.0) -> Atoms:
    """:func:`scenes.hanging_net` with the springs of one interior point cut.

    That point has no spring: in 3D its block is traceless
    (``Tr K_mm = 0``), and by Earnshaw's theorem no arrangement of the other
    points holds it, so the scene has no finite minimum.
    """
    atoms = hanging_net(size, seed, a, Q)
    m = loose_index(size)
    springs = atoms.calc.springs
    atoms.calc = MaudCalculator(springs[(springs != m).all(axis=1)], a=a, Q=Q)
    return atoms


def loose_index(size: int) -> int:
    """Index of the cut point of :func:`loose_point`: the grid's middle."""
    return (size // 2) * size + size // 2


def bead(size: int = 8, seed: int = 0, a: float = 1.0, Q: float = 1.0) -> Atoms:
    """A point with no spring, confined to the plane of a fixed ring.

    ``size`` fixed points on a circle of radius a at z = 0 and one free point
    held at z = 0 by :class:`FixCartesian`, starting within 0.3 a of the
    centre. Its block is traceless (``Tr K_mm = 0``, zz stiffness negative)
    but its in-plane part is positive definite: the centre is the minimum.
    """
    n = _count(size, 3, 'bead')
    rng = np.random.default_rng(seed)
    angle = 2 * np.pi * np.arange(n) / n
    positions = np.zeros((n + 1, 3))
    positions[:n, :2] = np.column_stack([np.cos(angle), np.sin(angle)])
    positions[n, :2] = rng.uniform(-0.3, 0.3, 2)
    atoms = _scene(positions, [], a, Q, fixed=np.arange(n))
    atoms.set_constraint([*atoms.constraints,
                          FixCartesian(n, mask=[False, False, True])])
    return atoms


def ring_with_centre(size: int = 16, seed: int = 0, a: float = 1.0, Q: float = 1.0) -> Atoms:
    """:func:`scenes.ring` (dim=2) plus a free point with no spring inside it.

    In the plane 1/L is not harmonic: the ring holds the point, and the
    minimum is the round ring about it, radius
    ``R**3 = a**3 (S + 4) / (16 sin**2(pi/size))``,
    ``S = sum_k 1/sin(pi k/size)``. The point starts within a tenth of R of
    the ring's centre; nothing is fixed.
    """
    atoms = ring(size, seed, a, Q)
    rng = np.random.default_rng(seed)
    centre = atoms.positions.mean(axis=0)
    radius = np.linalg.norm(atoms.positions - centre, axis=1).mean()
    centre[:2] += rng.uniform(-0.1, 0.1, 2) * radius
    atoms.append('X')
    atoms.positions[-1] = centre
    return keep_on_plane(atoms)


def stiff_soft(size: int = 40, seed: int = 0, a: float = 1.0, Q: float = 1.0,
               dense: int = DENSE) -> Atoms:
    """A dense cluster on a long sparse chain: stiff and soft in one scene.

    An all-pairs cluster of ``dense`` points (default :data:`DENSE`: spring
    degree 9, spacing about 0.5 a) sits in the middle of a chain of ``size``
    points (degree 2, spacing about a) whose two ends are fixed. Starts: the
    cluster in a ball, each half of the chain straight along x from it, every
    chain coordinate moved by up to 0.3 a, the ends fixed where they start.
    """
    n = _count(size, 2, 'stiff_soft')
    rng = np.random.default_rng(seed)
    cluster = _ball(rng, dense)
    left, right = n // 2, n - n // 2
    line = np.zeros((n, 3))
    line[:left, 0] = cluster[:, 0].min() - np.arange(1, left + 1)
    line[left:, 0] = cluster[:, 0].max() + np.arange(1, right + 1)
    line += rng.uniform(-0.3, 0.3, line.shape)
    ends = [(int(np.argmin(cluster[:, 0])), dense),
            (int(np.argmax(cluster[:, 0])), dense + left)]
    springs = np.concatenate([np.column_stack(np.triu_indices(dense, 1)), ends,
                              dense + _path(left),
                              dense + left + _path(right)])
    return _scene(np.concatenate([cluster, line]), springs, a, Q,
                  fixed=[dense + left - 1, dense + n - 1])


def tangled_net(size: int = 6, seed: int = 0, a: float = 1.0, Q: float = 1.0) -> Atoms:
    """:func:`scenes.net3d`'s springs with every point drawn in a ball of one
    point per a**3: a tangle with many local minima. Nothing fixed."""
    atoms = net3d(size, seed, a, Q)
    rng = np.random.default_rng(seed)
    atoms.positions = a * _ball(rng, len(atoms))
    return atoms


def tangled_hanging_net(size: int = 6, seed: int = 0, a: float = 1.0, Q: float = 1.0) -> Atoms:
    """:func:`scenes.hanging_net` with its interior points drawn in a ball of
    one point per a**3 about the centre (the boundary stays fixed)."""
    atoms = hanging_net(size, seed, a, Q)
    free = np.flatnonzero(~fixed_atoms(atoms))
    atoms.positions[free] = a * _ball(np.random.default_rng(seed), len(free))
    return atoms


def heavy_net(size: int = 6, seed: int = 0, a: float = 1.0, Q: float = 1.0,
              load: float = 100.0) -> Atoms:
    """:func:`scenes.hanging_net` with ``load`` ``Q a`` pulling every point
    down (-z): its minimum lies far below the fixed boundary (at ``load`` =
    100 and size 6 the scene spreads to about 4.7 ``a N``), yet the fixed
    boundary proves it exists."""
    atoms = hanging_net(size, seed, a, Q)
    loads = np.zeros((len(atoms), 3))
    loads[:, 2] = -load * Q * a
    atoms.calc = MaudCalculator(atoms.calc.springs, a=a, Q=Q, loads=loads)
    return atoms


def flat_cluster(size: int = 8, seed: int = 0, a: float = 1.0, Q: float = 1.0) -> Atoms:
    """:func:`scenes.all_pairs` pressed onto the plane z = 0, in 3D (dim=3).

    By symmetry every z force vanishes, so the points stay on the plane and
    end at a planar stationary point: a saddle of the 3D energy.
    """
    atoms = all_pairs(size, seed, a, Q)
    atoms.positions[:, 2] = 0.0
    return atoms


HARD_CASES = {f.__name__: f for f in (close_pair, no_springs, islands,
                                      anchored_islands, loose_point, bead,
                                      ring_with_centre, stiff_soft,
                                      tangled_net, tangled_hanging_net,
                                      flat_cluster)}
