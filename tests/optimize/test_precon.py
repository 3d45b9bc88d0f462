"""MaudPrecon (ase_maud.optimize.precon): its matrix and solve agree, and it
drives ASE's optimizers under FixAtoms."""

import numpy as np
import pytest
from ase.constraints import FixAtoms
from ase.optimize import BFGS
from ase.optimize.precon import PreconFIRE, PreconLBFGS

from ase_maud.optimize.precon import MaudPrecon
from ase_maud.scenes.catalogue import build

from helpers import random_scene

# -- MaudPrecon -------------------------------------------------------------------


@pytest.mark.parametrize('seed', range(3))
@pytest.mark.parametrize('dim', [2, 3])
def test_precon_matrix_and_solve_agree(seed, dim):
    atoms = random_scene(seed, dim)
    precon = MaudPrecon()
    P = precon.make_precon(atoms)
    dense = precon.asarray()
    assert P.shape == (3 * len(atoms),) * 2
    assert np.allclose(dense, dense.T)
    assert np.linalg.eigvalsh(dense).min() > 0
    x = np.random.default_rng(seed).normal(size=3 * len(atoms))
    assert np.allclose(precon.Pdot(precon.solve(x)), x, atol=1e-9 * np.abs(x).max())
    copy = precon.copy()
    copy.make_precon(atoms)
    assert np.allclose(copy.solve(x), precon.solve(x))


@pytest.mark.parametrize('optimizer', [PreconLBFGS, PreconFIRE])
@pytest.mark.parametrize('seed', range(2))
def test_precon_drives_ase_optimizers_under_fixatoms(optimizer, seed):
    atoms = build('hanging_net', 5, seed=seed)  # boundary held by FixAtoms
    assert any(isinstance(c, FixAtoms) for c in atoms.constraints)
    reference = build('hanging_net', 5, seed=seed)
    start = atoms.positions.copy()
    fixed = atoms.constraints[0].index
    kwargs = {'maxstep': 1.0} if optimizer is PreconLBFGS else {}
    with optimizer(atoms, precon=MaudPrecon(), logfile=None, **kwargs) as opt:
        assert opt.run(fmax=1e-6, steps=3000)
    with BFGS(reference, logfile=None) as opt:
        assert opt.run(fmax=1e-6, steps=5000)
    assert np.array_equal(atoms.positions[fixed], start[fixed])
    assert atoms.get_potential_energy() == pytest.approx(
        reference.get_potential_energy(), rel=1e-9)
