"""The divergence cases of docs/hard_cases.md (issue 30): what Maud does on
scenes whose minimum lies far out, and on scenes with none.

    PYTHONPATH=$PWD python dev/divergence_cases.py [NAME ...]

prints one line per case: Maud's outcome (converged, not converged, or the
MaudError's class), its steps and energy, and for the converged ones the
verdict of ``classify`` and BFGS's outcome from the same start.
"""

from __future__ import annotations

import io
import sys
import time

import numpy as np
from ase import Atoms
from ase.constraints import FixAtoms, FixCartesian, FixedPlane
from ase.optimize import BFGS

from ase_maud import Maud, MaudCalculator
from ase_maud.analysis.stationary import classify
from ase_maud.errors import MaudError
from ase_maud.scenes.builders import chain
from ase_maud.scenes.hard_cases import heavy_net, islands


def loaded_net(seed: int, load: float, plane: int | None = None) -> Atoms:
    """:func:`heavy_net` pulled by ``-load``; ``plane``: a point held to its
    plane by FixedPlane (nothing proved then)."""
    atoms = heavy_net(6, seed=seed, load=-load)
    if plane is not None:
        atoms.set_constraint([*atoms.constraints, FixedPlane(plane, [0, 0, 1])])
    return atoms


def soft_chain(seed: int) -> Atoms:
    """``chain(6)`` (ends fixed), q log-uniform in [1e-6, 1e6], loads 1e6 along z."""
    atoms = chain(6, seed=seed)
    q = 10 ** np.random.default_rng(seed).uniform(-6, 6, len(atoms.calc.springs))
    loads = np.zeros((6, 3))
    loads[:, 2] = 1e6
    atoms.calc = MaudCalculator(atoms.calc.springs, q=q, loads=loads)
    atoms.set_constraint(FixAtoms(indices=[0, 5]))
    return atoms


def pushed_chain(seed: int) -> Atoms:
    """``chain(8)`` held to a plane by FixedPlane on point 0, every point
    pushed along x: no minimum, nothing proved before the run."""
    atoms = chain(8, seed=seed)
    loads = np.zeros((8, 3))
    loads[:, 0] = 1.0
    atoms.set_constraint(FixedPlane(0, [0, 0, 1]))
    atoms.calc = MaudCalculator(atoms.calc.springs, loads=loads)
    return atoms


def islands_2d(seed: int) -> Atoms:
    atoms = islands(2, seed=seed)
    atoms.positions[:, 2] = 0.0
    atoms.calc = MaudCalculator(atoms.calc.springs, dim=2)
    return atoms


def pair_2d(seed: int) -> Atoms:
    rng = np.random.default_rng(seed)
    atoms = Atoms('H2', positions=[[0, 0, 0], [*rng.uniform(0.5, 1.5, 2), 0]])
    atoms.calc = MaudCalculator([], dim=2)
    return atoms


#: name: (builder, fmax, Maud's keywords, BFGS's maxstep or None: no BFGS)
CASES = {
    'loaded_net_100': (lambda s: loaded_net(s, -100.0), 1e-6, {}, 0.2),
    'unproved_net_1e3': (lambda s: loaded_net(s, -1e3, plane=20), 1e-4, {}, 20.0),
    'soft_chain': (soft_chain, 1.0, {}, 0.2),
    'pushed_chain': (pushed_chain, 1e-6, {}, None),
    'islands_2d': (islands_2d, 1e-6, {}, None),
    'islands_2d_nodal': (islands_2d, 1e-6, {'model': 'nodal'}, None),
    'pair_2d': (pair_2d, 1e-6, {}, None),
}


def run(atoms: Atoms, opt, fmax: float, steps: int, **kwargs) -> tuple[str, int]:
    dyn = opt(atoms, logfile=io.StringIO(), **kwargs)
    try:
        outcome = 'converged' if dyn.run(fmax=fmax, steps=steps) else 'not converged'
    except MaudError as error:
        outcome = type(error).__name__
    return outcome, dyn.nsteps


def main(names: list[str], seeds=(0, 1, 2, 3, 4), steps: int = 5000) -> None:
    for name in names or CASES:
        make, fmax, kwargs, maxstep = CASES[name]
        for seed in seeds:
            atoms, start = make(seed), time.perf_counter()
            outcome, n = run(atoms, Maud, fmax, steps, **kwargs)
            took = time.perf_counter() - start
            line = f'{name} seed {seed}: Maud {outcome} in {n} steps ({took:.1f} s)'
            if outcome == 'converged':
                line += f', E {atoms.get_potential_energy():.10g}'
                if any(isinstance(c, FixedPlane) for c in atoms.constraints):
                    atoms.set_constraint([c if not isinstance(c, FixedPlane) else
                                          FixCartesian(c.index, [False, False, True])
                                          for c in atoms.constraints])
                line += f', {classify(atoms, ftol=10 * fmax).verdict}'
            if maxstep is not None:
                reference = make(seed)
                b_outcome, b_n = run(reference, BFGS, fmax, steps, maxstep=maxstep)
                line += (f'; BFGS {b_outcome} in {b_n} steps, E '
                         f'{reference.get_potential_energy():.10g}')
            print(line, flush=True)


if __name__ == '__main__':
    main(sys.argv[1:])
