"""The seeded scene families of ase_maud.scenes.families: a seed gives one
scene, sizes stay in range, and each family's draw relaxes to a minimum."""

import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from ase_maud import Maud, classify
from ase_maud.physics.dofs import free_dofs
from ase_maud.scenes.families import FAMILIES, hub_net, sagging_net

SEEDS = np.random.default_rng(20261206).integers(0, 2**31, size=3).tolist()


@pytest.mark.parametrize('family', sorted(FAMILIES))
@pytest.mark.parametrize('seed', SEEDS)
def test_a_seed_draws_one_scene_within_its_sizes(family, seed):
    one, again = FAMILIES[family](seed, (40, 90)), FAMILIES[family](seed, (40, 90))
    assert 30 <= len(one) <= 100   # grids round their sides
    np.testing.assert_array_equal(one.positions, again.positions)
    np.testing.assert_array_equal(one.calc.parameters['springs'],
                                  again.calc.parameters['springs'])
    other = FAMILIES[family](seed + 1, (40, 90))
    assert len(other) != len(one) or not np.array_equal(other.positions, one.positions)


@pytest.mark.parametrize('family', sorted(FAMILIES))
def test_each_family_relaxes_to_a_minimum(family):
    atoms = FAMILIES[family](SEEDS[0], (30, 50))
    assert Maud(atoms, logfile=None).run(fmax=1e-8, steps=5000)
    assert classify(atoms).verdict == 'minimum'


def test_a_sagging_net_is_loaded_on_its_free_points_only():
    for seed in SEEDS:
        net = sagging_net(seed, (40, 90))
        free = free_dofs(net, 3).all(axis=1)
        loads = net.calc.parameters['loads']
        assert (loads[free, 2] < 0).all() and not loads[~free].any()
        assert 3 <= (~free).sum() < len(net)


def test_sizes_out_of_order_are_refused():
    with pytest.raises(ValueError, match='sizes'):
        sagging_net(0, (500, 100))


def test_a_hub_net_holds_its_outer_ring_and_ties_every_point_to_the_hub():
    """One spring component, the held points the outer ring (each sprung to
    its two neighbours and its spoke), loads on the free points only, all
    equal or none."""
    for seed in SEEDS:
        net = hub_net(seed, (200, 400))
        springs, n = net.calc.parameters['springs'], len(net)
        assert connected_components(coo_matrix((np.ones(len(springs)), springs.T),
                                               shape=(n, n)), directed=False)[0] == 1
        free = free_dofs(net, 3).all(axis=1)
        degree = np.bincount(np.ravel(springs), minlength=n)
        assert (degree[~free] == 3).all() and 8 <= (~free).sum() < n // 2
        loads = net.calc.parameters['loads']
        assert not loads[~free].any() and len(np.unique(loads[free, 2])) == 1
        assert (loads[free, 2] <= 0).all() and not loads[:, :2].any()
