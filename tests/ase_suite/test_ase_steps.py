"""ASE's ase/test/optimize/test_nsteps.py and test_optimize_stepwise.py with
Maud: ``irun`` yields once before the first step and once per step, and
``fmax=0`` runs the steps asked."""

import pytest
from ase.build import bulk
from ase.calculators.emt import EMT
from ase.test.optimize.test_nsteps import test_nsteps  # noqa: F401
from ase.test.optimize.test_optimize_stepwise import (  # noqa: F401
    atoms,
    atoms0,
    test_attach_trajectory,
    test_irun_start,
)

from ase_maud import Maud


@pytest.fixture
def opt():
    """test_nsteps's ``opt`` (rattled bulk Au on EMT), with Maud."""
    gold = bulk('Au', cubic=True)
    gold.rattle(stdev=0.12345, seed=42)
    gold.calc = EMT()
    with Maud(gold) as optimizer:
        yield optimizer
