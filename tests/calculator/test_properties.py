"""Property-based tests (hypothesis) over random small scenes, sizes, scales
and springs: the calculator stays finite and matches the finite-difference
gradient, and Maud either converges or stops with a MaudError that says why."""

import io
import os
from itertools import combinations

import numpy as np
import pytest
from ase import Atoms
from ase.calculators.fd import calculate_numerical_forces
from ase.constraints import FixAtoms
from hypothesis import event, given, settings
from hypothesis import strategies as st

from ase_maud import Maud, MaudCalculator, MaudError

from helpers import random_points

#: A fixed example budget: the same examples on every run, no deadline.
#: ASE_MAUD_EXAMPLES raises it for a longer search.
BUDGET = settings(max_examples=int(os.environ.get('ASE_MAUD_EXAMPLES', 150)),
                  deadline=None, derandomize=True)

#: Bound on the steps of one Maud run.
STEPS = 3000


@st.composite
def scenes(draw, max_atoms=8, squeeze=False, fixed=False):
    """A random scene: 2 to ``max_atoms`` points about ``a`` apart (one pair
    moved to between 1e-8 a and a apart if ``squeeze``), a random set of
    springs, dim 2 or 3, ``a`` in [1e-6, 1e6], ``Q`` in [1e-9, 1e9], and (if
    ``fixed``) a random set of fixed points."""
    n = draw(st.integers(2, max_atoms))
    dim = draw(st.sampled_from([2, 3]))
    a = 10.0 ** draw(st.floats(-6, 6))
    q = 10.0 ** draw(st.floats(-9, 9))
    pairs = list(combinations(range(n), 2))
    springs = draw(st.lists(st.sampled_from(pairs), unique=True))
    positions = random_points(n, dim, seed=draw(st.integers(0, 2**32 - 1)))
    if squeeze:
        gap = 10.0 ** draw(st.floats(-8, 0))
        d = positions[1] - positions[0]
        positions[1] = positions[0] + gap * d / np.linalg.norm(d)
    atoms = Atoms(positions=a * positions)
    atoms.calc = MaudCalculator(springs, a=a, Q=q, dim=dim)
    if fixed:
        held = draw(st.lists(st.integers(0, n - 1), unique=True, max_size=n))
        atoms.set_constraint(FixAtoms(indices=held))
    return atoms


def force_unit(atoms):
    p = atoms.calc.parameters
    return p['Q'] * p['a']


@BUDGET
@given(scenes(squeeze=True))
def test_calculator_is_finite(atoms):
    energy = atoms.get_potential_energy()
    forces = atoms.get_forces()
    blocks = atoms.calc.get_stiffness(atoms)
    assert np.isfinite(energy) and energy > 0
    assert np.isfinite(forces).all() and np.isfinite(blocks).all()
    dim = atoms.calc.parameters['dim']
    assert blocks.shape == (len(atoms), dim, dim)
    # No fixed points: the forces sum to zero, to rounding of the largest.
    assert np.abs(forces.sum(axis=0)).max() <= 1e-12 * len(atoms) * np.abs(
        forces).max()


@pytest.mark.integration
@BUDGET
@given(scenes())
def test_forces_are_minus_the_energy_gradient(atoms):
    a = atoms.calc.parameters['a']
    dim = atoms.calc.parameters['dim']
    forces = atoms.get_forces()
    # Central differences: truncation ~ (1e-4)**2 relative at spacing ~a,
    # rounding ~ 1e-16 E / 1e-4 a; both far below 1e-6 of the force scale.
    numeric = calculate_numerical_forces(atoms, eps=1e-4 * a,
                                         icarts=range(dim))
    scale = max(np.abs(forces).max(), force_unit(atoms))
    np.testing.assert_allclose(numeric, forces[:, :dim], rtol=0,
                               atol=1e-6 * scale)
    if dim == 2:
        assert np.all(forces[:, 2] == 0.0)


@pytest.mark.integration
@BUDGET
@given(scenes(fixed=True), st.sampled_from(['tensor', 'scalar']))
def test_maud_converges_or_says_why(atoms, method):
    log = io.StringIO()
    fmax = 1e-6 * force_unit(atoms)
    with Maud(atoms, logfile=log, method=method) as opt:
        try:
            converged = opt.run(fmax=fmax, steps=STEPS)
        except MaudError as error:
            event(type(error).__name__)
            assert str(error) and f'Maud: stopped: {error}' in log.getvalue()
        else:
            event(f'converged in {10 ** len(str(opt.nsteps)) // 10}+ steps')
            assert converged, f'neither converged nor stopped in {STEPS} steps'
            assert np.linalg.norm(atoms.get_forces(), axis=1).max() < fmax
    assert opt.nsteps <= STEPS
    assert np.isfinite(atoms.positions).all()
    assert np.isfinite(atoms.get_potential_energy())
