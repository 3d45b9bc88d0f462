"""ASE's ase/test/test_linesearch_maxstep.py with Maud: one step from a Pt13
cluster moves no atom further than ``maxstep``."""

from ase.test import test_linesearch_maxstep
from ase.test.test_linesearch_maxstep import atoms, positions  # noqa: F401

from ase_maud import Maud


def test_linesearch(atoms, positions):  # noqa: F811
    """ASE's test_linesearch, its optimizer Maud."""
    test_linesearch_maxstep.test_linesearch(Maud, 'Maud', atoms, positions)
