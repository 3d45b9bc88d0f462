"""Divergence (ase_maud.optimize.monitor, issue 30): "diverged" only when there
is no minimum.

A scene whose calculator proves a finite minimum (every spring component
held, the loads held) is never stopped for spreading; where nothing is
proved, a run is stopped only when its forces show no balance in reach
(the secant curvature along its growth). Each false alarm here was a
DivergenceError on 5f059dc.
"""

import io

import numpy as np
import pytest
from ase import Atoms
from ase.calculators.calculator import Calculator, all_changes
from ase.constraints import FixCartesian, FixedPlane
from ase.optimize import BFGS

from ase_maud import DivergenceError, Maud, MaudCalculator, NoEquilibriumError
from ase_maud.analysis.stationary import classify
from ase_maud.cli.command import main
from ase_maud.scenes.builders import chain
from ase_maud.scenes.hard_cases import heavy_net


def loaded_net(seed, load, plane=None):
    """:func:`heavy_net` pulled by ``-load``; ``plane``: an interior point
    held to its z plane by FixedPlane (a constraint no proof covers)."""
    atoms = heavy_net(6, seed=seed, load=-load)
    if plane is not None:
        atoms.set_constraint([*atoms.constraints, FixedPlane(plane, [0, 0, 1])])
    return atoms


def relax(atoms, opt=Maud, fmax=1e-6, steps=5000, **kwargs):
    log = io.StringIO()
    dyn = opt(atoms, logfile=log, **kwargs)
    return dyn.run(fmax=fmax, steps=steps), dyn, log.getvalue()


def assert_bfgs_minimum(atoms, make, fmax, maxstep=0.2):
    """``atoms`` are at a minimum (classify) with BFGS's energy from the
    same start (``make()``; ``maxstep`` BFGS's)."""
    assert classify(atoms, ftol=10 * fmax).verdict == 'minimum'
    reference = make()
    assert relax(reference, BFGS, fmax=fmax, steps=5000, maxstep=maxstep)[0]
    assert atoms.get_potential_energy() == pytest.approx(
        reference.get_potential_energy(), rel=1e-10)


@pytest.mark.parametrize('seed', [1, 2])
def test_a_loaded_net_far_below_its_supports_converges(seed):
    # On 5f059dc: DivergenceError at step ~255 (spread 3 x a N); its minimum
    # lies at about 4.7 x a N. The fixed boundary proves the minimum.
    atoms = loaded_net(seed, -100.0)
    assert atoms.calc.potential.minimum_proved(atoms)
    converged, dyn, log = relax(atoms)
    assert converged, log[-400:]
    assert dyn.monitor.bounded and dyn.monitor.marks == 0
    size = np.linalg.norm(atoms.positions - atoms.positions.mean(axis=0), axis=1).max()
    assert size > 3 * len(atoms)   # beyond the old bound
    assert_bfgs_minimum(atoms, lambda: loaded_net(seed, -100.0), 1e-6)


@pytest.mark.filterwarnings('ignore:You are using a \\*very\\* large')
@pytest.mark.parametrize('seed', [3, 4])
def test_an_unproved_net_that_grows_far_converges(seed):
    # FixedPlane on one point leaves the minimum unproved: the run is judged
    # by its forces, and the springs' curvature along its growth shows the
    # balance ahead (on 5f059dc: DivergenceError).
    make = lambda: loaded_net(seed, -1e3, plane=20)  # noqa: E731
    atoms = make()
    assert not atoms.calc.potential.minimum_proved(atoms)
    converged, dyn, log = relax(atoms, fmax=1e-4)
    assert converged, log[-400:]
    assert not dyn.monitor.bounded and dyn.monitor.marks >= 3
    # FixedPlane along z is FixCartesian of z, which classify reads
    atoms.set_constraint([atoms.constraints[0], FixCartesian(20, [False, False, True])])
    assert_bfgs_minimum(atoms, make, 1e-4, maxstep=20.0)   # 1100 a away


def test_the_cli_relaxes_the_loaded_net_of_the_issue(tmp_path, capsys):
    assert main(['relax', '--scene', 'hanging_net', '--size', '6', '--load', '0', '0',
                 '-100', '--traj', str(tmp_path / 'm.traj'), '--quiet']) == 0
    assert capsys.readouterr().out.startswith('converged: hanging_net 36 points')
    with pytest.raises(SystemExit):
        main(['relax', '--divergence-factor', '1', '--traj', str(tmp_path / 'n.traj')])
    assert 'divergence_factor must be a number > 1' in capsys.readouterr().err


@pytest.mark.parametrize('seed', [0, 5])
def test_a_free_scene_pushed_by_a_load_still_diverges(seed):
    # A chain held to a plane by FixedPlane (so no net load is proved
    # unheld), pushed along x: nothing slows it.
    atoms = chain(8, seed=seed)
    loads = np.zeros((8, 3))
    loads[:, 0] = 1.0
    atoms.set_constraint(FixedPlane(0, [0, 0, 1]))
    atoms.calc = MaudCalculator(atoms.calc.springs, loads=loads)
    with pytest.raises(DivergenceError, match='came no nearer') as error:
        relax(atoms, steps=2000)
    assert 'drifted by' in str(error.value)
    atoms = chain(8, seed=seed)   # switched off: runs on
    atoms.set_constraint(FixedPlane(0, [0, 0, 1]))
    atoms.calc = MaudCalculator(atoms.calc.springs, loads=loads)
    assert not relax(atoms, steps=300, divergence_factor=np.inf)[0]


@pytest.mark.parametrize('seed', [0, 1])
def test_a_repulsive_pair_with_nothing_holding_it_stops(seed):
    rng = np.random.default_rng(seed)
    from ase import Atoms
    pair = Atoms('H2', positions=[[0, 0, 0], [*rng.uniform(0.5, 1.5, 2), 0]])
    pair.calc = MaudCalculator([], dim=2)   # 2D: nothing proved either way
    with pytest.raises(DivergenceError, match='spread to'):
        relax(pair, steps=200)
    pair.calc = MaudCalculator([])   # 3D: proved before the first step
    with pytest.raises(NoEquilibriumError, match='no finite minimum'):
        relax(pair)


class _Repulsion(Calculator):
    """Point charges repelling (E = sum 1/r), a calculator with forces only:
    no finite minimum, but forces that fade as the points spread."""

    implemented_properties = ['energy', 'forces']

    def calculate(self, atoms=None, properties=('energy',), system_changes=all_changes):
        super().calculate(atoms, properties, system_changes)
        d = self.atoms.positions[:, None] - self.atoms.positions[None]
        r = np.linalg.norm(d, axis=2)
        np.fill_diagonal(r, np.inf)
        self.results['energy'] = 0.5 * (1 / r).sum()
        self.results['forces'] = (d / r[..., None] ** 3).sum(axis=1)


@pytest.mark.parametrize('seed', [31, 32])
def test_another_calculators_spreading_run_ends_by_fmax_as_with_bfgs(seed):
    """Issue 32: the divergence test is for a MaudCalculator's scene. Charges
    that repel under a calculator with forces only spread until their forces
    fall below fmax, and BFGS stops there; Maud does too (it raised
    DivergenceError at 8 times the start's size before)."""
    start = np.random.default_rng(seed).normal(scale=0.5, size=(4, 3))
    ends = {}
    for opt in (BFGS, Maud):
        atoms = Atoms('H4', positions=start)
        atoms.calc = _Repulsion()
        with opt(atoms, logfile=None) as dyn:
            assert dyn.run(fmax=0.01, steps=2000)
        ends[opt] = atoms
    fresh = ends[Maud].copy()
    fresh.calc = _Repulsion()
    assert np.linalg.norm(fresh.get_forces(), axis=1).max() <= 0.01
    size = np.linalg.norm(start - start.mean(axis=0), axis=1).max()
    assert np.ptp(ends[Maud].positions, axis=0).max() > 8 * size   # it did spread
