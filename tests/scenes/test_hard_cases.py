"""The builders of the hard cases (ase_maud.scenes.hard_cases): seeded, and
scaled by a and Q."""

import numpy as np
import pytest

from ase_maud import (
    MaudCalculator,
)
from ase_maud.scenes.hard_cases import (
    HARD_CASES,
)


@pytest.mark.parametrize('name', sorted(HARD_CASES))
def test_builders_are_seeded_and_scale(name):
    builder = HARD_CASES[name]
    atoms = builder(seed=5)
    assert isinstance(atoms.calc, MaudCalculator)
    assert np.isfinite(atoms.get_potential_energy())
    assert np.array_equal(builder(seed=5).positions, atoms.positions)
    assert not np.allclose(builder(seed=6).positions, atoms.positions)
    scaled = builder(seed=5, a=3.7, Q=0.2)
    np.testing.assert_allclose(scaled.positions, 3.7 * atoms.positions,
                               rtol=1e-12, atol=1e-12)
    # close_pair's 1e-8 a gap is a difference of O(a) positions: 1e-8 relative.
    rel = 1e-7 if name == 'close_pair' else 1e-12
    assert scaled.get_potential_energy() == pytest.approx(
        3.7**2 * 0.2 * atoms.get_potential_energy(), rel=rel)
