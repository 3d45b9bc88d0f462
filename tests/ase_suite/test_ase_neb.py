"""ASE's NEB tests with Maud: ase/test/neb/test_neb.py (the band relaxed by
the optimizer) and test_COCu111_2.py."""

from ase.test.neb.test_COCu111_2 import test_COCu111_2  # noqa: F401
from ase.test.neb.test_neb import fixture_neb, test_unconstrained_forces  # noqa: F401
