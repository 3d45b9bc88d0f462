"""Where ASE's optimisers converge, Maud converges (issue 52, item 4),
checked against ASE's BFGS on the same inputs: energies with undeclared
noise (steps judged by the forces once the energy disagrees with them),
a = 0 nets with force densities spread over decades (a quadratic energy: no
step bound, the Newton move its minimum), and basin hopping with large hops
(bounded force calls)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from ase import Atoms
from ase.calculators.emt import EMT
from ase.calculators.lj import LennardJones
from ase.cluster import Icosahedron
from ase.optimize import BFGS
from ase.optimize.basin import BasinHopping

from ase_maud import Maud, MaudCalculator
from ase_maud.bench.doubles import UndeclaredNoise
from ase_maud.scenes.catalogue import build


def fmax_of(atoms, calc):
    copy = atoms.copy()
    copy.calc = calc
    return np.linalg.norm(copy.get_forces(), axis=1).max()


@pytest.mark.parametrize('seed', range(3))
@pytest.mark.parametrize('scene, size', [('hanging_net', 5), ('random_graph', 12),
                                         ('hanging_net', 10)])
def test_undeclared_energy_noise_like_bfgs(scene, size, seed):
    """Energy noise of 1e-2 (forces exact): BFGS converges; so does Maud, to
    the same minimum (the exact forces below fmax), in no more steps."""
    steps = {}
    for optimizer in (BFGS, Maud):
        atoms = build(scene, size, seed=seed)
        parameters = atoms.calc.parameters
        atoms.calc = UndeclaredNoise(MaudCalculator(**parameters), 1e-2, seed)
        with optimizer(atoms, logfile=None) as opt:
            assert opt.run(fmax=1e-4, steps=1000)
        steps[optimizer] = opt.nsteps
        assert fmax_of(atoms, MaudCalculator(**parameters)) < 1e-4
    assert steps[Maud] <= steps[BFGS]


@pytest.mark.parametrize('seed', range(2))
def test_undeclared_energy_noise_on_emt(seed):
    ends = {}
    for optimizer in (BFGS, Maud):
        atoms = Icosahedron('Cu', 2)
        atoms.rattle(0.05, seed=seed)
        atoms.calc = UndeclaredNoise(EMT(), 1e-2, seed)
        with optimizer(atoms, logfile=None) as opt:
            assert opt.run(fmax=1e-3, steps=1000)
        assert fmax_of(atoms, EMT()) < 1e-3
        ends[optimizer] = atoms.copy()
        ends[optimizer].calc = EMT()
    assert ends[Maud].get_potential_energy() == pytest.approx(
        ends[BFGS].get_potential_energy(), abs=1e-4)


@pytest.mark.parametrize('seed', range(2))
@pytest.mark.parametrize('size', [5, 7, 10])
@pytest.mark.parametrize('spread', [1e1, 1e3, 1e6])
def test_a_zero_net_with_any_spread_of_force_densities(size, spread, seed):
    """a = 0 (springs and loads: a quadratic energy), q log-uniform over
    1/spread..spread: Maud in a few steps (the Newton move is the minimum),
    at BFGS's minimum."""
    rng = np.random.default_rng(seed)
    ends, steps = {}, {}
    for optimizer in (BFGS, Maud):
        atoms = build('hanging_net', size, seed=seed)
        k = len(atoms.calc.springs)
        if optimizer is BFGS:
            q = np.exp(rng.uniform(-1, 1, k) * np.log(spread))
        atoms.calc.set(a=0.0, q=q, loads=np.tile([0.0, 0.0, -0.1], (len(atoms), 1)))
        with optimizer(atoms, logfile=None) as opt:
            assert opt.run(fmax=1e-6, steps=3000)
        ends[optimizer], steps[optimizer] = atoms.positions.copy(), opt.nsteps
    assert steps[Maud] <= 5
    scale = np.abs(ends[BFGS]).max()
    np.testing.assert_allclose(ends[Maud], ends[BFGS], atol=1e-4 * scale)


@pytest.mark.parametrize('seed', range(3))
def test_basin_hopping_with_large_hops_ends(seed):
    """BasinHopping of LJ6 with dr=2.5 (fragments fly apart): 10 hops end,
    in force calls of the order of BFGS's (counted; never timed)."""
    calls = {}
    for optimizer in (BFGS, Maud):
        half = 6 ** (1 / 3)
        atoms = Atoms('He6', positions=np.random.RandomState(42 + seed).uniform(
            -half, half, (6, 3)))
        atoms.calc = LennardJones()
        count = [0]
        calculate = atoms.calc.calculate

        def counted(*args, count=count, calculate=calculate, **kwargs):
            count[0] += 1
            assert count[0] < 50000, 'basin hopping spins'
            return calculate(*args, **kwargs)
        atoms.calc.calculate = counted
        np.random.seed(seed)
        with warnings.catch_warnings():
            warnings.simplefilter('ignore')
            with BasinHopping(atoms, temperature=1.0, dr=2.5, optimizer=optimizer,
                              logfile=None, optimizer_logfile=None, trajectory=None,
                              local_minima_trajectory=None) as hopping:
                hopping.run(10)
        calls[optimizer] = count[0]
    assert calls[Maud] <= 5 * calls[BFGS]


@pytest.mark.parametrize('held', [0, 3])
@pytest.mark.parametrize('seed', [0, 1, 2, 5])
def test_a_ring_held_at_one_point_finds_the_free_ring_s_saddle(seed, held):
    """A ring of 8 held at one point (no loads: the hold removes only the
    translations): target='saddle' follows the free ring's modes and ends at
    its saddle, moved to keep the point, in as many steps (it diverged)."""
    from ase.constraints import FixAtoms
    free = build('ring', 8, seed=seed)
    with Maud(free, logfile=None, target='saddle') as opt:
        assert opt.run(fmax=1e-6, steps=500)
    atoms = build('ring', 8, seed=seed)
    start = atoms.positions[held].copy()
    atoms.set_constraint([*atoms.constraints, FixAtoms(indices=[held])])
    with Maud(atoms, logfile=None, target='saddle') as held_opt:
        assert held_opt.run(fmax=1e-6, steps=500)
    assert held_opt.found.verdict == 'saddle' and held_opt.found.index == 1
    assert held_opt.nsteps == opt.nsteps
    np.testing.assert_array_equal(atoms.positions[held], start)
    assert atoms.get_potential_energy() == pytest.approx(free.get_potential_energy(),
                                                         rel=1e-10)
