"""ASE's constraint and filter tests that run an optimizer, with Maud."""

from ase.test.constraints.test_CO2linear_Au111 import test_au111  # noqa: F401
from ase.test.constraints.test_fixbondlength_CO2_Au111 import test_CO2_Au111  # noqa: F401
from ase.test.constraints.test_fixedline_fixedplane import (  # noqa: F401
    test_constrained_optimization_fixedline,
    test_constrained_optimization_fixedplane,
)
from ase.test.filter.test_filter import test_filter  # noqa: F401
