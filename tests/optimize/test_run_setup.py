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
from ase_maud.bench.optimizers import ScipyLBFGSB
from ase_maud.optimize.directions import within_reach
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


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_the_springs_memory_forgets_pairs_beyond_its_reach(seed):
    """The springs model's L-BFGS memory keeps, after every step, only pairs
    the points have moved at most one ``a`` from (the steps of the pairs after
    each summed by their longest point move), and the run ends in the minimum
    energy SciPy's L-BFGS-B reaches from the same start (a hanging net's
    minima are one shape and its mirror images)."""
    rng = np.random.default_rng(seed)
    atoms = build('hanging_net', int(rng.integers(12, 20)), seed=seed)
    atoms.calc.set(a=float(rng.uniform(0.7, 1.3)))
    reference = atoms.copy()
    reference.calc = type(atoms.calc)(**atoms.calc.parameters)
    opt = Maud(atoms, logfile=None, model='springs')
    reach = opt.strategy.rule.memory_reach
    assert reach == atoms.calc.parameters['a']
    held, seen = [], set()

    def check():
        pairs = opt.state.pairs
        held.append(len(pairs))
        seen.update(id(s) for s, _ in pairs)
        assert len(within_reach(pairs, reach)) == len(pairs)
    opt.attach(check)
    assert opt.run(fmax=1e-6, steps=500)
    assert max(held) > 1 and len(seen) > max(held)   # the memory filled and turned over
    assert ScipyLBFGSB(reference).run(fmax=1e-6, steps=5000)
    assert atoms.get_potential_energy() == pytest.approx(
        reference.get_potential_energy(), rel=1e-10)


@pytest.mark.parametrize('a', [0.0, 1.5])
def test_the_memory_reach_is_in_units_of_a_on_a_net_held_in_a_plane(a):
    """A net on its rim: ``a`` (none at ``a = 0``, no repulsion); the same net
    hanging from two points, a tree from its root, a free cluster: none (their
    memory keeps what it holds); the global model's memory: none."""
    def reach(atoms, model='springs'):
        atoms.calc.set(a=a)
        return Maud(atoms, logfile=None, model=model).strategy.rule.memory_reach

    net = build('hanging_net', 12, seed=3)
    assert reach(net) == (None if a == 0 else a)
    assert reach(net, 'global') is None
    net.set_constraint(FixAtoms(indices=[0, 11]))
    assert reach(net) is None
    assert reach(build('tree', 200, seed=3)) is None
    assert reach(build('all_pairs', 60, seed=3)) is None
