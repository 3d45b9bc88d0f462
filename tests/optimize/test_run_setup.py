"""What Maud is given is checked before the model is assembled
(ase_maud.optimize.run_setup, issue 30):
atoms edited under their calculator, a saddle search with nothing free,
atoms with no calculator that computes forces. Each raised a raw error
(SciPy's, numpy's, ASE's) on 5f059dc."""

import numpy as np
import pytest
from ase.constraints import FixAtoms, FixCartesian
from ase.io import read, write

from ase_maud import Maud
from ase_maud.scenes.catalogue import build


@pytest.mark.parametrize('edit', ['del', 'pop'])
@pytest.mark.parametrize('seed', [2, 7])
def test_atoms_edited_under_the_calculator_name_the_spring(edit, seed):
    # was: "axis 1 index 8 exceeds matrix dimension 8" (SciPy)
    atoms = build('net3d', 3, seed=seed)
    atoms.set_constraint()
    index = int(np.random.default_rng(seed).integers(9)) if edit == 'del' else -1
    if edit == 'del':
        del atoms[index]
    else:
        atoms.pop()
    with pytest.raises(ValueError, match=r'spring \d+ \(\d+, 8\) names an atom beyond'):
        Maud(atoms, logfile=None)


@pytest.mark.parametrize('model', ['auto', 'springs', 'exact'])
@pytest.mark.parametrize('name', ['chain', 'hanging_net'])
def test_a_saddle_search_with_every_atom_fixed_is_refused(name, model):
    # was: "cannot reshape array of size 0 into shape (0,newaxis)" (springs)
    atoms = build(name, 6, seed=4)
    atoms.set_constraint(FixAtoms(indices=range(len(atoms))))
    with pytest.raises(ValueError, match="target='saddle' with every coordinate"):
        Maud(atoms, logfile=None, target='saddle', model=model)
    atoms.set_constraint([FixAtoms(indices=range(1, len(atoms))),   # one left free
                          FixCartesian(0, [True, True, False])])
    Maud(atoms, logfile=None, target='saddle', model=model)


@pytest.mark.parametrize('ext', ['xyz', 'traj'])
def test_atoms_read_by_ase_need_a_calculator_with_forces(tmp_path, ext):
    # was: "Atoms object has no calculator" (xyz: ASE's RuntimeError) and
    # PropertyNotImplementedError (traj: a SinglePointCalculator)
    atoms = build('ring', 8, seed=3)
    atoms.get_forces()
    write(tmp_path / f'r.{ext}', atoms)
    read_back = read(tmp_path / f'r.{ext}')
    with pytest.raises(ValueError, match='computes no forces at new positions|has no '
                       'calculator') as error:
        Maud(read_back, logfile=None)
    assert 'read_net' in str(error.value)
    read_back.calc = None
    with pytest.raises(ValueError, match='the atoms have no calculator: Maud needs forces'):
        Maud(read_back, logfile=None)
