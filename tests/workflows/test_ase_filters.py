"""ASE's filters and constraints under Maud: a Filter (a subset of the atoms) with every
stiffness model, and the cell filters of a periodic crystal, each checked
against BFGS on the same filter from the same start."""

import numpy as np
import pytest
from ase.constraints import FixAtoms, FixBondLength, FixBondLengths, Hookean
from ase.filters import Filter, FrechetCellFilter, StrainFilter, UnitCellFilter
from ase.optimize import BFGS

from ase_maud import Maud, MaudCalculator
from ase_maud.bench.hard_inputs import relaxed_in_a_cell_filter
from ase_maud.scenes.catalogue import build

MODELS = ['auto', 'exact', 'springs', 'nodal', 'global', 'secant', 'near']


def subset_scene(seed):
    """A hanging net with its supports taken off, and a random subset of its
    points (the supports never in it) to move, as indices or as a mask."""
    atoms = build('hanging_net', 6, seed=seed)
    held = set(atoms.constraints[0].index)
    atoms.set_constraint()
    rng = np.random.default_rng(seed)
    free = [i for i in range(len(atoms)) if i not in held and rng.random() < 0.7]
    return atoms, free


def bfgs_energy(atoms, subset):
    reference = atoms.copy()
    reference.calc = type(atoms.calc)(**atoms.calc.parameters)
    BFGS(Filter(reference, indices=subset), logfile=None).run(fmax=1e-9, steps=5000)
    return reference.get_potential_energy()


@pytest.mark.parametrize('model', MODELS)
@pytest.mark.parametrize('seed', [0, 1])
def test_a_filter_moves_its_atoms_to_the_minimum_bfgs_finds(model, seed):
    atoms, free = subset_scene(seed)
    expected = bfgs_energy(atoms, free)
    start = atoms.positions.copy()
    selected = (Filter(atoms, indices=free) if seed % 2 == 0
                else Filter(atoms, mask=np.isin(np.arange(len(atoms)), free)))
    with Maud(selected, logfile=None, model=model) as opt:
        assert opt.run(fmax=1e-7, steps=3000)
    left_out = np.setdiff1d(np.arange(len(atoms)), free)
    np.testing.assert_array_equal(atoms.positions[left_out], start[left_out])
    energy = atoms.get_potential_energy()
    if energy != pytest.approx(expected, rel=1e-9):   # another minimum: verified one
        hessian = atoms.calc.get_property('hessian', atoms)
        dofs = (3 * np.asarray(free)[:, None] + np.arange(3)).ravel()
        assert np.linalg.eigvalsh(hessian[np.ix_(dofs, dofs)]).min() > 0


@pytest.mark.parametrize('seed', [2, 3])
def test_a_filter_steps_as_fixing_the_atoms_it_leaves_out(seed):
    atoms, free = subset_scene(seed)
    fixed = atoms.copy()
    fixed.calc = type(atoms.calc)(**atoms.calc.parameters)
    fixed.set_constraint(FixAtoms(indices=np.setdiff1d(np.arange(len(atoms)), free)))
    with Maud(Filter(atoms, indices=free), logfile=None, model='exact') as one, \
            Maud(fixed, logfile=None, model='exact') as other:
        for _ in zip(one.irun(fmax=1e-7), other.irun(fmax=1e-7), strict=True):
            np.testing.assert_allclose(atoms.positions, fixed.positions, rtol=0, atol=1e-12)
    assert one.nsteps == other.nsteps


@pytest.mark.parametrize('target', ['minimum', 'saddle'])
@pytest.mark.parametrize('seed', [4, 5])
def test_a_small_filter_steps_on_the_hessians_block(target, seed, monkeypatch):
    """A Filter of fewer than half the points (a local activation's region):
    the exact model asks the calculator for the Hessian's block on them
    (one Hessian counted a block), never for the whole, and steps as it
    does on the whole Hessian's rows (the block held off)."""
    atoms, _ = subset_scene(seed)
    region = np.random.default_rng(seed).choice(len(atoms), len(atoms) // 3, replace=False)
    asked, blocks = [], []
    calc_class = type(atoms.calc)
    calculate, block = calc_class.calculate, calc_class.get_hessian_block

    def calculate_asked(self, a=None, properties=('energy',), changes=()):
        asked.append(set(properties))
        return calculate(self, a, properties, changes)

    def block_counted(self, a, index):
        blocks.append(len(index))
        return block(self, a, index)

    monkeypatch.setattr(calc_class, 'calculate', calculate_asked)
    monkeypatch.setattr(calc_class, 'get_hessian_block', block_counted)
    whole = atoms.copy()
    whole.calc = type(atoms.calc)(**atoms.calc.parameters)
    steps = []
    with Maud(Filter(atoms, indices=region), logfile=None, target=target) as one:
        for _ in one.irun(fmax=1e-8, steps=25):
            steps.append(atoms.positions.copy())
    assert set(blocks) == {len(region)} and not any('hessian' in props for props in asked)
    assert one.work.hessians == len(blocks)
    monkeypatch.setattr(MaudCalculator, 'block_min_held', 1.0)
    with Maud(Filter(whole, indices=region), logfile=None, target=target) as other:
        for k, _ in enumerate(other.irun(fmax=1e-8, steps=25)):
            np.testing.assert_allclose(whole.positions, steps[k], rtol=0, atol=1e-9)
    assert other.nsteps == one.nsteps and any('hessian' in props for props in asked)


@pytest.mark.parametrize('cell_filter', [StrainFilter, UnitCellFilter, FrechetCellFilter])
@pytest.mark.parametrize('seed', [0, 1])
def test_cell_filters_reach_the_energy_bfgs_reaches(cell_filter, seed):
    converged, energy, expected = relaxed_in_a_cell_filter(cell_filter, seed)
    assert converged and energy == pytest.approx(expected, abs=1e-7)


@pytest.mark.parametrize('make', [lambda: FixBondLength(6, 7), lambda: Hookean(6, 18, 1.0, 1.0)],
                         ids=['FixBondLength', 'Hookean'])
@pytest.mark.parametrize('seed', [0, 1, 2, 3])
def test_constraints_that_ase_adjusts_end_where_bfgs_does_or_lower(make, seed):
    # ASE adjusts every move for these (SHAKE for a bond length): long
    # moves made its iteration fail ("Did not converge")
    atoms = build('hanging_net', 5, seed=seed)
    atoms.set_constraint([*atoms.constraints, make()])
    reference = atoms.copy()
    reference.calc = type(atoms.calc)(**atoms.calc.parameters)
    reference.set_constraint([c.copy() for c in atoms.constraints])
    BFGS(reference, logfile=None).run(fmax=1e-8, steps=5000)
    length = atoms.get_distance(6, 7)
    with Maud(atoms, logfile=None) as opt:
        assert opt.run(fmax=1e-7, steps=5000)
    energy = atoms.get_potential_energy()
    if energy != pytest.approx(reference.get_potential_energy(), rel=1e-9):
        # another minimum: BFGS from a point beside it comes back to it
        beside = atoms.copy()
        beside.calc = type(atoms.calc)(**atoms.calc.parameters)
        beside.set_constraint([c.copy() for c in atoms.constraints])
        beside.rattle(1e-3, seed=seed)
        BFGS(beside, logfile=None).run(fmax=1e-8, steps=5000)
        assert beside.get_potential_energy() == pytest.approx(energy, rel=1e-9)
    if isinstance(atoms.constraints[-1], FixBondLengths):
        assert atoms.get_distance(6, 7) == pytest.approx(length, rel=1e-9)
