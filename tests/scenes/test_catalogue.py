"""Scenes: valid, seeded, scalable starts with a reachable minimum."""

import numpy as np
import pytest
from ase.collections import g2
from ase.constraints import FixAtoms, FixCartesian
from ase.optimize import BFGS, FIRE
from scipy.optimize import minimize_scalar
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial.distance import pdist

from ase_maud import Maud, MaudCalculator
from ase_maud.physics.topology import fixed_atoms
from ase_maud.scenes.catalogue import COLLECTIVE, LARGE, SCENES, SUITE, SUITES, build

CASES = [(name, None) for name in SCENES] + SUITE
UNITS = [(0, 1.0, 1.0), (3, 2.5, 0.3), (11, 0.04, 7.0)]  # seed, a, Q


def assert_held_together(atoms):
    """One spring component, or every component holds a fixed point."""
    n, springs = len(atoms), atoms.calc.springs
    graph = coo_matrix((np.ones(len(springs)), springs.T), shape=(n, n))
    count, labels = connected_components(graph, directed=False)
    fixed = [i for c in atoms.constraints if isinstance(c, FixAtoms)
             for i in c.get_indices()]
    if fixed:
        assert set(labels[fixed]) == set(range(count))
    else:
        assert count == 1


@pytest.mark.parametrize('seed, a, Q', UNITS)
@pytest.mark.parametrize('name, size', CASES)
def test_start_is_valid_and_not_converged(name, size, seed, a, Q):
    atoms = build(name, size, seed=seed, a=a, Q=Q)
    calc = atoms.calc
    assert isinstance(calc, MaudCalculator)
    assert calc.parameters['a'] == a and calc.parameters['Q'] == Q
    assert not atoms.pbc.any()
    for c in atoms.constraints:   # fixed points; a plane's z (keep_on_plane)
        assert isinstance(c, FixAtoms) or (calc.parameters['dim'] == 2 and isinstance(
            c, FixCartesian) and c.mask.tolist() == [False, False, True])
    assert np.isfinite(atoms.get_potential_energy())
    forces = atoms.get_forces()
    assert np.isfinite(forces).all()
    assert np.linalg.norm(forces, axis=1).max() > 1e-3 * Q * a
    assert pdist(atoms.positions).min() > 0.05 * a
    if calc.parameters['dim'] == 2:
        assert np.all(atoms.positions[:, 2] == atoms.positions[0, 2])
    assert_held_together(atoms)


@pytest.mark.parametrize('name, size', CASES)
def test_seed_fixes_start_and_a_scales_it(name, size):
    positions = build(name, size, seed=5).positions
    assert np.array_equal(build(name, size, seed=5).positions, positions)
    assert not np.allclose(build(name, size, seed=6).positions, positions)
    scaled = build(name, size, seed=5, a=3.7, Q=0.2).positions
    np.testing.assert_allclose(scaled, 3.7 * positions, rtol=1e-12, atol=0)


@pytest.mark.parametrize('name', [n for n in g2.names if len(g2[n]) > 1])
def test_every_g2_molecule_is_one_bond_graph(name):
    atoms = build('molecule', name, seed=2)
    assert atoms.get_chemical_formula() == g2[name].get_chemical_formula()
    assert pdist(atoms.positions).min() > 0.05
    assert_held_together(atoms)


def test_scenes_are_what_they_say():
    a = 2.0
    chain = build('chain', 30, a=a)
    assert list(chain.constraints[0].get_indices()) == [0, 29]
    assert np.isclose(chain.get_distance(0, 29), 10 * a)
    ring = build('ring', 50, a=a)  # equilibrium radius 12.677155 a
    radii = np.linalg.norm(ring.positions - ring.positions.mean(0), axis=1)
    assert abs(radii.mean() / (12.677155 * a) - 1) < 0.05
    net = build('hanging_net', 8, a=a)
    edge = net.constraints[0].get_indices()
    x, y, z = net.positions[edge].T
    assert len(edge) == 28 and np.ptp(z) > 2 * a
    np.testing.assert_allclose(z, (x**2 - y**2) / (8 * a), atol=1e-12)
    assert len(build('net2d', 8).constraints[0].get_indices()) == 28
    assert len(build('random_graph', 30).calc.springs) == 45
    assert len(build('all_pairs', 10).calc.springs) == 45
    mol = build('molecule', 'C6H6', a=a)
    i, j = mol.calc.springs.T
    bonds = np.linalg.norm(mol.positions[i] - mol.positions[j], axis=1)
    assert len(bonds) == 12 and abs(bonds.mean() / a - 1) < 0.1


def test_build_names_sizes_and_errors():
    assert len(build('ring')) == 24 and len(build('net2d')) == 64
    assert len(build('molecule', 'CH4')) == 5
    with pytest.raises(ValueError, match='ring, chain'):
        build('torus')
    with pytest.raises(ValueError, match='size >= 3'):
        build('chain', 2)
    with pytest.raises(ValueError, match='single atom'):
        build('molecule', 'H')
    assert {name for suite in SUITES.values() for name, _ in suite} == set(SCENES)
    assert all(len(build(name, size)) < 60 for name, size in SUITE)
    assert SUITES['small'] is SUITE and SUITES['large'] is LARGE
    assert SUITES['collective'] is COLLECTIVE


# The chain takes FIRE longest by far: in the full run only.
@pytest.mark.parametrize('name, size', [
    pytest.param(name, size, marks=pytest.mark.integration) if name == 'chain' else (name, size)
    for name, size in SUITE])
def test_fire_reaches_a_minimum(name, size):
    atoms = build(name, size)
    opt = FIRE(atoms, logfile=None)
    assert opt.run(fmax=1e-4, steps=5000), f'{name}: {opt.nsteps} steps'
    assert np.linalg.norm(atoms.get_forces(), axis=1).max() < 1e-4
    print(f'FIRE {name} {size}: {opt.nsteps} steps')


@pytest.mark.integration
@pytest.mark.parametrize('name, size', COLLECTIVE + LARGE)
def test_large_suite_scenes_are_large_and_valid(name, size):
    atoms = build(name, size)
    assert len(atoms) == {'hanging_net': size**2, 'weighted_net': size**2, 'wheel': size + 1,
                          'hub_net': 1 + size * (size + 2)}.get(name, size)
    assert len(atoms) >= 40
    forces = atoms.get_forces()
    assert np.isfinite(atoms.get_potential_energy()) and np.isfinite(forces).all()
    assert np.linalg.norm(forces, axis=1).max() > 1e-3
    assert_held_together(atoms)


@pytest.mark.parametrize('seed', [0, 4])
def test_tree_is_a_tree_with_long_branches_and_a_fixed_root(seed):
    atoms = build('tree', 200, seed=seed, a=2.0)
    parent, child = atoms.calc.springs.T
    assert len(parent) == 199 and np.array_equal(child, np.arange(1, 200))
    assert np.all(parent < child)        # n - 1 springs, each to an earlier point
    assert list(atoms.constraints[0].get_indices()) == [0]
    extends = np.mean(parent == child - 1)   # 1/2 + (1/2) / i on average
    assert 0.45 < extends < 0.65
    lengths = np.linalg.norm(atoms.positions[child] - atoms.positions[parent], axis=1)
    # A unit step from the parent, unless moved apart from a close point.
    assert np.mean(np.isclose(lengths, 2.0, rtol=1e-12)) > 0.8
    assert_held_together(atoms)


def test_wheel_is_a_hub_with_spokes_and_a_rim_at_its_planar_radius():
    n = 24
    atoms = build('wheel', n, seed=1)
    springs = np.sort(atoms.calc.springs, axis=1)
    degree = np.bincount(springs.ravel(), minlength=n + 1)
    assert len(atoms) == n + 1 and len(springs) == 2 * n
    assert degree[0] == n and np.all(degree[1:] == 3)
    assert {tuple(s) for s in springs[n:]} == (
        {(i, i + 1) for i in range(1, n)} | {(1, n)})
    assert np.array_equal(atoms.positions[0], np.zeros(3))
    assert np.ptp(atoms.positions[1:, 2]) > 0        # off the plane
    phi = 2 * np.pi * np.arange(n) / n
    circle = np.column_stack([np.cos(phi), np.sin(phi), np.zeros(n)])

    def energy(radius):
        perfect = atoms.copy()
        perfect.calc = MaudCalculator(atoms.calc.springs)
        perfect.positions[1:] = radius * circle
        return perfect.get_potential_energy()

    best = minimize_scalar(energy, bracket=(1, 2, 4), tol=1e-10).x
    radii = np.linalg.norm(atoms.positions[1:, :2], axis=1)
    assert abs(radii.mean() / best - 1) < 0.03


def test_all_pairs2d_is_a_planar_cluster():
    atoms = build('all_pairs2d', 12, seed=2, a=0.5)
    assert atoms.calc.parameters['dim'] == 2
    assert len(atoms.calc.springs) == 66 and not fixed_atoms(atoms).any()
    assert np.all(atoms.positions[:, 2] == 0)
    radius = np.linalg.norm(atoms.positions, axis=1).max()
    assert radius <= 0.5 * np.sqrt(12 / np.pi) and radius > 0.5


@pytest.mark.parametrize('name, size', [('tree', 12), ('wheel', 12), ('all_pairs2d', 8)])
def test_maud_and_bfgs_reach_a_minimum(name, size):
    energies = {}
    for opt in (BFGS, Maud):
        atoms = build(name, size, seed=0)
        with opt(atoms, logfile=None) as dyn:
            assert dyn.run(fmax=1e-6, steps=5000), f'{opt.__name__}: {dyn.nsteps}'
        energies[opt.__name__] = atoms.get_potential_energy()
    # The same minimum or, for Maud, a lower one.
    assert energies['Maud'] <= energies['BFGS'] * (1 + 1e-8)


@pytest.mark.parametrize('seed', [0, 3])
def test_form_finding_scenes_are_what_they_say(seed):
    hub = build('hub_net', 6, seed=seed)
    degree = np.bincount(hub.calc.springs.ravel(), minlength=len(hub))
    assert len(hub) == 1 + 6 * 8 and degree[0] == 8       # the hub holds 8 spokes
    assert fixed_atoms(hub).sum() == 8                     # the outer ring
    disc = build('disc', 200, seed=seed)
    rim = np.flatnonzero(fixed_atoms(disc))
    radius = np.linalg.norm(disc.positions[rim, :2], axis=1)
    np.testing.assert_allclose(radius, np.sqrt(200 / np.pi))
    inner = np.linalg.norm(disc.positions[~fixed_atoms(disc), :2], axis=1)
    assert inner.max() < radius[0]
    graph = build('neighbour_graph', 300, seed=seed)
    degree = np.bincount(graph.calc.springs.ravel(), minlength=300)
    assert degree.min() >= 3 and not fixed_atoms(graph).any()
    assert_held_together(graph)


# -- 5. errors that name the input ------------------------------------------------------

@pytest.mark.parametrize('args, keywords, match', [
    (('ring', 'x'), {}, r"ring needs an integer size >= 3, got 'x'"),
    (('ring', np.nan), {}, r'ring needs an integer size >= 3, got nan'),
    (('chain', None), {'seed': 'x'}, r"seed must be a whole number >= 0, got 'x'"),
    (('chain', None), {'seed': 1.5}, r'seed must be a whole number >= 0, got 1.5'),
    (('ring', 8), {'a': 'x'}, r"a must be a finite number >= 0 \(0: no repulsion, "
     r"the force-density method\), got 'x'"),
    (('ring', 8), {'b': 1}, r"build takes the keywords a and Q, got \['b'\]"),
    (('molecule', 'XYZ'), {}, r"molecule needs the name of a molecule of ase.collections.g2 "
                              r".*got 'XYZ'"),
    ((3,), {}, r'unknown scene 3; known: dimer'),
])
def test_scene_errors_name_the_input(args, keywords, match):
    with pytest.raises(ValueError, match=match):
        build(*args, **keywords)
