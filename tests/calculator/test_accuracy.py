"""Accuracy follows the run: Maud asks a tol-aware calculator for coarse
sums far from the answer and fine ones near it, and still reaches fmax
(checked with the exact direct sum)."""

import numpy as np
import pytest
from ase.calculators.emt import EMT
from ase.cluster import Icosahedron

from ase_maud import Maud
from ase_maud.calculator.accuracy import ACCURACY_FRACTION
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
