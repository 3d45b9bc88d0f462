"""Topology (ase_maud.physics.topology): a mesh's boundary and a network's
leaves (the supports by rule), how far a form strays beyond its supports, the
spring components and the proof of a minimum that needs every one held."""

import numpy as np
import pytest
from ase import Atoms
from ase.constraints import FixAtoms, FixCartesian, FixedPlane
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from ase_maud.physics.topology import (
    boundary_vertices,
    leaf_vertices,
    minimum_proved,
    spring_components,
    support_excursion,
)
from ase_maud.scenes.builders import chain


def test_the_proof_needs_every_component_held():
    atoms = chain(6, seed=0)   # ends fixed: proved
    springs, loads = atoms.calc.springs, np.ones((6, 3))

    def proved(springs, loads):
        return minimum_proved(atoms, spring_components(6, springs), loads)

    assert proved(springs, loads)
    assert proved(springs[1:], loads)   # [0] and [1..5]: each held
    assert not proved(springs[1:-1], loads)   # [1..4] free
    atoms.set_constraint(FixCartesian([1, 2, 3], [True, False, False]))
    assert not proved(springs, loads)   # y and z unheld, loads there
    assert proved(springs, loads * [1, 0, 0])   # ... unless balanced
    atoms.set_constraint([FixAtoms([0]), FixedPlane(1, [0, 0, 1])])
    assert not proved(springs, None)   # not a FixAtoms nor FixCartesian


@pytest.mark.parametrize('seed', range(5))
def test_spring_components_are_the_graphs_components(seed):
    """Two atoms share a label exactly when a path of springs joins them
    (checked by merging labels spring by spring), springs in any order,
    isolated atoms alone."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 40))
    pairs = rng.integers(0, n, size=(int(rng.integers(0, 2 * n)), 2))
    springs = pairs[pairs[:, 0] != pairs[:, 1]]
    labels = spring_components(n, springs)
    group = np.arange(n)
    for i, j in springs:   # the closure, slowly
        group[group == group[j]] = group[i]
    same = labels[:, None] == labels[None, :]
    np.testing.assert_array_equal(same, group[:, None] == group[None, :])


@pytest.mark.parametrize('seed', range(12))
def test_spring_components_are_scipys_labels(seed):
    """The compiled union-find labels the atoms as SciPy's
    ``connected_components(directed=False)`` does (int32, the components
    numbered in the order of their lowest atom), springs in any order and
    orientation: pairs repeated both ways, atoms tied to themselves, atoms
    on no spring, no springs, and the chains of the proof's test above."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 60))
    pairs = rng.integers(0, n, size=(int(rng.integers(0, 2 * n)), 2))
    chain_springs = chain(6, seed=seed).calc.springs
    cases = [(n, pairs), (n, np.concatenate([pairs, pairs[::2, ::-1], pairs[:3]])),
             (n, np.concatenate([pairs, np.repeat(rng.integers(0, n, (3, 1)), 2, axis=1)])),
             (n, np.zeros((0, 2), int)), (6, chain_springs), (6, chain_springs[1:]),
             (6, chain_springs[1:-1][::-1, ::-1])]
    for natoms, springs in cases:
        labels = spring_components(natoms, springs)
        graph = coo_matrix((np.ones(len(springs)), (springs[:, 0], springs[:, 1])),
                           shape=(natoms, natoms))
        expected = connected_components(graph, directed=False)[1]
        assert labels.dtype == expected.dtype
        np.testing.assert_array_equal(labels, expected)
        first = np.unique(labels, return_index=True)[1]
        assert np.all(np.diff(first) > 0)   # numbered by their lowest atom


def test_spring_components_name_a_spring_out_of_range():
    with pytest.raises(ValueError, match=r'spring 1 \(2, 5\) names an atom beyond'):
        spring_components(5, [[0, 1], [2, 5]])
    with pytest.raises(ValueError, match=r'spring 0 \(-1, 2\) has a negative'):
        spring_components(5, [[-1, 2]])

HAND_CHECKED = [
    ([[0, 1, 2], [0, 2, 3]], [0, 1, 2, 3]),                          # two triangles
    ([[0, 1, 2], [2, 1, 0]], []),                                    # both sides: closed
    ([[0, 1, 2], [0, 3, 1], [1, 3, 2], [0, 2, 3]], []),              # a tetrahedron
    ([[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 1]], [1, 2, 3, 4]),    # a fan about 0
    ([[0, 1, 2], [0, 1, 3], [0, 1, 4]], [0, 1, 2, 3, 4]),            # edge 0-1 of 3 faces
    ([[0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [4, 5, 9, 8], [6, 7, 11, 10],
      [8, 9, 13, 12], [9, 10, 14, 13], [10, 11, 15, 14]],             # 3 x 3 quads, one
     [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15]),        # missing: a hole
    ([[0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [4, 5, 9, 8], [5, 6, 10, 9],
      [6, 7, 11, 10], [8, 9, 13, 12], [9, 10, 14, 13], [10, 11, 15, 14]],
     [0, 1, 2, 3, 4, 7, 8, 11, 12, 13, 14, 15]),                     # 3 x 3 quads
]


@pytest.mark.parametrize('faces, boundary', HAND_CHECKED)
def test_boundary_of_hand_checked_meshes(faces, boundary):
    assert boundary_vertices(faces).tolist() == boundary


def random_grid(seed):
    """An n x m grid of quads, some faces missing, every face with a random
    orientation and starting corner, in random order; and its boundary by
    counting, for each edge, the faces present beside it."""
    rng = np.random.default_rng(seed)
    n, m = rng.integers(2, 9, size=2)
    index = np.arange((n + 1) * (m + 1)).reshape(n + 1, m + 1)
    present = rng.random((n, m)) > 0.15
    faces = []
    for i, j in zip(*np.nonzero(present), strict=True):
        ring = [index[i, j], index[i + 1, j], index[i + 1, j + 1], index[i, j + 1]]
        ring = np.roll(ring[::rng.choice([-1, 1])], rng.integers(4)).tolist()
        faces.append(ring)
    faces = [faces[k] for k in rng.permutation(len(faces))]
    padded = np.pad(present, 1)   # face (i, j) at padded (i + 1, j + 1)
    boundary = set()
    for i in range(n + 1):
        for j in range(m + 1):
            if j < m:   # the edge (i, j)-(i, j+1), between faces (i-1, j) and (i, j)
                if padded[i, j + 1] != padded[i + 1, j + 1]:
                    boundary |= {index[i, j], index[i, j + 1]}
            if i < n:   # the edge (i, j)-(i+1, j), between faces (i, j-1) and (i, j)
                if padded[i + 1, j] != padded[i + 1, j + 1]:
                    boundary |= {index[i, j], index[i + 1, j]}
    return faces, sorted(int(k) for k in boundary)


@pytest.mark.parametrize('seed', range(6))
def test_boundary_of_random_grids(seed):
    faces, boundary = random_grid(seed)
    assert boundary_vertices(faces).tolist() == boundary


@pytest.mark.parametrize('seed', range(4))
def test_leaves_of_random_trees(seed):
    """Point k > 0 hangs from a random parent before it: the leaves are the
    points no one hangs from, and 0 if one point hangs from it."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 40))
    parents = [int(rng.integers(k)) for k in range(1, n)]
    springs = np.array([(p, k) for k, p in enumerate(parents, 1)])
    springs = springs[rng.permutation(len(springs))]
    leaves = {k for k in range(1, n) if k not in parents} | (
        {0} if parents.count(0) == 1 else set())
    assert leaf_vertices(n, springs).tolist() == sorted(leaves)


def test_leaves_of_hand_checked_networks():
    assert leaf_vertices(6, [[0, 1], [0, 2], [0, 3], [3, 4]]).tolist() == [1, 2, 4]
    assert leaf_vertices(4, [[0, 1], [1, 2], [2, 0]]).tolist() == []   # 3: no spring


@pytest.mark.parametrize('seed', range(4))
def test_support_excursion_against_clipping(seed):
    """The distance of each free point to the nearest point of the fixed
    points' box is its distance to its own coordinates clipped to the box."""
    rng = np.random.default_rng(seed)
    atoms = Atoms(positions=rng.normal(size=(30, 3)) * [1, 2, 0.5])
    fixed = rng.choice(30, 8, replace=False)
    atoms.set_constraint(FixAtoms(indices=fixed))
    low, high = atoms.positions[fixed].min(axis=0), atoms.positions[fixed].max(axis=0)
    free = np.delete(atoms.positions, fixed, axis=0)
    distance = np.linalg.norm(free - np.clip(free, low, high), axis=1).max()
    assert support_excursion(atoms) == pytest.approx(
        (distance, np.linalg.norm(high - low)), rel=1e-14)
    atoms.set_constraint()
    assert support_excursion(atoms) == (0.0, 0.0)


def test_support_excursion_by_hand():
    atoms = Atoms(positions=[[0, 0, 0], [1, 1, 1], [0.5, 0.5, 0.5], [2, 0.5, -1]])
    atoms.set_constraint(FixAtoms(indices=[0, 1]))
    assert support_excursion(atoms) == pytest.approx((2 ** 0.5, 3 ** 0.5), rel=1e-15)
