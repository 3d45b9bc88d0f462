"""Classification of stationary points: known verdicts, both solvers, H v."""

import itertools

import numpy as np
import pytest
from ase import Atoms
from ase.constraints import FixAtoms, FixCartesian, FixedPlane
from ase.optimize import BFGS
from scipy.optimize import brentq

from ase_maud.analysis import stationary as analysis
from ase_maud.analysis.stationary import (
    classify,
    displace_along_mode,
    free_mask,
    near_field_stiffness,
    rigid_body_modes,
)
from ase_maud.calculator.maud_calculator import MaudCalculator
from ase_maud.calculator.potential import MaudPotential
from ase_maud.counting import Work
from ase_maud.physics import pair_law as physics


def scene(positions, springs, dim=3, a=1.0, Q=1.0):
    atoms = Atoms(f'X{len(positions)}', positions=positions)
    atoms.calc = MaudCalculator(springs=springs, a=a, Q=Q, dim=dim)
    return atoms


def relaxed(atoms, fmax=1e-8):
    assert BFGS(atoms, logfile=None).run(fmax=fmax, steps=5000)
    return atoms


def ring(n, dim):
    """The relaxed ring of n points, a = Q = 1 (radius from design.md)."""
    s = np.sin(np.pi * np.arange(1, n) / n)
    radius = (np.sum(1 / s) / (16 * s[0]**2)) ** (1 / 3)
    phi = 2 * np.pi * np.arange(n) / n
    positions = radius * np.column_stack([np.cos(phi), np.sin(phi), 0 * phi])
    return scene(positions, [(i, (i + 1) % n) for i in range(n)], dim)


def chorded_ring(random_points, n, seed, dim, chord=5):
    """n random points sprung along a ring and by chords i -> i + chord."""
    springs = [(i, (i + s) % n) for i in range(n) for s in (1, chord)]
    return scene(2 * random_points(n, dim, seed), springs, dim)


def pair_energy_derivatives(L, a=1.0, Q=1.0):
    """f, f' of the sprung pair energy f(L) = a^3 Q / L + Q L^2 / 2."""
    c = a**3 * Q
    return c / L + Q * L**2 / 2, -c / L**2 + Q * L


@pytest.mark.parametrize('dim', [2, 3])
@pytest.mark.parametrize('seed', [0, 1])
def test_hessian_vector_product_matches_dense(random_points, dim, seed):
    n = 30
    positions = random_points(n, dim, seed)
    springs = np.array([(i, (i + 3) % n) for i in range(n)])
    hessian = MaudPotential(springs, 1.3, 0.7, dim).hessian(positions)
    v = np.random.default_rng(seed).standard_normal((4, n, dim))
    hv = MaudPotential(springs, 1.3, 0.7, dim).hvp(positions, v)
    expected = (v.reshape(4, -1) @ hessian).reshape(v.shape)
    np.testing.assert_allclose(hv, expected,
                               atol=1e-12 * np.abs(hessian).max())
    single = MaudPotential(springs, 1.3, 0.7, dim).hvp(positions, v[0])
    np.testing.assert_allclose(single, hv[0], rtol=1e-13, atol=1e-13)


@pytest.mark.parametrize('dim', [2, 3])
@pytest.mark.parametrize('seed', [0, 1])
def test_hessian_vector_product_matches_physics(random_points, dim, seed):
    """(H v)_i = sum_j B_ij (v_i - v_j), with the pair blocks of physics."""
    n = 25
    positions = random_points(n, dim, seed)[:, :dim]
    springs = np.array([(i, (i + 4) % n) for i in range(n)])
    v = np.random.default_rng(seed).standard_normal((3, n, dim))
    hv = MaudPotential(springs, 1.3, 0.7, dim).hvp(positions, v)
    i, j = np.nonzero(~np.eye(n, dtype=bool))
    blocks = 1.3**3 * 0.7 * physics.repulsion_block(positions[i]
                                                    - positions[j])
    expected = np.zeros_like(v)
    for k in range(len(v)):
        np.add.at(expected[k], i,
                  np.einsum('pab,pb->pa', blocks, v[k, i] - v[k, j]))
    sprung = physics.spring_hessian(springs, n, 0.7, dim)
    expected += (sprung @ v.reshape(3, -1).T).T.reshape(v.shape)
    np.testing.assert_allclose(hv, expected, rtol=0,
                               atol=1e-12 * np.abs(expected).max())


@pytest.mark.parametrize('dim', [2, 3])
def test_near_field_is_the_hessian_when_every_block_is_positive(
        random_points, dim):
    """Every pair sprung and longer than a: each pair block
    c (3 n n^T - I) / L^3 + Q I is positive, so |B| = B and the near field,
    holding every pair, is the Hessian itself."""
    n = 7
    atoms = scene(3 * random_points(n, dim, seed=3),
                  list(itertools.combinations(range(n), 2)), dim, a=1.1,
                  Q=0.8)
    near = near_field_stiffness(atoms, cutoff=100.0)
    hessian = atoms.calc.get_hessian(atoms)
    assert near.shape == hessian.shape
    np.testing.assert_allclose(near.toarray(), hessian, rtol=0,
                               atol=1e-13 * np.abs(hessian).max())


@pytest.mark.parametrize('n', [5, 12, 30])
def test_ring_in_plane_is_minimum(n):
    point = classify(ring(n, dim=2))
    assert point.stationary and point.verdict == 'minimum'
    assert (point.n_rigid, point.n_zero, point.n_modes) == (3, 0, 2 * n - 3)
    largest = np.abs(point.eigenvalues).max()
    assert point.tolerance == pytest.approx(1e-8 * largest)


@pytest.mark.parametrize('n', [5, 12, 30])
def test_ring_in_3d_is_stable_out_of_plane(n):
    """Out of plane the Hessian is circulant: for k = 2 .. n-2,
    lambda_k = sum_j w_j (1 - cos(2 pi k j / n)), w_j = Q [j = +-1] - c / L_j^3
    (k = 0, +-1 are the z translation and the two tilts, zero by balance)."""
    in_plane = classify(ring(n, dim=2)).eigenvalues
    atoms = ring(n, dim=3)
    j = np.arange(1, n)
    lengths = np.linalg.norm(atoms.positions[j] - atoms.positions[0], axis=1)
    w = -1 / lengths**3 + np.isin(j, [1, n - 1])
    k = np.arange(2, n - 1)
    out = (w * (1 - np.cos(2 * np.pi * np.outer(k, j) / n))).sum(axis=1)
    assert np.all(out > 0)
    point = classify(atoms)
    assert point.verdict == 'minimum' and point.n_rigid == 6
    np.testing.assert_allclose(point.eigenvalues,
                               np.sort(np.concatenate([in_plane, out])),
                               atol=1e-10)


@pytest.mark.parametrize('size', [3, 4])
def test_flat_net_in_3d_is_stable_out_of_plane(size):
    """On a plane z decouples: H_zz is the Laplacian with weights
    w_ij = Q [sprung] - c / L^3, and the in-plane balance
    sum_j w_ij (r_i - r_j) = 0
    makes 1, x and y its null vectors (the rigid z modes)."""
    ij = np.array(list(itertools.product(range(size), repeat=2)))
    index = {tuple(p): k for k, p in enumerate(ij)}
    springs = [(index[tuple(p)], index[tuple(p + e)]) for p in ij
               for e in ((1, 0), (0, 1)) if tuple(p + e) in index]
    flat = relaxed(scene(np.column_stack([ij, np.zeros(len(ij))]), springs,
                         dim=2))
    in_plane = classify(flat).eigenvalues
    atoms = scene(flat.positions, springs, dim=3)
    h_zz = atoms.calc.get_hessian(atoms)[2::3, 2::3]
    null = np.column_stack([np.ones(len(ij)), atoms.positions[:, :2]])
    assert np.abs(h_zz @ null).max() < 1e-7
    out = np.linalg.eigvalsh(h_zz)[3:]
    point = classify(atoms)
    assert point.verdict == 'minimum' and np.all(out > point.tolerance)
    np.testing.assert_allclose(point.eigenvalues,
                               np.sort(np.concatenate([in_plane, out])),
                               atol=1e-9)


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_relaxed_all_pairs_cluster_is_minimum(random_points, seed):
    n = 6
    atoms = relaxed(scene(random_points(n, 3, seed),
                          list(itertools.combinations(range(n), 2))))
    point = classify(atoms)
    assert point.verdict == 'minimum' and point.stationary
    assert (point.n_rigid, point.n_zero, point.n_modes) == (6, 0, 3 * n - 6)
    rigid = rigid_body_modes(atoms.positions, free_mask(atoms, 3), 3)
    curvature = rigid.T @ atoms.calc.get_hessian(atoms) @ rigid
    assert np.abs(curvature).max() < point.tolerance
    assert point.eigenvalues[0] > 1e3 * point.tolerance


def test_square_of_four_is_a_saddle_between_tetrahedra():
    """Four points, all pairs sprung: the flat square (side s with
    4 f'(s) + 2 sqrt(2) f'(sqrt(2) s) = 0) has one unstable mode, corners
    alternately up and down, lambda = 4 f'(s) / s; both ways lead to the
    regular tetrahedron of side a, energy 6 f(a)."""
    def slope(L):
        return pair_energy_derivatives(L)[1]

    s = brentq(lambda s: 4 * slope(s) + 2**1.5 * slope(2**0.5 * s), 0.1, 2.0)
    square = s * np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    atoms = scene(square, list(itertools.combinations(range(4), 2)))
    point = classify(atoms)
    assert point.stationary and point.verdict == 'saddle' and point.index == 1
    assert point.eigenvalues[0] == pytest.approx(4 * slope(s) / s)
    np.testing.assert_allclose(np.abs(point.modes[0][:, 2]), 0.5, atol=1e-12)
    for side in displace_along_mode(atoms, point, step=0.1):
        relaxed(side)
        assert classify(side).verdict == 'minimum'
        tetrahedron = 6 * pair_energy_derivatives(1.0)[0]
        assert side.get_potential_energy() == pytest.approx(tetrahedron)


@pytest.mark.parametrize('dim, rigid', [(2, 3), (3, 5)])
def test_dimer_has_one_mode(dim, rigid):
    """Dimer at L = a: lambda = 2 f''(a) = 2 (2 c / a^3 + Q) = 6 Q; collinear,
    so 3D keeps two rotations."""
    a, Q = 1.3, 0.7
    atoms = scene([[0, 0, 0], [a, 0, 0]], [(0, 1)], dim, a=a, Q=Q)
    point = classify(atoms)
    assert point.n_rigid == rigid and point.verdict == 'minimum'
    np.testing.assert_allclose(point.eigenvalues, [6 * Q], rtol=1e-12)


def test_straight_chain_in_3d_loses_one_rotation():
    atoms = relaxed(scene([[0, 0, 0], [1.1, 0, 0], [2.3, 0, 0]],
                          [(0, 1), (1, 2)]))
    point = classify(atoms)
    assert point.n_rigid == 5 and point.n_modes == 4
    assert point.verdict == 'minimum'


@pytest.mark.parametrize('constraint, fixed, rigid', [
    (FixAtoms([0]), 3, 3),
    (FixAtoms([0, 1]), 6, 1),
    (FixAtoms([0, 1, 2]), 9, 0),
    (FixCartesian(range(8), mask=(False, False, True)), 8, 3),
])
def test_fixed_dofs_and_rigid_modes(random_points, constraint, fixed, rigid):
    atoms = scene(random_points(8, 3, 0), [(i, (i + 1) % 8) for i in range(8)])
    atoms.set_constraint(constraint)
    with pytest.warns(UserWarning, match='not a stationary point'):
        point = classify(atoms)
    assert (point.n_fixed, point.n_rigid) == (fixed, rigid)
    assert point.n_modes == 24 - fixed - rigid
    free = free_mask(atoms, 3).ravel()
    assert not np.any(point.modes.reshape(len(point.modes), -1)[:, ~free])
    if rigid == 0:
        hessian = atoms.calc.get_hessian(atoms)[np.ix_(free, free)]
        np.testing.assert_allclose(point.eigenvalues,
                                   np.linalg.eigvalsh(hessian),
                                   atol=1e-12 * np.abs(hessian).max())


def test_one_fixed_point_in_2d_keeps_its_rotation(random_points):
    atoms = scene(random_points(6, 2, 1), [(i, (i + 1) % 6) for i in range(6)],
                  dim=2)
    atoms.set_constraint(FixAtoms([0]))
    with pytest.warns(UserWarning):
        point = classify(atoms)
    assert (point.n_fixed, point.n_rigid) == (2, 1)


def test_other_constraints_are_refused(random_points):
    atoms = scene(random_points(4, 3, 0), [(0, 1)])
    atoms.set_constraint(FixedPlane(0, [1, 1, 0]))
    with pytest.raises(ValueError, match='FixAtoms and FixCartesian'):
        classify(atoms)


@pytest.mark.parametrize('dim', [2, 3])
@pytest.mark.parametrize('seed', [0, 1, 2])
def test_iterative_matches_dense_at_minima(random_points, dim, seed):
    atoms = relaxed(chorded_ring(random_points, 40, seed, dim))
    if seed == 2:
        atoms.set_constraint(FixAtoms([0, 7]))
    dense = classify(atoms, method='dense')
    lowest = classify(atoms, method='iterative', k=6)
    for name in ('verdict', 'index', 'n_modes', 'n_rigid', 'n_fixed'):
        assert getattr(lowest, name) == getattr(dense, name)
    np.testing.assert_allclose(lowest.eigenvalues, dense.eigenvalues[:6],
                               atol=dense.tolerance)
    assert lowest.tolerance == pytest.approx(dense.tolerance, rel=0.05)


def test_iterative_matches_dense_at_a_saddle(random_points):
    """A chorded ring relaxed in the plane buckles out of it in 3D."""
    flat = relaxed(chorded_ring(random_points, 40, 0, dim=2))
    atoms = scene(flat.positions, flat.calc.springs, dim=3)
    dense = classify(atoms, method='dense')
    assert dense.verdict == 'saddle' and dense.index > 5
    lowest = classify(atoms, method='iterative', k=dense.index + 2)
    assert (lowest.verdict, lowest.index) == ('saddle', dense.index)
    np.testing.assert_allclose(lowest.eigenvalues,
                               dense.eigenvalues[:dense.index + 2],
                               atol=dense.tolerance)
    with pytest.raises(ValueError, match='larger k'):
        classify(atoms, method='iterative', k=dense.index - 2)


@pytest.mark.parametrize('seed', [3, 4])
def test_iterative_started_from_modes_gives_the_same_answer_for_fewer_products(
        random_points, seed):
    """A chorded ring's minimum: started from its own lowest modes, LOBPCG
    finds the same verdict, index and eigenvalues with fewer Hessian-vector
    products than from a random start; from a random move, still the same
    answer."""
    atoms, k = relaxed(chorded_ring(random_points, 40, seed, 3)), 6
    cold = classify(atoms, method='iterative', k=k, work=(cold_work := Work()))
    warm = classify(atoms, method='iterative', k=k, work=(warm_work := Work()),
                    guess=cold.modes[:2])
    other = np.random.default_rng(seed).standard_normal((1, len(atoms), 3))
    for point in (warm, classify(atoms, method='iterative', k=k, guess=other)):
        assert (point.verdict, point.index, point.n_zero) == (cold.verdict, cold.index,
                                                              cold.n_zero)
        np.testing.assert_allclose(point.eigenvalues, cold.eigenvalues, atol=cold.tolerance)
    assert warm_work.hvp_vectors < cold_work.hvp_vectors


@pytest.mark.parametrize('dim', [2, 3])
@pytest.mark.parametrize('seed', [0, 1, 2])
def test_lowest_of_the_dense_hessian_matches_dense(random_points, dim, seed, monkeypatch):
    """A minimum (two points fixed for seed 2: fewer rigid modes) and, in 2D,
    a saddle of high index (the ring buckling out of its plane): the lowest
    eigenvalues and counts of the dense path, for one Hessian; ``'auto'``
    takes LOBPCG above the dense size, with the same counts and no Hessian."""
    flat = relaxed(chorded_ring(random_points, 40, seed, dim))
    if seed == 2:
        flat.set_constraint(FixAtoms([0, 7]))
    buckled = scene(flat.positions, flat.calc.springs, dim=3)
    monkeypatch.setattr(analysis, 'DENSE_MAX_DOFS', 10)
    for atoms in (flat, buckled):
        dense = classify(atoms, method='dense')
        auto = classify(atoms, k=dense.index + 4, work=(work := Work()))
        assert auto.method == 'iterative' and work.hessians == 0 and work.hvp_vectors > 0
        assert (auto.verdict, auto.index, auto.n_zero) == (dense.verdict, dense.index,
                                                           dense.n_zero)
        lowest = classify(atoms, method='lowest', k=dense.index + 4, work=(work := Work()))
        assert lowest.method == 'lowest' and work == Work(hessians=1)
        for name in ('verdict', 'index', 'n_zero', 'n_modes', 'n_rigid', 'n_fixed'):
            assert getattr(lowest, name) == getattr(dense, name)
        np.testing.assert_allclose(lowest.eigenvalues, dense.eigenvalues[:dense.index + 4],
                                   atol=dense.tolerance)
        overlap = np.abs(np.einsum('kij,kij->k', lowest.modes, dense.modes[:dense.index + 4]))
        assert overlap[0] == pytest.approx(1.0, abs=1e-6)
        assert lowest.tolerance == pytest.approx(dense.tolerance, rel=0.05)
    assert dim == 3 or dense.index > 5   # a plane ring buckles; a 3D one is the minimum


@pytest.mark.parametrize('seed', [0, 1])
def test_iterative_on_a_scene_too_small_for_lobpcg_takes_the_dense_lowest(random_points,
                                                                           seed):
    """LOBPCG needs five times as many coordinates as vectors: below, the
    lowest eigenpairs come from the dense Hessian, with the dense answer."""
    atoms = relaxed(chorded_ring(random_points, 8, seed, 3))
    dense = classify(atoms, method='dense')
    small = classify(atoms, method='iterative', k=6)
    assert small.method == 'lowest'
    assert (small.verdict, small.index) == (dense.verdict, dense.index)
    np.testing.assert_allclose(small.eigenvalues, dense.eigenvalues[:6], atol=dense.tolerance)


def test_not_stationary_is_flagged(random_points):
    atoms = scene(random_points(8, 3, 3), [(i, (i + 1) % 8) for i in range(8)])
    with pytest.warns(UserWarning, match='not a stationary point'):
        point = classify(atoms)
    assert not point.stationary and point.fmax > 1e-3


def test_displace_along_mode_needs_an_unstable_mode():
    atoms = ring(6, dim=2)
    with pytest.raises(ValueError, match='not unstable'):
        displace_along_mode(atoms, classify(atoms))
