"""ASE's ase/test/optimize/test_pure.py with Maud: an Optimizable of 2
coordinates (the Booth function) relaxed to its minimum (1, 3)."""

from ase.test.optimize import test_pure

from ase_maud import Maud


def test_booth():
    """ASE's test_booth, its optimizer Maud (it takes a class)."""
    test_pure.test_booth(Maud)
