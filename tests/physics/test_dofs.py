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
