"""Evaluation cost against accuracy for the calculator's kernels (backends).

For each N, ``N`` points uniform in a cube of one point per unit volume
(``a = Q = 1``, no springs: the repulsion is the whole cost) are evaluated by
every backend, for energy and forces and for energy, forces and the nodal
stiffness blocks. Time per call is the best of ``repeats`` calls after one
warm-up (numba compiles on first use); the relative error is the Frobenius
norm of the difference from the reference backend's forces (or blocks) over
the reference's norm. The ``fmm`` backend is measured at every requested
precision ``fmm_eps``, each a backend of its own named ``fmm eps=...``.
"""

import time

import numba
import numpy as np
from ase import Atoms
from ase.calculators.calculator import all_changes

from ..calculator import BACKENDS, MaudCalculator

#: What one call computes, and the result compared with the reference.
PROPERTIES = {'forces': ['energy', 'forces'], 'stiffness': ['stiffness']}


def _time_per_call(calc, atoms, properties, repeats):
    calc.calculate(atoms, properties, all_changes)
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        calc.calculate(atoms, properties, all_changes)
        best = min(best, time.perf_counter() - start)
    return best


def measure_backends(natoms=(100, 300, 1000), backends=tuple(BACKENDS),
                     reference='numpy', repeats=3, seed=0,
                     fmm_eps=(1e-3, 1e-6)):
    """One dict per (N, property set, backend): ``time_per_call_s``, the
    throughput ``pairs_per_s`` (N (N - 1) / 2 pairs per call) and
    ``rel_error`` (0 for the reference itself), with numba's thread count."""
    variants = {}  # backend name in the rows: calculator parameters
    for backend in dict.fromkeys([reference, *backends]):
        if backend == 'fmm':
            variants.update({f'fmm eps={eps:g}': {'backend': 'fmm',
                                                  'fmm_eps': eps}
                             for eps in fmm_eps})
        else:
            variants[backend] = {'backend': backend}
    rows = []
    rng = np.random.default_rng(seed)
    for n in natoms:
        side = n ** (1 / 3)
        atoms = Atoms(f'X{n}', positions=rng.uniform(0, side, (n, 3)))
        for what, properties in PROPERTIES.items():
            value = {}
            for backend, parameters in variants.items():
                calc = MaudCalculator(**parameters)
                seconds = _time_per_call(calc, atoms, properties, repeats)
                value[backend] = calc.results[what]
                error = (np.linalg.norm(value[backend] - value[reference])
                         / np.linalg.norm(value[reference]))
                rows.append({'backend': backend, 'properties': what,
                             'natoms': n, 'threads': numba.get_num_threads(),
                             'time_per_call_s': seconds,
                             'pairs_per_s': n * (n - 1) / 2 / seconds,
                             'rel_error': float(error)})
    return rows
