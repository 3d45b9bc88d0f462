"""search_saddles' defaults find what its options find: a net held at points
that span a plane gets the path to its mirror image by itself, a free scene
whose climbs found nothing the path to a neighbouring minimum; and every
search reports its CPU in units of one force call of the scene."""

import numpy as np
import pytest
from ase.constraints import FixAtoms

from ase_maud import Maud, classify, search_saddles
from ase_maud.analysis.stationary import displace_along_mode
from ase_maud.counting import fresh_copy
from ase_maud.scenes import build
from ase_maud.scenes.families import FAMILIES


def corner_net(size: int, seed: int):
    """``net3d`` of ``size`` x ``size`` points with its four corners held."""
    atoms = build('net3d', size, seed=seed)
    side = int(round(np.sqrt(len(atoms))))
    atoms.set_constraint(FixAtoms([0, side - 1, side * (side - 1), side * side - 1]))
    return atoms


@pytest.mark.parametrize('seed', [11, 12, 13])
def test_the_default_call_finds_a_corner_net_s_saddle_by_its_mirror(seed):
    net = corner_net(6, seed)
    assert Maud(net, logfile=None).run(fmax=1e-8, steps=5000)
    assert classify(net).verdict == 'minimum'
    found = search_saddles(net, modes=0, local=0)
    assert found.saddles, found.report()
    point = classify(fresh_copy(found.saddles[0]), ftol=1e-6)
    assert point.verdict == 'saddle' and point.index == 1
    assert [a.kind for a in found.found_by] == ['path']
    none = search_saddles(net, modes=0, local=0, mirror=False)
    assert not none.saddles and not none.attempts   # what the default adds


@pytest.mark.parametrize('seed', [14, 15])
def test_a_search_for_a_first_saddle_takes_the_mirror_path_first(seed):
    """With ``wanted``, the path to the mirror image is the first attempt and,
    finding a verified saddle, the only one; asked for every attempt, the
    climbs and activations come first and the path only if they found none."""
    net = corner_net(6, seed)
    assert Maud(net, logfile=None).run(fmax=1e-8, steps=5000)
    first = search_saddles(net, modes=1, local=1, wanted=1, seed=seed)
    assert [a.kind for a in first.attempts] == ['path'] and first.rounds == 0
    point = classify(fresh_copy(first.saddles[0]), ftol=1e-6)
    assert point.verdict == 'saddle' and point.index == 1
    every = search_saddles(net, modes=1, local=1, seed=seed)
    kinds = [a.kind for a in every.attempts]
    assert kinds[:3] == ['mode', 'mode', 'local']
    if 'path' in kinds:
        assert not any(a.outcome == 'saddle' for a in every.attempts[:kinds.index('path')])
    else:
        assert every.saddles


def test_a_flat_scene_gets_no_mirror_attempt_by_default():
    """A 2D scene (every point on one plane with its held points) is its own
    mirror image: the default makes no path attempt."""
    ring = build('ring', 12, seed=3)
    ring.set_constraint(FixAtoms([0, 4, 8]))
    assert Maud(ring, logfile=None).run(fmax=1e-8, steps=5000)
    found = search_saddles(ring, modes=0, local=0)
    assert not any(a.kind == 'path' for a in found.attempts)


@pytest.mark.parametrize('seed', [0, 1])
def test_a_search_reports_its_cpu_in_force_calls(seed):
    cluster = build('all_pairs', 7, seed=seed)
    assert Maud(cluster, logfile=None).run(fmax=1e-9, steps=2000)
    found = search_saddles(cluster, modes=1, local=1, wanted=1, seed=seed)
    assert found.force_call_cpu_s > 0 and np.isfinite(found.force_call_cpu_s)
    assert found.cpu_in_force_calls == pytest.approx(found.cpu_s / found.force_call_cpu_s)
    lines = found.report().splitlines()
    assert "force calls' CPU" in lines[0]
    assert all("force calls' CPU" in line for line in lines[1:])


@pytest.mark.integration
@pytest.mark.parametrize('family, seed', [('random_tree', 1), ('random_tree', 3),
                                          ('knn_cluster', 1)])
def test_a_free_scene_whose_attempts_ran_out_gets_the_path_to_a_neighbouring_minimum(
        family, seed):
    """Free scenes of 30-50 points (no mirror: nothing held) where every
    climb runs out of a budget of 20 equivalents: the default call relaxes
    where the attempts stopped into another minimum and takes the band to it.
    The saddle is index 1 from a fresh calculator, and pushed both ways along
    its negative mode it relaxes into two minima below it: the band's own
    saddle joins the start to the other minimum; a refinement from the band
    may reach another saddle first (the path takes the first verified one,
    ``saddle_between(..., any_saddle=True)``), which then joins two others."""
    minimum = FAMILIES[family](seed, (30, 50))
    assert Maud(minimum, logfile=None).run(fmax=1e-8, steps=5000)
    found = search_saddles(minimum, modes=1, local=2, budget=20, seed=seed, wanted=1)
    assert [a.kind for a in found.found_by] == ['neighbour'], found.report()
    assert all(a.outcome != 'saddle' for a in found.attempts[:-1])
    saddle = fresh_copy(found.saddles[0])
    point = classify(saddle, method='dense')
    assert (point.index, point.n_zero, point.stationary) == (1, 0, True)
    energies = []
    for side in displace_along_mode(saddle, point):
        assert Maud(side, logfile=None).run(fmax=1e-8, steps=5000)
        assert classify(side, method='dense').verdict == 'minimum'
        energies.append(side.get_potential_energy())
    assert abs(energies[0] - energies[1]) > 1e-9 * abs(energies[0])   # two minima
    assert saddle.get_potential_energy() > max(energies)
