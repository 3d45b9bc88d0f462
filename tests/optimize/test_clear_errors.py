"""Every raw traceback of issue 52 (item 5) is a clear error naming the
argument or file: model='springs'/'near' on EMT, (N, 2) forces, a
calculator without energy, UnitCellFilter on a MaudCalculator scene, a
disc too small for its rim, search_saddles(client=object())."""

from __future__ import annotations

import numpy as np
import pytest
from ase.calculators.calculator import Calculator, all_changes
from ase.calculators.emt import EMT
from ase.cluster import Icosahedron
from ase.filters import FrechetCellFilter, UnitCellFilter
from ase.optimize import BFGS

from ase_maud import Maud, search_saddles
from ase_maud.scenes.catalogue import build


def copper(seed=1):
    atoms = Icosahedron('Cu', 2)
    atoms.rattle(0.05, seed=seed)
    atoms.calc = EMT()
    return atoms


@pytest.mark.parametrize('model', ['springs', 'near', 'global'])
def test_a_maud_model_on_emt(model):
    atoms = copper()
    start = atoms.positions.copy()
    with pytest.raises(ValueError, match=f"model='{model}' needs a calculator with"):
        Maud(atoms, logfile=None, model=model)
    assert np.array_equal(atoms.positions, start)


class Reduced(Calculator):
    """Forces of the wrong shape, or none of the energy."""
    implemented_properties = ['energy', 'forces']

    def __init__(self, shape_2=False, energy=True):
        super().__init__()
        self.shape_2, self.energy = shape_2, energy
        if not energy:
            self.implemented_properties = ['forces']

    def calculate(self, atoms=None, properties=('energy',), system_changes=all_changes):
        super().calculate(atoms, properties, system_changes)
        forces = -atoms.positions.copy()
        self.results = {'forces': forces[:, :2] if self.shape_2 else forces}
        if self.energy:
            self.results['energy'] = 0.5 * float((atoms.positions**2).sum())


@pytest.mark.parametrize('calc, said', [(Reduced(shape_2=True), r'shape \(13, 2\)'),
                                        (Reduced(energy=False), 'energy property not')])
def test_a_calculator_short_of_what_an_optimiser_needs(calc, said):
    atoms = Icosahedron('Cu', 2)
    atoms.calc = calc
    with pytest.raises(ValueError, match=f'Reduced.*{said}'):
        Maud(atoms, logfile=None).run(fmax=1e-3, steps=20)


@pytest.mark.parametrize('cell_filter', [UnitCellFilter, FrechetCellFilter])
def test_a_cell_filter_on_a_scene_without_stress(cell_filter):
    """BFGS says 'stress property not implemented'; so does Maud, before any step."""
    atoms = build('hanging_net', 5, seed=1)
    start = atoms.positions.copy()
    with pytest.raises(Exception, match='stress'):
        BFGS(cell_filter(atoms), logfile=None).run(fmax=1e-3, steps=3)
    atoms.positions = start
    with pytest.raises(ValueError, match='stress property not implemented'):
        Maud(cell_filter(atoms), logfile=None)
    assert np.array_equal(atoms.positions, start)


@pytest.mark.parametrize('size', [8, 10, 12])
def test_a_disc_too_small_for_its_rim(size):
    with pytest.raises(ValueError, match='disc needs an integer size >= 13'):
        build('disc', size)
    assert len(build('disc', 13)) == 13


def test_search_saddles_with_a_client_that_is_none():
    atoms = build('ring', 8, seed=1)
    Maud(atoms, logfile=None).run(fmax=1e-6)
    with pytest.raises(ValueError, match='client must be None or a dask'):
        search_saddles(atoms, client=object())
