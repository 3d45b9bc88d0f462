"""ASE's ase/test/constraints/test_fixsubsetcom.py with Maud."""

from ase.test.constraints.test_fixsubsetcom import (  # noqa: F401
    fixture_atoms,
    test_center_of_mass_position,
)
