"""MaudCalculator: derivatives, analytic cases, 2D/3D blocks, ASE behaviour."""

import itertools

import numpy as np
import pytest
from ase import Atoms
from ase.calculators.fd import calculate_numerical_forces
from ase.constraints import FixAtoms
from ase.io import read, write
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.distance import pdist, squareform

from ase_maud.bench.hard_inputs import wrong_results_of_threads
from ase_maud.calculator.maud_calculator import MaudCalculator
from ase_maud.scenes.catalogue import build

SHAPES = ['chain', 'ring', 'star', 'tree', 'all_pairs']
#: Central-difference step, in units of the point spacing (1 here). It leaves
#: relative errors of at most 4e-10 on these scenes (4e-8 at 1e-4, where the
#: h**2 truncation dominates; 3e-9 at 1e-6, where rounding does).
STEP = 1e-5
FD_RTOL = 1e-8


def make_springs(shape, n, rng):
    """(K, 2) sprung pairs of a graph on ``n`` points."""
    idx = np.arange(n)
    if shape == 'chain':
        return np.c_[idx[:-1], idx[1:]]
    if shape == 'ring':
        return np.c_[idx, np.roll(idx, -1)]
    if shape == 'star':
        return np.c_[np.zeros(n - 1, dtype=int), idx[1:]]
    if shape == 'tree':
        label = rng.permutation(n)
        parent = [rng.integers(k) for k in range(1, n)]
        return np.c_[label[parent], label[1:]]
    if shape == 'all_pairs':
        return np.array(list(itertools.combinations(idx, 2)))
    raise ValueError(shape)


@pytest.fixture
def scene(random_points):
    """Factory: ``n`` random points, springs of ``shape``, a calculator."""
    def build(shape='tree', n=9, dim=3, seed=0, **kwargs):
        rng = np.random.default_rng(seed)
        kwargs = {'a': 1.3, 'Q': 0.7, 'dim': dim, **kwargs}
        calc = MaudCalculator(springs=make_springs(shape, n, rng), **kwargs)
        return Atoms(f'H{n}', random_points(n, dim, seed), calculator=calc)
    return build


def rel_err(actual, expected):
    """Largest deviation relative to the largest entry of ``expected``."""
    return np.abs(actual - expected).max() / np.abs(expected).max()


def fd_hessian(atoms, dim, h=STEP):
    """Central differences of minus the forces, shape (dim N, dim N)."""
    p0 = atoms.get_positions()
    columns = []
    for i, k in itertools.product(range(len(atoms)), range(dim)):
        forces = []
        for step in (h, -h):
            p = p0.copy()
            p[i, k] += step
            atoms.positions = p
            forces.append(atoms.get_forces()[:, :dim].ravel())
        columns.append((forces[1] - forces[0]) / (2 * h))
    atoms.positions = p0
    return np.array(columns).T


def block_diagonal(hessian, dim):
    """The (N, dim, dim) diagonal blocks of a (dim N, dim N) matrix."""
    n = len(hessian) // dim
    return hessian.reshape(n, dim, n, dim)[np.arange(n), :, np.arange(n)]


# -- derivatives -------------------------------------------------------------

@pytest.mark.parametrize('seed', [0, 1])
@pytest.mark.parametrize('dim', [2, 3])
@pytest.mark.parametrize('shape', SHAPES)
def test_forces_are_minus_energy_gradient(scene, shape, dim, seed):
    """Forces against ASE's central differences of the energy."""
    atoms = scene(shape, n=9, dim=dim, seed=seed)
    forces = atoms.get_forces()
    numerical = calculate_numerical_forces(atoms, eps=STEP,
                                           icarts=range(dim))
    err = rel_err(forces[:, :dim], numerical)
    print(f'forces vs FD energy  {shape:9s} dim={dim} seed={seed}: {err:.1e}')
    assert err < FD_RTOL


@pytest.mark.parametrize('seed', [0, 1])
@pytest.mark.parametrize('dim', [2, 3])
@pytest.mark.parametrize('shape', SHAPES)
def test_hessian_and_blocks_are_force_derivatives(scene, shape, dim, seed):
    atoms = scene(shape, n=8, dim=dim, seed=seed)
    calc = atoms.calc
    numerical = fd_hessian(atoms, dim)
    hessian = calc.get_hessian(atoms)
    blocks = calc.get_stiffness(atoms)
    err_h = rel_err(hessian, numerical)
    err_k = rel_err(blocks, block_diagonal(numerical, dim))
    print(f'Hessian, blocks vs FD forces {shape:9s} dim={dim} seed={seed}: '
          f'{err_h:.1e}, {err_k:.1e}')
    assert hessian.shape == (dim * 8, dim * 8)
    assert blocks.shape == (8, dim, dim)
    assert err_h < FD_RTOL and err_k < FD_RTOL
    np.testing.assert_allclose(hessian, hessian.T, rtol=1e-14)
    np.testing.assert_allclose(block_diagonal(hessian, dim), blocks,
                               rtol=0, atol=1e-12 * np.abs(blocks).max())


def loaded(scene, shape, n, dim, seed):
    """``scene(shape, n, dim, seed)`` with a random force density multiplier
    per spring in [0.2, 3] and a random load on every point, (n, dim)."""
    atoms = scene(shape, n=n, dim=dim, seed=seed)
    rng = np.random.default_rng(1000 + seed)
    atoms.calc.set(q=rng.uniform(0.2, 3.0, len(atoms.calc.springs)),
                   loads=rng.normal(0.0, 2.0, (n, dim)))
    return atoms


@pytest.mark.parametrize('seed', [0, 1, 2])
@pytest.mark.parametrize('dim', [2, 3])
@pytest.mark.parametrize('shape', ['chain', 'tree', 'all_pairs'])
def test_loads_and_force_densities_are_derivatives(scene, shape, dim, seed):
    """With random loads and force densities: forces against central
    differences of the energy, the Hessian and the nodal blocks against
    central differences of the forces."""
    atoms = loaded(scene, shape, 8, dim, seed)
    calc = atoms.calc
    forces = atoms.get_forces()
    numerical = calculate_numerical_forces(atoms, eps=STEP, icarts=range(dim))
    assert rel_err(forces[:, :dim], numerical) < FD_RTOL
    numerical = fd_hessian(atoms, dim)
    assert rel_err(calc.get_hessian(atoms), numerical) < FD_RTOL
    assert rel_err(calc.get_stiffness(atoms), block_diagonal(numerical, dim)) < FD_RTOL


@pytest.mark.parametrize('seed', [0, 1, 2])
@pytest.mark.parametrize('dim', [2, 3])
@pytest.mark.parametrize('shape', ['tree', 'all_pairs'])
def test_a_hessian_block_is_the_whole_hessians_rows_there(scene, shape, dim, seed):
    """``get_hessian_block`` on a random subset of the atoms, in random
    order, with random loads and force densities: the whole Hessian's rows
    and columns there, and central differences of the forces."""
    atoms = loaded(scene, shape, 9, dim, seed)
    rng = np.random.default_rng(seed)
    index = rng.permutation(9)[:rng.integers(1, 6)]
    coords = (dim * index[:, None] + np.arange(dim)).ravel()
    atoms.get_forces()
    block = atoms.calc.get_hessian_block(atoms, index)
    assert set(atoms.calc.results) == {'energy', 'free_energy', 'forces'}   # none kept
    np.testing.assert_allclose(block, atoms.calc.get_hessian(atoms)[np.ix_(coords, coords)],
                               rtol=0, atol=1e-12 * np.abs(block).max())
    assert rel_err(block, fd_hessian(atoms, dim)[np.ix_(coords, coords)]) < FD_RTOL


@pytest.mark.parametrize('indices, message', [
    ([0, 9], r'indices: atom 9 is not one of the 9 atoms'),
    ([-1], r'indices: atom -1 is not one of the 9 atoms'),
    ([2, 2], r'indices: an atom is given twice'),
    ([[0, 1]], r'indices must be a 1-D sequence of atom indices'),
    ([0.5], r'indices must be a 1-D sequence of atom indices'),
])
def test_a_bad_hessian_block_is_named(scene, indices, message):
    atoms = scene('tree', n=9)
    with pytest.raises(ValueError, match=message):
        atoms.calc.get_hessian_block(atoms, indices)


def test_a_hessian_block_names_coincident_atoms(scene):
    atoms = scene('tree', n=9)
    atoms.positions[7] = atoms.positions[2]
    with pytest.raises(ValueError, match=r'atoms 2 and 7 are at the same position'):
        atoms.calc.get_hessian_block(atoms, [3, 2])


@pytest.mark.parametrize('seed', [0, 1, 2])
@pytest.mark.parametrize('dim', [2, 3])
def test_loads_and_force_densities_by_formula(scene, dim, seed):
    """Against the formulas written out here: a spring ``Q q L**2 / 2``, a
    load ``-F . r`` (its force ``F``), on top of the repulsion alone; loads
    leave the Hessian and the blocks as they are."""
    atoms = loaded(scene, 'tree', 9, dim, seed)
    calc = atoms.calc
    q, loads = calc.parameters['q'], calc.parameters['loads']
    repulsion = MaudCalculator(a=1.3, Q=0.7, dim=dim)
    r = atoms.positions
    i, j = calc.springs.T
    length2 = ((r[i] - r[j])**2).sum(axis=1)
    expected = (repulsion.get_potential_energy(atoms) + 0.5 * 0.7 * (q * length2).sum()
                - (loads * r).sum())
    assert calc.get_potential_energy(atoms) == pytest.approx(expected, rel=1e-12)
    unloaded = MaudCalculator(springs=calc.springs, a=1.3, Q=0.7, dim=dim, q=q)
    np.testing.assert_allclose(calc.get_forces(atoms) - unloaded.get_forces(atoms),
                               loads, rtol=0, atol=1e-12 * np.abs(loads).max())
    np.testing.assert_array_equal(calc.get_hessian(atoms), unloaded.get_hessian(atoms))
    np.testing.assert_array_equal(calc.get_stiffness(atoms), unloaded.get_stiffness(atoms))
    weighted = np.zeros((9, 9))
    for (m, k), qs in zip(calc.springs, q, strict=True):
        weighted[[m, k, m, k], [m, k, k, m]] += [qs, qs, -qs, -qs]
    np.testing.assert_allclose(calc.get_spring_hessian(atoms).toarray(),
                               0.7 * np.kron(weighted, np.eye(dim)), rtol=1e-14)
    v = np.random.default_rng(seed).normal(size=(9, dim))
    np.testing.assert_allclose(calc.potential.hvp(atoms.positions, v).ravel(),
                               calc.get_hessian(atoms) @ v.ravel(), rtol=1e-10,
                               atol=1e-12 * np.abs(calc.get_hessian(atoms)).max())


@pytest.mark.parametrize('bad, message', [
    ({'q': [1.0] * 7 + [0.0]}, r'q of spring 7 must be a finite nonzero number'),
    ({'q': [1.0, np.nan] + [1.0] * 6}, r'q of spring 1 must be a finite nonzero'),
    ({'q': [1.0] * 7}, r'q must hold one value per spring, shape \(8,\)'),
    ({'q': [[1.0] * 8]}, r'q must hold one value per spring'),
    ({'q': ['x'] * 8}, r'q must be an array of numbers'),
    ({'loads': [[0, 0, 1.0]] * 4 + [[0, np.inf, 0]]}, r'loads of atom 4 must be a finite'),
    ({'loads': np.ones((9, 4))}, r'loads must have shape \(N, 3\)'),
    ({'loads': np.ones(9)}, r'loads must have shape'),
])
def test_bad_loads_and_force_densities_are_named(scene, bad, message):
    atoms = scene('tree', n=9)
    with pytest.raises(ValueError, match=message):
        atoms.calc.set(**bad)
    atoms.get_potential_energy()   # the calculator kept its good parameters


@pytest.mark.parametrize('dim', [2, 3])
def test_loads_not_one_per_atom_are_refused_when_computing(scene, dim):
    atoms = scene('tree', n=9, dim=dim)
    atoms.calc.set(loads=np.ones((8, dim)))
    with pytest.raises(ValueError, match='loads has 8 rows, one per atom, but the atoms are 9'):
        atoms.get_potential_energy()


def test_a_2d_load_off_the_plane_names_the_atom(scene):
    with pytest.raises(ValueError, match='loads of atom 2 has z = 0.5'):
        scene('tree', n=9, dim=2).calc.set(loads=[[0, 0, 0]] * 2 + [[0, 0, 0.5]] * 7)


# -- analytic cases (design.md section 2) -------------------------------------

def random_rotation(seed):
    """A random 3x3 rotation matrix."""
    q, r = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    q *= np.sign(np.diag(r))
    return q * np.linalg.det(q)


@pytest.mark.parametrize('a, Q', [(1.0, 1.0), (0.3, 2.5), (7.0, 0.1)])
def test_dimer_equilibrium(a, Q):
    """One spring: zero forces at L = a, E = c/a + Q a**2/2, K = 3Q n n^T."""
    n = random_rotation(0)[0]
    atoms = Atoms('H2', [np.ones(3), np.ones(3) + a * n],
                  calculator=MaudCalculator(springs=[[0, 1]], a=a, Q=Q))
    assert atoms.get_potential_energy() == pytest.approx(1.5 * Q * a**2,
                                                         rel=1e-14)
    np.testing.assert_allclose(atoms.get_forces(), 0, atol=1e-14 * Q * a)
    expected = 3 * Q * np.outer(n, n)
    np.testing.assert_allclose(atoms.calc.get_stiffness(atoms),
                               [expected, expected], atol=1e-14 * Q)


@pytest.mark.parametrize('a, Q', [(1.0, 1.0), (2.5, 0.4)])
def test_sprung_triangle_has_sides_a(a, Q):
    corners = a / np.sqrt(3) * np.array(
        [[np.cos(t), np.sin(t), 0] for t in 2 * np.pi * np.arange(3) / 3])
    atoms = Atoms('H3', corners @ random_rotation(1).T,
                  calculator=MaudCalculator(springs=[[0, 1], [1, 2], [2, 0]],
                                            a=a, Q=Q))
    assert np.allclose(pdist(atoms.positions), a)
    np.testing.assert_allclose(atoms.get_forces(), 0, atol=1e-14 * Q * a)


def ring_radius_energy(n, a, Q):
    """Radius and energy of the sprung ring of ``n`` points in equilibrium."""
    s = np.sum(1 / np.sin(np.pi * np.arange(1, n) / n))
    sin2 = np.sin(np.pi / n) ** 2
    radius = (a**3 * s / (16 * sin2)) ** (1 / 3)
    energy = 2 * n * Q * sin2 * radius**2 + a**3 * Q * n * s / (4 * radius)
    return radius, energy


def test_ring_formula_values():
    radius, energy = ring_radius_energy(50, 1.0, 1.0)
    assert radius == pytest.approx(12.6771550, abs=5e-8)
    assert energy == pytest.approx(190.0872603, abs=5e-8)


@pytest.mark.parametrize('dim', [2, 3])
@pytest.mark.parametrize('n, a, Q', [(50, 1.0, 1.0), (7, 0.5, 3.0),
                                     (120, 2.0, 0.25)])
def test_ring_in_equilibrium(n, a, Q, dim):
    radius, energy = ring_radius_energy(n, a, Q)
    t = 2 * np.pi * np.arange(n) / n
    positions = radius * np.c_[np.cos(t), np.sin(t), np.zeros(n)]
    ring = np.c_[np.arange(n), np.roll(np.arange(n), -1)]
    atoms = Atoms(f'H{n}', positions + [0.5, -2.0, 3.0],
                  calculator=MaudCalculator(springs=ring, a=a, Q=Q, dim=dim))
    assert atoms.get_potential_energy() == pytest.approx(energy, rel=1e-12)
    np.testing.assert_allclose(atoms.get_forces(), 0, atol=1e-12 * Q * radius)


@pytest.mark.parametrize('scale, Q', [(1.0, 3.0), (0.01, 1.0), (40.0, 0.2)])
def test_scaling_in_a_and_Q(scene, scale, Q):
    """Positions scale with a: E as Q a**2, forces as Q a, blocks as Q."""
    unit = scene('tree', n=10, seed=3, a=1.0, Q=1.0)
    scaled = unit.copy()
    scaled.positions *= scale
    scaled.calc = MaudCalculator(springs=unit.calc.springs, a=scale, Q=Q)
    assert scaled.get_potential_energy() == pytest.approx(
        Q * scale**2 * unit.get_potential_energy(), rel=1e-13)
    np.testing.assert_allclose(scaled.get_forces(),
                               Q * scale * unit.get_forces(), rtol=1e-12)
    np.testing.assert_allclose(scaled.calc.get_stiffness(scaled),
                               Q * unit.calc.get_stiffness(unit), rtol=1e-12)


@pytest.mark.parametrize('seed', [0, 1, 2])
@pytest.mark.parametrize('dim', [2, 3])
@pytest.mark.parametrize('shape', SHAPES)
def test_no_net_force_or_torque(scene, shape, dim, seed):
    atoms = scene(shape, n=30, dim=dim, seed=seed)
    forces = atoms.get_forces()
    r = atoms.positions - atoms.positions.mean(axis=0)
    size = np.abs(forces).sum()
    np.testing.assert_allclose(forces.sum(axis=0), 0, atol=1e-13 * size)
    np.testing.assert_allclose(np.cross(r, forces).sum(axis=0), 0,
                               atol=1e-13 * size * np.abs(r).max())


# -- 2D and 3D blocks ---------------------------------------------------------

@pytest.mark.parametrize('seed', [0, 1])
@pytest.mark.parametrize('shape', SHAPES)
def test_blocks_2d_and_3d(scene, shape, seed):
    """2D: z forces exactly 0, 2x2 blocks, Tr = sum c/L**3 + 2 Q deg.

    3D: the repulsive part is traceless, Tr = 3 Q deg. The 2D blocks of a
    planar scene are the xy part of its 3D blocks.
    """
    flat = scene(shape, n=12, dim=2, seed=seed)
    flat.positions[:, 2] = 4.25
    p = flat.calc.parameters
    c, Q = p['a']**3 * p['Q'], p['Q']
    deg = np.bincount(flat.calc.springs.ravel(), minlength=len(flat))
    inv3 = squareform(pdist(flat.positions) ** -3.0).sum(axis=1)
    blocks2 = flat.calc.get_stiffness(flat)
    assert blocks2.shape == (12, 2, 2)
    assert np.all(flat.get_forces()[:, 2] == 0.0)
    np.testing.assert_allclose(np.trace(blocks2, axis1=1, axis2=2),
                               c * inv3 + 2 * Q * deg, rtol=1e-12)

    space = flat.copy()
    space.calc = MaudCalculator(**{**p, 'dim': 3})
    blocks3 = space.calc.get_stiffness(space)
    assert blocks3.shape == (12, 3, 3)
    scale = c * inv3.max()
    np.testing.assert_allclose(np.trace(blocks3, axis1=1, axis2=2),
                               3 * Q * deg, rtol=0, atol=1e-13 * scale)
    np.testing.assert_allclose(blocks3[:, :2, :2], blocks2, rtol=0,
                               atol=1e-13 * scale)
    np.testing.assert_allclose(space.get_forces()[:, :2],
                               flat.get_forces()[:, :2], rtol=1e-13)


# -- ASE behaviour ------------------------------------------------------------

def count_calculations(calc, monkeypatch):
    """Wrap ``calc.calculate``; return the list of properties of each call."""
    calls = []
    calculate = calc.calculate

    def counted(atoms=None, properties=('energy',), system_changes=()):
        calls.append(list(properties))
        return calculate(atoms, properties, system_changes)

    monkeypatch.setattr(calc, 'calculate', counted)
    return calls


def test_results_are_cached_and_blocks_lazy(scene, monkeypatch):
    atoms = scene()
    calc = atoms.calc
    calls = count_calculations(calc, monkeypatch)
    energy = atoms.get_potential_energy()
    assert atoms.get_potential_energy() == energy
    forces = atoms.get_forces()
    assert len(calls) == 1
    assert 'stiffness' not in calc.results

    blocks = calc.get_stiffness(atoms)
    assert len(calls) == 2 and 'stiffness' in calc.results
    calc.get_stiffness(atoms)
    np.testing.assert_allclose(atoms.get_forces(), forces, rtol=1e-13)
    assert len(calls) == 2

    atoms.positions[3] += [0.1, 0.0, -0.05]
    assert atoms.get_potential_energy() != energy
    assert len(calls) == 3 and 'stiffness' not in calc.results
    assert not np.array_equal(calc.get_stiffness(atoms), blocks)


def test_set_discards_results(scene):
    atoms = scene()
    calc = atoms.calc
    energy = atoms.get_potential_energy()
    calc.get_stiffness(atoms)
    calc.set(a=2.0)
    assert calc.results == {}
    fresh = MaudCalculator(springs=calc.springs, a=2.0, Q=0.7)
    expected = fresh.get_potential_energy(atoms)
    assert atoms.get_potential_energy() == pytest.approx(expected, rel=1e-14)
    assert expected != pytest.approx(energy)


def test_todict_and_trajectory_round_trip(scene, tmp_path):
    atoms = scene('ring', n=7, dim=2, backend='numpy')
    calc = atoms.calc
    params = calc.todict()
    np.testing.assert_array_equal(params['springs'], calc.springs)
    assert (params['a'], params['Q'], params['dim']) == (1.3, 0.7, 2)
    assert params['backend'] == 'numpy'

    energy, forces = atoms.get_potential_energy(), atoms.get_forces()
    write(tmp_path / 'scene.traj', atoms)
    back = read(tmp_path / 'scene.traj')
    assert back.calc.name == calc.name == 'maudcalculator'
    saved = back.calc.parameters
    np.testing.assert_array_equal(saved['springs'], calc.springs)
    assert {k: saved[k] for k in ('a', 'Q', 'dim', 'backend')} == {
        'a': 1.3, 'Q': 0.7, 'dim': 2, 'backend': 'numpy'}
    assert back.get_potential_energy() == energy
    np.testing.assert_array_equal(back.get_forces(), forces)
    # The saved parameters rebuild the same calculator.
    back.calc = MaudCalculator(**saved)
    assert back.get_potential_energy() == pytest.approx(energy, rel=1e-14)


@pytest.mark.parametrize('dim', [2, 3])
@pytest.mark.parametrize('shape', ['chain', 'all_pairs'])
def test_backends_agree(scene, shape, dim):
    atoms = scene(shape, n=40, dim=dim, seed=5)
    reference = atoms.copy()
    reference.calc = MaudCalculator(**{**atoms.calc.parameters,
                                       'backend': 'numpy'})
    assert atoms.get_potential_energy() == pytest.approx(
        reference.get_potential_energy(), rel=1e-12)
    for got, want in [(atoms.get_forces(), reference.get_forces()),
                      (atoms.calc.get_stiffness(atoms),
                       reference.calc.get_stiffness(reference))]:
        np.testing.assert_allclose(got, want, rtol=0,
                                   atol=1e-12 * np.abs(want).max())


# -- what the optimiser asks of the calculator ---------------------------------

@pytest.mark.parametrize('dim', [2, 3])
@pytest.mark.parametrize('shape', ['chain', 'star', 'all_pairs'])
def test_spring_hessian_is_constant_and_cached(scene, shape, dim):
    atoms = scene(shape, n=7, dim=dim, seed=2)
    calc = atoms.calc
    spring = calc.get_spring_hessian(atoms)
    assert spring.shape == (7 * dim, 7 * dim) and spring.format == 'csr'
    # the spring part of the Hessian: the Hessian minus that with no springs
    free = MaudCalculator(**{**calc.parameters, 'springs': ()})
    np.testing.assert_allclose(
        spring.toarray(), calc.get_hessian(atoms) - free.get_hessian(atoms),
        rtol=0, atol=1e-12 * np.abs(calc.get_hessian(atoms)).max())
    atoms.positions *= 1.7   # positions do not enter: the same matrix
    assert calc.get_spring_hessian(atoms) is spring
    atoms.get_potential_energy()
    assert calc.get_spring_hessian() is spring   # the last atoms computed
    calc.set(Q=2 * calc.parameters['Q'])
    doubled = calc.get_spring_hessian(atoms)
    np.testing.assert_allclose(doubled.toarray(), 2 * spring.toarray())
    calc.set(springs=[[0, 1]])
    assert calc.get_spring_hessian(atoms).nnz == 2 * 2 * dim
    with pytest.raises(ValueError, match='spring 0 \\(0, 1\\).*index 0'):
        calc.get_spring_hessian(atoms[:1])


def test_length_scale_and_dim():
    calc = MaudCalculator(a=2.5, Q=0.3, dim=2)
    assert (calc.length_scale, calc.dim) == (2.5, 2)
    calc.set(a=0.1, dim=3)
    assert (calc.length_scale, calc.dim) == (0.1, 3)


@pytest.mark.parametrize('dim, expected', [(3, [[2, 3], [4]]), (2, [])])
def test_unbounded_components(random_points, dim, expected):
    """Three spring components in 3D, the first held: the other two fly
    away (topology.unbounded_components); in 2D nothing is proved."""
    atoms = Atoms('H5', random_points(5, dim, seed=1))
    atoms.set_constraint(FixAtoms([1]))
    atoms.calc = MaudCalculator(springs=[[0, 1], [2, 3]], dim=dim)
    assert atoms.calc.potential.unbounded_components(atoms) == expected


@pytest.mark.parametrize('a', [1e-12, 1.0, 1e12])
def test_every_move_is_seen_at_any_scale(a):
    # ASE's default change detection (absolute 1e-15) misses moves of tiny
    # scenes; the calculator compares positions exactly.
    atoms = build('ring', 8, seed=int(a > 1), a=a)
    before = atoms.get_forces().copy()
    atoms.positions[3, 0] += 1e-3 * a
    after = atoms.get_forces()
    assert np.abs(after - before).max() > 1e-6 * np.abs(before).max()
    assert atoms.calc.check_state(atoms) == []


# -- extreme scales: the scaled form, or a ValueError (never NaN) -------------

EXTREME = [(1e-105, 1.0), (1e100, 1e-12), (1e-12, 1e12), (1e12, 1e-12),
           (1e-150, 1e12), (1e150, 1.0), (1e160, 1.0)]


def check_scaled(unit, a, Q, dim, with_hessian=True):
    """The scene ``unit`` (at a = Q = 1) scaled by ``a``, evaluated at
    ``a, Q``: finite and ``a^2 Q E``, ``a Q F``, ``Q K`` (and ``Q H``) of the
    unit scene within 1e-12, or a ValueError that says what overflowed."""
    scaled = unit.copy()
    scaled.positions *= a
    scaled.calc = MaudCalculator(springs=unit.calc.springs, a=a, Q=Q,
                                 dim=dim)
    properties = ['energy', 'forces', 'stiffness'] + (
        ['hessian'] * with_hessian)
    try:
        scaled.calc.calculate(scaled, properties)
    except ValueError as err:
        assert 'overflow' in str(err)
        return None
    unit.calc.calculate(unit, properties)
    got, ref = scaled.calc.results, unit.calc.results
    for name, power in [('energy', 2), ('forces', 1), ('stiffness', 0),
                        ('hessian', 0)][:3 + with_hessian]:
        assert np.all(np.isfinite(got[name])), name
        expected = Q * a**power * np.asarray(ref[name]) if power else (
            Q * np.asarray(ref[name]))
        np.testing.assert_allclose(got[name], expected, rtol=0,
                                   atol=1e-12 * np.abs(expected).max())
    return got


@settings(max_examples=40, deadline=None, derandomize=True)
@given(log_a=st.floats(-12, 12), log_q=st.floats(-12, 12),
       seed=st.integers(0, 2**16), dim=st.sampled_from([2, 3]))
def test_any_scale_is_the_unit_scene_scaled(log_a, log_q, seed, dim):
    rng = np.random.default_rng(seed)
    n = 7
    unit = Atoms(f'H{n}', rng.uniform(-1, 1, (n, 3)) * [1, 1, dim == 3])
    unit.calc = MaudCalculator(springs=make_springs('tree', n, rng), dim=dim)
    got = check_scaled(unit, 10.0**log_a, 10.0**log_q, dim)
    assert got is not None   # nothing overflows between 1e-12 and 1e12


@pytest.mark.parametrize('a, Q', EXTREME)
@pytest.mark.parametrize('dim', [2, 3])
def test_extreme_scales_are_finite_or_refused(scene, a, Q, dim):
    unit = scene('chain', n=6, dim=dim, seed=4, a=1.0, Q=1.0)
    got = check_scaled(unit, a, Q, dim)
    # a^2 Q e representable: it must be given; beyond, refused
    assert (got is not None) == (a * a * Q < 1e300)


def test_scale_invariance_for_unit_q(scene):
    unit = scene('ring', n=8, seed=5, a=1.0, Q=1.0)
    for a in (1e-105, 1e-30, 3.0, 1e100):
        scaled = unit.copy()
        scaled.positions *= a
        scaled.calc = MaudCalculator(springs=unit.calc.springs, a=a)
        assert scaled.get_potential_energy() == pytest.approx(
            a**2 * unit.get_potential_energy(), rel=1e-13)


@pytest.mark.parametrize('dim', [2, 3])
def test_forces_and_blocks_are_derivatives_at_a_1e_105(scene, dim):
    a, Q = 1e-105, 0.7
    atoms = scene('tree', n=7, dim=dim, seed=6, a=1.0, Q=1.0)
    atoms.positions *= a
    atoms.calc = MaudCalculator(springs=atoms.calc.springs, a=a, Q=Q,
                                dim=dim)
    forces = atoms.get_forces()
    numerical = calculate_numerical_forces(atoms, eps=STEP * a,
                                           icarts=range(dim))
    assert rel_err(forces[:, :dim], numerical) < FD_RTOL
    blocks = atoms.calc.get_stiffness(atoms)
    assert rel_err(blocks, block_diagonal(fd_hessian(atoms, dim, STEP * a),
                                          dim)) < FD_RTOL


def test_separation_1e_110_names_the_pair_or_scales():
    # 1 / L**3 overflows below L = 1e-103 a: refused, naming the pair; in
    # units of a of the same order the same scene is finite.
    positions = [[0, 0, 0], [1e-110, 0, 0], [2e-110, 1e-110, 0]]
    atoms = Atoms('H3', positions)
    atoms.calc = MaudCalculator()
    with pytest.raises(ValueError, match=r'atoms 0 and 1 are 1e-110 a apart'):
        atoms.get_forces()
    atoms.calc = MaudCalculator(a=1e-110, springs=[[0, 1]])
    assert np.isfinite(atoms.get_forces()).all()
    assert np.isfinite(atoms.calc.get_stiffness(atoms)).all()
    far = Atoms('H2', [[0, 0, 0], [1e300, 0, 0]])
    far.calc = MaudCalculator(a=1e-10)
    with pytest.raises(ValueError, match='atom 1 .* beyond the float64 range'):
        far.get_forces()


@pytest.mark.parametrize('gap', [1e-120, 1e-200, 1e-300])
def test_pairs_closer_than_float64_allows_name_two_atoms(gap):
    rng = np.random.default_rng(int(-np.log10(gap)))
    positions = rng.uniform(0, 5, (6, 3))
    positions[1] = 0.0                        # a gap representable beside it
    positions[4] = [gap, 0, 0]
    atoms = Atoms('H6', positions)
    atoms.calc = MaudCalculator()
    with pytest.raises(ValueError, match=r'atoms 1 and 4 are 1e-\d+ a apart'):
        atoms.get_forces()


@pytest.mark.parametrize('seed', [0, 1])
def test_threads_sharing_one_calculator_get_their_own_results(seed):
    assert wrong_results_of_threads(seed) == 0


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_potential_of_and_scene_dim_name_a_maud_scene_and_nothing_else(seed):
    """``potential_of`` gives a MaudCalculator's potential (a subclass's too)
    and None for another calculator, no calculator or no atoms; ``scene_dim``
    its dim, else 3."""
    from ase.calculators.emt import EMT

    from ase_maud.bench.doubles import NoisyEnergy
    from ase_maud.calculator.identify import potential_of, scene_dim
    rng = np.random.default_rng(seed)
    dim = int(rng.choice([2, 3]))
    atoms = build('all_pairs2d' if dim == 2 else 'all_pairs', int(rng.integers(4, 9)), seed=seed)
    assert potential_of(atoms) is atoms.calc.potential
    assert scene_dim(atoms) == atoms.calc.dim == dim
    atoms.calc = NoisyEnergy(1e-3, seed, True, **atoms.calc.parameters)
    assert potential_of(atoms) is atoms.calc.potential
    atoms.calc = EMT()
    assert potential_of(atoms) is None and scene_dim(atoms) == 3
    atoms.calc = None
    assert potential_of(atoms) is None and potential_of(None) is None
