"""The optimisers the benchmark compares: ``OPTIMIZERS[name](atoms)``.

Every entry builds a silent optimiser on ``atoms`` whose ``run(fmax, steps)``
returns True on convergence (largest atomic force norm <= fmax, constraints
applied). :data:`ASE_BASELINES` are the ones the Maud rows are measured
against ("x best ASE" in the summary), :data:`SCIPY_BASELINE` the one their
CPU seconds are also measured against; :data:`MAX_ATOMS` bounds the scenes
an optimiser is run on (:func:`too_large`).
"""

from __future__ import annotations

import numpy as np
from ase.optimize import BFGS, FIRE, LBFGS
from ase.optimize.fire2 import FIRE2
from ase.optimize.precon import Exp, PreconFIRE, PreconLBFGS
from scipy.optimize import minimize

from ase_maud.optimize.maud import Maud
from ase_maud.optimize.precon import MaudPrecon

#: Exp's cut-off radius in units of its r_NN (ASE's own default is 2).
EXP_R_CUT = 2.0


def precon_lbfgs(atoms):
    """PreconLBFGS with an explicit Exp preconditioner.

    ``r_NN`` is the mean spring length at the start and ``r_cut`` is
    :data:`EXP_R_CUT` ``r_NN``; ``mu`` is ASE's estimate (two force calls,
    counted), which needs ``r_NN`` on a scene without a cell.
    """
    i, j = atoms.calc.springs.T
    r_nn = np.linalg.norm(atoms.positions[i] - atoms.positions[j],
                          axis=1).mean()
    return PreconLBFGS(atoms, precon=Exp(r_cut=EXP_R_CUT * r_nn, r_NN=r_nn),
                       logfile=None)


class _Converged(Exception):
    """Raised inside the objective to stop SciPy at a converged point."""


class ScipyLBFGSB:
    """SciPy's L-BFGS-B (``scipy.optimize.minimize``) on all 3N coordinates.

    The energy and gradient ``-forces`` come from ``atoms`` (constraints
    applied, so fixed coordinates have zero gradient and do not move; or a
    cell filter, whose rows are positions and cell alike). SciPy's
    own stopping tests are switched off; the run stops at the first
    evaluation with fmax <= ``fmax``, or when SciPy gives up (line-search
    failure) or has made ``steps`` iterations.
    """

    def __init__(self, atoms):
        self.atoms = atoms

    def __enter__(self) -> ScipyLBFGSB:
        return self

    def __exit__(self, *exc) -> None:
        return None

    def _energy_gradient(self, x, fmax):
        self.atoms.set_positions(x.reshape(-1, 3))
        forces = self.atoms.get_forces()
        if np.sqrt((forces**2).sum(axis=1).max()) <= fmax:
            raise _Converged
        return self.atoms.get_potential_energy(), -forces.ravel()

    def run(self, fmax=0.05, steps=1000):
        try:
            minimize(self._energy_gradient, self.atoms.get_positions().ravel(),
                     args=(fmax,), jac=True, method='L-BFGS-B',
                     options={'maxiter': steps, 'maxfun': 100 * steps,
                              'ftol': 0.0, 'gtol': 0.0})
        except _Converged:
            return True
        return False


def precon_maud(optimizer):
    """``optimizer`` (PreconLBFGS or PreconFIRE) with :class:`MaudPrecon`;
    PreconLBFGS with ``maxstep=1.0`` (its default 0.04 caps every step)."""
    options = {'maxstep': 1.0} if optimizer is PreconLBFGS else {}
    return lambda atoms: optimizer(atoms, precon=MaudPrecon(), logfile=None,
                                   **options)


OPTIMIZERS = {
    'Maud': lambda atoms: Maud(atoms, logfile=None),
    'Maud-exact': lambda atoms: Maud(atoms, model='exact', logfile=None),
    'Maud-global': lambda atoms: Maud(atoms, model='global', logfile=None),
    'Maud-springs': lambda atoms: Maud(atoms, model='springs', logfile=None),
    'Maud-tensor': lambda atoms: Maud(atoms, model='nodal', method='tensor',
                                      logfile=None),
    'Maud-scalar': lambda atoms: Maud(atoms, model='nodal', method='scalar',
                                      logfile=None),
    'PreconLBFGS-Maud': precon_maud(PreconLBFGS),
    'PreconFIRE-Maud': precon_maud(PreconFIRE),
    'FIRE': lambda atoms: FIRE(atoms, logfile=None),
    'FIRE2': lambda atoms: FIRE2(atoms, logfile=None),
    'BFGS': lambda atoms: BFGS(atoms, logfile=None),
    'LBFGS': lambda atoms: LBFGS(atoms, logfile=None),
    'PreconLBFGS': precon_lbfgs,
    'L-BFGS-B': ScipyLBFGSB,
}

ASE_BASELINES = ('FIRE', 'FIRE2', 'BFGS', 'LBFGS', 'PreconLBFGS')
SCIPY_BASELINE = 'L-BFGS-B'

#: Largest scene (points) each optimiser is run on. ASE's BFGS keeps a dense
#: (3N)^2 Hessian and eigen-decomposes it at every step, O(N^3) per step
#: (docs/dev/benchmarks.md has its seconds on a net of 400 points).
MAX_ATOMS = {'BFGS': 500, 'Maud-exact': 200}


def too_large(optimiser: str, natoms: int) -> str:
    """Why ``optimiser`` is not run on ``natoms`` points ('' if it is)."""
    limit = MAX_ATOMS.get(optimiser, np.inf)
    if natoms <= limit:
        return ''
    return f'{natoms} points, over the limit of {limit} for {optimiser}'

