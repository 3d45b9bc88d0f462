"""Degrees of freedom (ase_maud.physics.dofs): a planar scene keeps z."""

import numpy as np
import pytest

from ase_maud.scenes.builders import keep_on_plane
from ase_maud.scenes.catalogue import SCENES, build

# -- 4. planar scenes under ASE's drivers ----------------------------------------------

@pytest.mark.parametrize('name', [n for n in SCENES if build(n).calc.parameters['dim'] == 2])
def test_planar_scenes_keep_z(name):
    atoms = build(name, seed=1)
    z = atoms.positions[:, 2].copy()
    atoms.set_positions(atoms.positions + np.random.default_rng(1).normal(size=(len(atoms), 3)))
    assert np.array_equal(atoms.positions[:, 2], z)
    assert len(atoms.constraints) == len(keep_on_plane(atoms).constraints)   # idempotent


@pytest.mark.parametrize('seed', range(4))
@pytest.mark.parametrize('shape', [(300, 6), (4, 6), (50, 3)])
def test_column_null_space_is_scipys(seed, shape):
    """The thin-SVD null space spans what scipy.linalg.null_space spans, on
    tall and wide matrices of random rank, with orthonormal columns."""
    import scipy.linalg

    from ase_maud.physics.dofs import column_null_space
    rng = np.random.default_rng(seed)
    rank = int(rng.integers(0, min(shape) + 1))
    matrix = rng.standard_normal((shape[0], rank)) @ rng.standard_normal((rank, shape[1]))
    ours, theirs = column_null_space(matrix, 1e-8), scipy.linalg.null_space(matrix, rcond=1e-8)
    assert ours.shape == theirs.shape == (shape[1], shape[1] - rank)
    np.testing.assert_allclose(ours.T @ ours, np.eye(ours.shape[1]), atol=1e-12)
    np.testing.assert_allclose(matrix @ ours, 0.0, atol=1e-10)
    np.testing.assert_allclose(ours @ ours.T, theirs @ theirs.T, atol=1e-10)
