"""Accuracy follows the run: Maud asks a tol-aware calculator for coarse
sums far from the answer and fine ones near it, and still reaches fmax
(checked with the exact direct sum); forces below fmax on sums too coarse to
say so are computed again before it stops, and the calculator's own tol is
back after the run."""

import numpy as np
import pytest
from ase.calculators.emt import EMT
from ase.cluster import Icosahedron

from ase_maud import Maud
from ase_maud.calculator import MaudCalculator
from ase_maud.calculator.accuracy import ACCURACY_FRACTION, MAX_RUN_TOL, settled
from ase_maud.physics.dofs import free_dofs
from ase_maud.scenes.catalogue import build

pytest.importorskip('fmm3dpy')


def _record_tolerances(calc):
    """Wrap ``calc.calculate`` to record (backend, tol, the force scale the
    tol was asked against) of every call."""
    seen, calculate = [], calc.calculate

    def recording(*args, **kwargs):
        scale = calc.last_force_scale
        calculate(*args, **kwargs)
        seen.append((calc.last_backend, calc.parameters['tol'], scale))
    calc.calculate = recording
    return seen


@pytest.mark.parametrize('seed', [0, 1])
def test_maud_reaches_fmax_on_the_fmm_path(seed):
    atoms = build('hanging_net', 24, seed=seed)          # 576 points
    atoms.calc.set(crossover=300)                         # the FMM from 300 points
    seen = _record_tolerances(atoms.calc)
    with Maud(atoms, logfile=None) as opt:
        assert opt.run(fmax=1e-6, steps=3000)
    assert {backend for backend, _, _ in seen} == {'fmm'}
    tolerances = [tol for _, tol, _ in seen[1:]]            # the first is the default
    assert tolerances[0] > 100 * tolerances[-1]          # coarse early, fine late
    # The answer, checked with the exact direct sum.
    exact = atoms.copy()
    exact.calc = type(atoms.calc)(**{**atoms.calc.parameters, 'backend': 'numba'})
    assert np.linalg.norm(exact.get_forces(), axis=1).max() < 1e-6
    reference = build('hanging_net', 24, seed=seed)
    reference.calc.set(backend='numba')
    with Maud(reference, logfile=None) as opt:
        assert opt.run(fmax=1e-6, steps=3000)
    assert exact.get_potential_energy() == pytest.approx(
        reference.get_potential_energy(), rel=1e-10)


@pytest.mark.parametrize('watched', [False, True])
@pytest.mark.parametrize('seed', [3, 4])
def test_energies_are_compared_within_their_own_error(monkeypatch, watched, seed):
    """On the FMM path a step compares energies within the error the
    calculator declares for them (``last_energy_error``), below the forces'
    relative error times the energy (a tenth at most, in most steps a
    hundredth or less), on arrays and in ASE's loop."""
    atoms = build('hanging_net', 24, seed=seed)          # 576 points
    atoms.calc.set(crossover=300)                         # the FMM from 300 points
    seen = []
    with Maud(atoms, logfile=None) as opt:
        kind = type(opt.strategy)
        step = kind.step

        def recording(self, state, x, merit, forces, noise, local_at):
            calc = atoms.calc
            seen.append((noise, calc.last_energy_error / abs(merit), calc.last_tolerance))
            return step(self, state, x, merit, forces, noise, local_at)
        monkeypatch.setattr(kind, 'step', recording)
        if watched:
            opt.attach(lambda: None)
        assert opt.run(fmax=1e-4, steps=500)
    assert len(seen) > 10
    ratios = []
    for noise, declared, force_tolerance in seen:
        assert noise == declared > 0
        ratios.append(noise / force_tolerance)
    assert max(ratios) < 0.15 and np.median(ratios) < 1e-2


@pytest.mark.parametrize('watched', [False, True])
def test_asked_tolerance_is_a_fraction_of_fmax(watched):
    """Each call asks for a force error of a tenth of the larger of the run's
    fmax and the largest force (on the free points) of the point before it,
    on arrays and in ASE's loop."""
    atoms = build('hanging_net', 10, seed=2)
    free = free_dofs(atoms, 3)
    seen = _record_tolerances(atoms.calc)
    largest = []
    calculate = atoms.calc.calculate

    def recording(*args, **kwargs):
        calculate(*args, **kwargs)
        largest.append(np.linalg.norm(atoms.calc.results['forces'] * free, axis=1).max())
    atoms.calc.calculate = recording
    with Maud(atoms, logfile=None) as opt:
        if watched:
            opt.attach(lambda: None)
        assert opt.run(fmax=1e-4, steps=500)
    assert len(seen) > 10
    for (_, tol, scale), before in zip(seen[-5:], largest[-6:-1], strict=True):
        assert tol * scale == pytest.approx(ACCURACY_FRACTION * max(1e-4, before), rel=1e-12)


def test_calculators_without_tol_are_left_alone():
    atoms = Icosahedron('Cu', 2)
    atoms.rattle(0.05, seed=3)
    atoms.calc = EMT()
    before = dict(atoms.calc.parameters)
    with Maud(atoms, logfile=None) as opt:
        assert opt.run(fmax=1e-3, steps=500)
    assert dict(atoms.calc.parameters) == before


class CoarseHidesForces(MaudCalculator):
    """A MaudCalculator that keeps to the letter of its promise: at a ``tol``
    of at least ``MAX_RUN_TOL`` it says its forces are that coarse and
    shrinks each toward zero by up to ``tol`` times the force scale (zero
    where smaller), an error within the promise."""

    def calculate(self, *args, **kwargs):
        super().calculate(*args, **kwargs)
        tol = self.parameters['tol']
        if tol >= MAX_RUN_TOL:
            self.last_tolerance = tol
            forces = self.results['forces']
            size = np.linalg.norm(forces, axis=1, keepdims=True)
            hidden = tol * self.last_force_scale
            forces *= np.clip(size - hidden, 0.0, None) / np.where(size > 0, size, 1.0)


def _near_minimum(seed):
    """A hanging net relaxed to forces below what a coarse call can see, on
    a :class:`CoarseHidesForces`, and the exact largest force there."""
    atoms = build('hanging_net', 8, seed=seed)
    with Maud(atoms, logfile=None) as opt:
        assert opt.run(fmax=1e-3, steps=500)
    atoms.calc = CoarseHidesForces(**atoms.calc.parameters)
    return atoms


def _exact_fmax(atoms):
    """The largest force on a free point, by the exact direct sum."""
    exact = atoms.copy()
    exact.calc = MaudCalculator(**{**atoms.calc.parameters, 'backend': 'numba'})
    return np.linalg.norm(exact.get_forces(), axis=1).max()   # held points' rows are 0


@pytest.mark.parametrize('watched', [False, True])
@pytest.mark.parametrize('seed', [3, 4])
def test_a_coarse_call_below_fmax_is_computed_again(seed, watched):
    """Forces a coarse call shows below fmax are not taken as converged: the
    run computes them again finely, goes on, and ends below fmax by the exact
    sum (on arrays and in ASE's loop; the calculator's own tol is coarse)."""
    atoms = _near_minimum(seed)
    assert 1e-6 < _exact_fmax(atoms) < 1e-3
    atoms.calc.set(tol=MAX_RUN_TOL)   # a run's first call is at the calculator's own tol
    assert np.linalg.norm(atoms.get_forces(), axis=1).max() == 0.0   # all hidden, as promised
    atoms.calc.reset()
    with Maud(atoms, logfile=None) as opt:
        if watched:
            opt.attach(lambda: None)
        assert opt.run(fmax=1e-6, steps=500)
        assert opt.nsteps > 0
    assert _exact_fmax(atoms) < 1e-6


@pytest.mark.parametrize('watched', [False, True])
def test_the_calculators_tol_is_back_after_a_run(watched):
    """A run asks its calculator for other tols; after it, the calculator's
    own is back, also when the calculator was called before the run."""
    atoms = build('hanging_net', 8, seed=5)
    atoms.get_forces()                 # a force scale known before the run
    own = atoms.calc.parameters['tol']
    with Maud(atoms, logfile=None) as opt:
        if watched:
            opt.attach(lambda: None)
        assert opt.run(fmax=1e-4, steps=500)
    assert atoms.calc.parameters['tol'] == own


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_settled_is_the_largest_force_plus_the_promised_error(seed):
    """Forces prove fmax when the largest shown plus the promised error (the
    last tol times the force scale) is below it; a calculator without a tol
    is taken at its word."""
    rng = np.random.default_rng(seed)
    calc = MaudCalculator(springs=[[0, 1]])
    fmax, scale = rng.uniform(1e-4, 1.0), rng.uniform(1.0, 100.0)
    calc.last_force_scale, shown = scale, rng.uniform(0.1, 0.9) * fmax
    for error, proved in ((0.99, True), (1.01, False)):
        calc.last_tolerance = error * (fmax - shown) / scale
        assert settled(calc, fmax, shown) is proved
    calc.last_tolerance = 0.0
    assert settled(calc, fmax, shown) and not settled(calc, fmax, 1.01 * fmax)
    assert settled(EMT(), fmax, shown) and not settled(EMT(), fmax, 1.01 * fmax)
