"""MaudPotential's Hessian block of held scenes: compiled, and the steps it gives."""

import numpy as np
import pytest
from ase.constraints import FixAtoms

from ase_maud import Maud
from ase_maud.calculator import potential as potential_module
from ase_maud.calculator.potential import MaudPotential
from ase_maud.physics import pair_law
from ase_maud.scenes.catalogue import build


@pytest.mark.parametrize('seed', range(4))
@pytest.mark.parametrize('dim', [2, 3])
def test_springs_block_is_the_sparse_hessians_slice(seed, dim):
    """The springs' block from the kept entries against a slice of their
    sparse Hessian: to the last bit with every ``q = 1``, to round-off with
    force densities (the entries sum a point's springs in another order)."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(3, 30))
    springs = np.array([(i, j) for i in range(n) for j in range(i + 1, n)
                        if rng.random() < 0.3] or [(0, 1)])
    index = rng.permutation(n)[:int(rng.integers(1, n + 1))]
    coords = (dim * index[:, None] + np.arange(dim)).ravel()
    for q in (None, rng.uniform(0.1, 3.0, len(springs))):
        potential = MaudPotential(springs, a=0.0, Q=1.7, dim=dim, q=q)   # the springs alone
        block = potential.hessian_block(rng.normal(size=(n, 3)) * [1, 1, dim == 3], index)
        sliced = potential.spring_hessian(n)[coords][:, coords].toarray()
        if q is None:
            assert np.array_equal(block, sliced)
        np.testing.assert_allclose(block, sliced, rtol=0, atol=1e-15 * np.abs(sliced).max())


def _held_net(seed):
    """A seeded net with most points held (the exact model then asks for the
    Hessian's block on the free ones), its free points shaken."""
    atoms = build('hanging_net', 6, seed=seed)
    rng = np.random.default_rng(seed)
    held = np.setdiff1d(np.arange(len(atoms)), rng.choice(len(atoms), 8, replace=False))
    atoms.set_constraint(FixAtoms(held))
    atoms.positions[~np.isin(np.arange(len(atoms)), held)] += rng.normal(0, 0.2, (8, 3))
    return atoms


def _steps(atoms):
    positions = []
    with Maud(atoms, logfile=None) as opt:
        for _ in opt.irun(fmax=1e-7, steps=200):
            positions.append(atoms.positions.copy())
    return np.array(positions)


@pytest.mark.parametrize('seed', [21, 22, 23])
def test_the_compiled_block_makes_the_reference_blocks_moves(seed, monkeypatch):
    """A held net relaxed with the compiled Hessian block and with the numpy
    reference's (``physics.repulsion_hessian_block``): the same number of
    steps, every step's positions equal to round-off."""
    compiled = _steps(_held_net(seed))
    monkeypatch.setattr(potential_module.direct, 'repulsion_hessian_block',
                        lambda x, index, dim: pair_law.repulsion_hessian_block(x, index, dim))
    reference = _steps(_held_net(seed))
    assert compiled.shape == reference.shape and len(compiled) > 2
    np.testing.assert_allclose(compiled, reference, rtol=0, atol=1e-9)
