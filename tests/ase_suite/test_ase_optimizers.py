"""ASE's ase/test/optimize/test_optimizers.py with Maud (conftest.py)."""

from ase.test.optimize.test_optimizers import (  # noqa: F401
    fixture_atoms,
    fixture_ref_atoms,
    test_optimize,
    test_path,
    test_run_twice,
    test_unconverged,
)
