"""The pair law of ase_maud.physics against its own finite differences."""

import itertools

import numpy as np
import pytest

from ase_maud.calculator.compiled_sums import flat_entries
from ase_maud.calculator.potential import MaudPotential
from ase_maud.physics import pair_law as physics

#: Central-difference step and tolerance for pair vectors of length ~1.
STEP = 1e-5
FD_RTOL = 1e-8


def pair_vectors(dim, seed, shape=(7,)):
    """Random pair vectors, lengths between 0.5 and 2."""
    rng = np.random.default_rng(seed)
    d = rng.standard_normal(shape + (dim,))
    length = rng.uniform(0.5, 2.0, shape)
    return d * (length / np.linalg.norm(d, axis=-1))[..., None]


def central_difference(f, d, h=STEP):
    """Derivatives ``df/dd_k`` of ``f`` at every pair vector, stacked on a
    new last axis: shape ``f(d).shape + (dim,)``."""
    out = []
    for k in range(d.shape[-1]):
        step = np.zeros(d.shape[-1])
        step[k] = h
        out.append((f(d + step) - f(d - step)) / (2 * h))
    return np.stack(out, axis=-1)


def assert_close(actual, expected, rtol=FD_RTOL):
    scale = np.abs(expected).max()
    np.testing.assert_allclose(actual, expected, rtol=0, atol=rtol * scale)


LAWS = {
    'repulsion': (physics.repulsion_energy, physics.repulsion_force,
                  physics.repulsion_block),
    'spring': (lambda d: physics.spring_energy(d, 0.7),
               lambda d: physics.spring_force(d, 0.7),
               lambda d: physics.spring_block(d, 0.7)),
}


@pytest.mark.parametrize('seed', [0, 1])
@pytest.mark.parametrize('dim', [2, 3])
@pytest.mark.parametrize('law', LAWS)
def test_force_and_block_are_derivatives(law, dim, seed):
    """Force on i = -dE/dr_i = -dE/dd (d = r_i - r_j); block = -d force/dd,
    symmetric and even in d."""
    energy, force, block = LAWS[law]
    d = pair_vectors(dim, seed)
    assert_close(force(d), -central_difference(energy, d))
    b = block(d)
    assert b.shape == d.shape + (dim,)
    assert_close(b, -central_difference(force, d))
    np.testing.assert_array_equal(b, np.swapaxes(b, -1, -2))
    np.testing.assert_allclose(block(-d), b, rtol=1e-15)


@pytest.mark.parametrize('dim', [2, 3])
def test_any_leading_shape(dim):
    """Pair vectors of shape (..., dim): each result is the per-pair one."""
    d = pair_vectors(dim, 2, shape=(3, 4))
    for energy, force, block in LAWS.values():
        assert energy(d).shape == (3, 4)
        assert force(d).shape == (3, 4, dim)
        assert block(d).shape == (3, 4, dim, dim)
        for idx in itertools.product(range(3), range(4)):
            np.testing.assert_array_equal(energy(d)[idx], energy(d[idx]))
            np.testing.assert_array_equal(force(d)[idx], force(d[idx]))
            np.testing.assert_array_equal(block(d)[idx], block(d[idx]))


def test_values_and_signs():
    """d = (1, 2, 2), L = 3: the table of the module docstring."""
    d = np.array([1.0, 2.0, 2.0])
    assert physics.repulsion_energy(d) == pytest.approx(1 / 3)
    np.testing.assert_allclose(physics.repulsion_force(d), d / 27)  # away
    np.testing.assert_allclose(physics.repulsion_block(d),
                               3 * np.outer(d, d) / 3**5 - np.eye(3) / 27)
    assert physics.spring_energy(d, 2.0) == pytest.approx(9.0)
    np.testing.assert_array_equal(physics.spring_force(d, 2.0), -2 * d)
    np.testing.assert_array_equal(physics.spring_block(d, 2.0), 2 * np.eye(3))
    # 1/L is harmonic in 3D: the repulsion block is traceless
    assert np.trace(physics.repulsion_block(d)) == pytest.approx(0, abs=1e-16)


def random_springs(n, k, seed):
    """``k`` distinct random pairs of ``n`` points."""
    pairs = np.array(list(itertools.combinations(range(n), 2)))
    rng = np.random.default_rng(seed)
    return pairs[rng.choice(len(pairs), k, replace=False)]


@pytest.mark.parametrize('seed', [0, 1])
@pytest.mark.parametrize('dim', [2, 3])
def test_spring_terms_are_the_summed_law(random_points, dim, seed):
    n = 9
    positions = random_points(n, dim, seed)
    springs = random_springs(n, 12, seed)
    energy, forces = physics.spring_terms(positions, springs, 0.7)

    def total(p):
        return physics.spring_terms(p, springs, 0.7)[0]

    numerical = np.zeros_like(positions)
    for i, k in itertools.product(range(n), range(3)):
        step = np.zeros_like(positions)
        step[i, k] = STEP
        numerical[i, k] = -(total(positions + step)
                            - total(positions - step)) / (2 * STEP)
    assert_close(forces, numerical)
    d = positions[springs[:, 0]] - positions[springs[:, 1]]
    assert energy == pytest.approx(0.35 * np.sum(d * d), rel=1e-14)


def test_spring_laplacian_is_degrees_minus_adjacency():
    springs = random_springs(8, 10, 3)
    laplacian = physics.spring_laplacian(springs, 8)
    expected = np.zeros((8, 8))
    for i, j in springs:
        expected[[i, j], [i, j]] += 1
        expected[i, j] = expected[j, i] = -1
    np.testing.assert_array_equal(laplacian.toarray(), expected)
    np.testing.assert_array_equal(physics.spring_degrees(springs, 8),
                                  np.diag(expected))
    assert physics.spring_laplacian(np.zeros((0, 2), int), 3).nnz == 0


@pytest.mark.parametrize('seed', [0, 1, 2])
@pytest.mark.parametrize('dim', [2, 3])
def test_spring_hessian_is_the_spring_part_of_the_hessian(random_points, dim,
                                                          seed):
    n = 10
    positions = random_points(n, dim, seed)
    springs = random_springs(n, 15, seed)
    full = MaudPotential(springs, 1.3, 0.7, dim).hessian(positions)
    repulsion = MaudPotential(np.zeros((0, 2), int), 1.3, 0.7, dim).hessian(positions)
    spring = physics.spring_hessian(springs, n, 0.7, dim)
    assert spring.shape == (dim * n, dim * n)
    np.testing.assert_allclose(spring.toarray(), full - repulsion, rtol=0,
                               atol=1e-13 * np.abs(full).max())
    np.testing.assert_array_equal(
        spring.toarray(),
        0.7 * np.kron(physics.spring_laplacian(springs, n).toarray(),
                      np.eye(dim)))
    diagonal = spring.toarray().reshape(n, dim, n, dim)[np.arange(n), :,
                                                        np.arange(n)]
    np.testing.assert_array_equal(
        physics.spring_nodal_blocks(springs, n, 0.7, dim), diagonal)


@pytest.mark.parametrize('seed', [3, 4, 5])
@pytest.mark.parametrize('dim', [2, 3])
def test_dense_hessian_sums_the_springs_at_each_point(random_points, dim, seed):
    """The dense Hessian's spring part (its entries summed without a sparse
    matrix: several springs meet at each point's diagonal block) is the
    sparse springs' Hessian, each spring with its own force density, listed
    in either order."""
    n = 9
    rng = np.random.default_rng(seed)
    springs = random_springs(n, 16, seed)
    springs[::3] = springs[::3, ::-1]
    q = rng.uniform(0.2, 3.0, len(springs))
    positions = random_points(n, dim, seed)
    full = MaudPotential(springs, 1.3, 0.7, dim, q=q).hessian(positions)
    repulsion = MaudPotential(np.zeros((0, 2), int), 1.3, 0.7, dim).hessian(positions)
    sparse = physics.spring_hessian(springs, n, 0.7 * q, dim).toarray()
    np.testing.assert_allclose(full - repulsion, sparse, rtol=0,
                               atol=1e-13 * np.abs(full).max())
    dense = np.zeros((dim * n, dim * n))
    rows, cols, data = physics.spring_hessian_entries(springs, 0.7 * q, dim)
    np.add.at(dense, (rows, cols), data)
    np.testing.assert_allclose(dense, sparse, rtol=1e-15, atol=1e-15)


def summed_entries(springs, weights, dim, n):
    """The flat indices and values of the springs' Hessian entries summed
    as c83d28e kept them: ``np.unique`` over all of them, ``np.bincount``
    in their order."""
    rows, cols, data = physics.spring_hessian_entries(springs, weights, dim)
    flat, which = np.unique(rows.astype(np.int64) * dim * n + cols, return_inverse=True)
    return flat, np.bincount(which, weights=data, minlength=len(flat))


@pytest.mark.parametrize('seed', range(8))
@pytest.mark.parametrize('dim', [2, 3])
def test_the_kept_hessian_entries_are_the_summed_entries_to_the_bit(dim, seed):
    """The compiled flat index of the springs' Hessian holds the entries
    (:func:`summed_entries`), each once, with their values to the last bit:
    weights over 16 decades (so the order of a sum shows), one or one per
    spring, atoms on no spring, pairs repeated in both orders."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 30))
    pairs = rng.integers(0, n, size=(int(rng.integers(1, 3 * n)), 2))
    pairs = pairs[pairs[:, 0] != pairs[:, 1]]
    if seed % 2:
        pairs = np.concatenate([pairs, pairs[::2, ::-1], pairs[:3]])
    for weights in (np.full(len(pairs), 10 ** rng.uniform(-8, 8)),
                    10 ** rng.uniform(-8, 8, len(pairs))):
        flat, data = flat_entries(pairs.astype(np.int64), weights, dim, n)
        expected_flat, expected = summed_entries(pairs, weights, dim, n)
        order = np.argsort(flat)
        np.testing.assert_array_equal(flat[order], expected_flat)
        assert data[order].tobytes() == expected.tobytes()
    flat, data = flat_entries(np.zeros((0, 2), np.int64), np.zeros(0), dim, n)
    assert flat.size == data.size == 0


@pytest.mark.parametrize('seed', range(3))
@pytest.mark.parametrize('dim', [2, 3])
def test_the_whole_hessian_adds_the_summed_spring_entries(dim, seed):
    """``whole_hessian``: ``Q`` times the repulsion's, plus the springs'
    entries summed as :func:`summed_entries` sums them, byte for byte, with
    one ``q`` per spring or none."""
    rng = np.random.default_rng(seed)
    n = 11
    springs = random_springs(n, 20, seed)
    springs[::3] = springs[::3, ::-1]
    repulsion = rng.standard_normal((dim * n, dim * n))
    for q in (None, 10 ** rng.uniform(-6, 6, len(springs))):
        potential = MaudPotential(springs, 1.3, 0.7, dim, q=q)
        expected = 0.7 * repulsion
        flat, data = summed_entries(springs, 0.7 * potential.stiffnesses, dim, n)
        expected.ravel()[flat] += data
        got = potential.whole_hessian(repulsion.copy())
        assert got.tobytes() == expected.tobytes()


@pytest.mark.parametrize('n, chunk', [(0, 5), (1, 5), (2, 1), (7, 1), (7, 4),
                                      (7, 100), (30, 50), (31, 7)])
def test_pair_chunks_give_every_pair_once(n, chunk):
    pairs = [np.c_[i, j] for i, j in physics.pair_chunks(n, chunk)]
    longest_row = max(n - 1, 0)
    assert all(len(p) <= max(chunk, longest_row) for p in pairs)
    got = np.concatenate(pairs) if pairs else np.zeros((0, 2), int)
    expected = np.array(list(itertools.combinations(range(n), 2)))
    np.testing.assert_array_equal(got, expected.reshape(-1, 2))


@pytest.mark.parametrize('seed', range(3))
@pytest.mark.parametrize('dim', [2, 3])
def test_the_potentials_spring_sums_are_the_pair_law(seed, dim):
    """``MaudPotential.spring_terms`` (the compiled sum) equals the pair law
    summed spring by spring (:func:`physics.spring_terms`), with and without
    force densities."""
    rng = np.random.default_rng(seed)
    n = 9
    positions = rng.normal(size=(n, 3))
    if dim == 2:
        positions[:, 2] = 0.0
    springs = np.array([(i, j) for i in range(n) for j in range(i + 1, n)
                        if rng.random() < 0.4])
    for q in (None, rng.uniform(0.2, 3.0, len(springs))):
        potential = MaudPotential(springs, dim=dim, q=q)
        energy, forces = potential.spring_terms(positions)
        expected = physics.spring_terms(positions, springs, 1.0 if q is None else q)
        assert energy == pytest.approx(expected[0], rel=1e-13)
        np.testing.assert_allclose(forces, expected[1], rtol=1e-12, atol=1e-13)


@pytest.mark.parametrize('seed', range(3))
def test_repulsion_stiffness_is_the_blocks_largest_eigenvalue(seed):
    d = np.random.default_rng(seed).normal(size=(5, 3))
    length = np.linalg.norm(d, axis=1)
    largest = np.linalg.eigvalsh(physics.repulsion_block(d))[:, -1]
    np.testing.assert_allclose(physics.repulsion_stiffness(length), largest, rtol=1e-12)
