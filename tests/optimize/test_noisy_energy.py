"""Runs whose energies are noisier than what their last steps gain (a huge
scene on the FMM, whose energy's error is relative to an energy of 1e8) still
converge: where two energies differ by less than their errors the step is
judged by the forces (ase_maud.optimize.step_length.merit_change). The scene here is small,
its noise large: a calculator that adds seeded noise of 1 % to each energy
and declares it (ase_maud/bench/doubles.py, NoisyEnergy)."""

import numpy as np
import pytest

from ase_maud import Maud, MaudCalculator
from ase_maud.analysis.stationary import classify
from ase_maud.bench.doubles import NoisyEnergy
from ase_maud.bench.optimizers import ScipyLBFGSB
from ase_maud.errors import StagnationError
from ase_maud.scenes.catalogue import build

NOISE = 1e-2


def noisy(scene, size, seed, declare=True):
    """The scene ``(scene, size, seed)`` with a :class:`NoisyEnergy` calculator
    of the same potential (its noise declared or not), and an exact copy of it
    at the same start."""
    atoms = build(scene, size, seed=seed)
    exact = atoms.copy()
    exact.calc = MaudCalculator(**atoms.calc.parameters)
    atoms.calc = NoisyEnergy(NOISE, seed, declare, **atoms.calc.parameters)
    return atoms, exact


def exact_energy(atoms):
    """The energy of ``atoms`` without noise."""
    copy = atoms.copy()
    copy.calc = MaudCalculator(**{**atoms.calc.parameters, 'backend': 'numba'})
    return copy.get_potential_energy(), copy


def last_gains(calc, steps):
    """The largest exact energy change over the last ``steps`` calls, as a
    fraction of the noise of the last energy."""
    exact = np.asarray(calc.exact)
    return np.abs(np.diff(exact[-steps - 1:])).max() / (NOISE * abs(exact[-1]))


@pytest.mark.parametrize('seed', range(3))
def test_a_net_whose_noise_exceeds_its_gains_converges_to_l_bfgs_b_minimum(seed):
    """A hanging net of 196 points (the springs model, the large scenes'
    one) to fmax 1e-5 with its energy 1 % noisy: its last steps gain less
    than 1e-3 of the noise, and it ends at SciPy's L-BFGS-B minimum from the
    same start on the exact calculator."""
    atoms, reference = noisy('hanging_net', 14, seed)
    with Maud(atoms, logfile=None) as opt:
        assert opt.model.name == 'springs'
        assert opt.run(fmax=1e-5, steps=150)
    assert last_gains(atoms.calc, 10) < 1e-3
    energy, exact = exact_energy(atoms)
    assert np.linalg.norm(exact.get_forces(), axis=1).max() < 1e-5
    assert ScipyLBFGSB(reference).run(fmax=1e-5, steps=3000)
    assert energy == pytest.approx(reference.get_potential_energy(), rel=1e-10)


@pytest.mark.parametrize('seed', range(3))
def test_a_maud_calculator_that_hides_its_noise_is_taken_at_its_word(seed):
    """The same runs with the noise undeclared by a MaudCalculator, which
    declares its accuracy: its energies are trusted (no noise is learnt from
    the steps, as for a plain ASE calculator), so every step is taken back
    once the gains fall below the hidden noise, until gamma underflows; a
    MaudCalculator's own noise is always declared."""
    atoms, _ = noisy('hanging_net', 14, seed, declare=False)
    with Maud(atoms, logfile=None) as opt, pytest.raises(StagnationError, match='gamma'):
        opt.run(fmax=1e-5, steps=150)


@pytest.mark.parametrize('seed', range(3))
def test_a_tree_whose_noise_exceeds_its_gains_ends_at_a_minimum(seed):
    """A tree of 24 points (the exact model, the steps taken on arrays) to
    fmax 1e-6 with its energy 1 % noisy: its last steps gain less than a
    tenth of the noise, and the analytic Hessian at its end says minimum."""
    atoms, _ = noisy('tree', 24, seed)
    with Maud(atoms, logfile=None) as opt:
        assert opt.model.name == 'exact'
        assert opt.run(fmax=1e-6, steps=300)
    assert last_gains(atoms.calc, 3) < 0.1
    _, exact = exact_energy(atoms)
    point = classify(exact, ftol=1e-6)
    assert point.verdict == 'minimum' and point.index == 0
