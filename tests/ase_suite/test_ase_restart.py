"""ASE's restart tests with Maud: ase/test/optimize/test_restart.py (a path
or None as ``restart``, an unreadable file raises RestartError),
test_optimizer_restart.py (a run under FrechetCellFilter broken after two
steps and carried on from its restart file repeats the uninterrupted one) and
test_replay.py."""

from ase.test.optimize import test_optimizer_restart
from ase.test.optimize.test_replay import test_replay  # noqa: F401
from ase.test.optimize.test_restart import (  # noqa: F401
    test_bad_restart,
    test_none_restart,
    test_path_restart,
)

from ase_maud import Maud


class MaudAlpha(Maud):
    """Maud taking ASE's BFGS keyword ``alpha`` (its initial Hessian,
    eV/A^2) as ``kappa0``, the same quantity: test_optimizers_restart passes
    it to every optimizer it runs."""

    def __init__(self, atoms, alpha: float = 70.0, **kwargs):
        super().__init__(atoms, kappa0=alpha, **kwargs)


def test_optimizers_restart(testdir):
    """ASE's test_optimizers_restart, its optimizer Maud."""
    test_optimizer_restart.test_optimizers_restart(testdir, MaudAlpha)
