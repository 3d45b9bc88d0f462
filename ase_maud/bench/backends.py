"""Evaluation cost against accuracy for the registered backends.

For each N, ``N`` points uniform in a cube of one point per unit volume
(``a = Q = 1``, no springs: the repulsion is the whole cost) are evaluated by
every backend of the registry :mod:`ase_maud.backends` asked for, for energy
and forces and for energy, forces and the nodal stiffness blocks. Time per
call is the best of ``repeats`` calls after one warm-up (numba compiles on
first use); the relative error is the Frobenius norm of the difference from
the reference backend's forces (or blocks) over the reference's norm. An
approximate backend (``fmm``) is measured at every requested tolerance, each
a backend of its own named ``<name> eps=<tolerance>``.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from pathlib import Path

import numba
import numpy as np
from ase import Atoms
from ase.calculators.calculator import all_changes

from ase_maud import backends as registry
from ase_maud.bench import report
from ase_maud.calculator.maud_calculator import MaudCalculator

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


def measure_backends(natoms: Sequence[int] = (100, 300, 1000),
                     backends: Sequence[str] | None = None,
                     reference: str = 'numpy', repeats: int = 3,
                     seed: int = 0,
                     tolerances: Sequence[float] = (1e-3, 1e-6)) -> list[dict]:
    """One dict per (N, property set, backend): ``time_per_call_s``, the
    throughput ``pairs_per_s`` (N (N - 1) / 2 pairs per call) and
    ``rel_error`` (0 for the reference itself), with numba's thread count.

    ``backends`` defaults to every installed one that computes rather than
    delegates (not ``auto``, which picks one of the others); an approximate
    backend is run at each of ``tolerances``.
    """
    names = ([name for name in registry.installed()   # kernels, not 'auto'
              if registry.get(name).choose is None]
             if backends is None else backends)
    variants = {}  # backend name in the rows: calculator parameters
    for name in dict.fromkeys([reference, *names]):
        backend = registry.get(name)
        if backend.exact:
            variants[name] = {'backend': name}
        else:
            variants.update({f'{name} eps={tol:g}': {'backend': name,
                                                     backend.tolerance: tol}
                             for tol in tolerances})
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


def write_backends_report(out: Path, natoms: Sequence[int],
                          backends: Sequence[str] | None = None,
                          reference: str = 'numpy', repeats: int = 3,
                          seed: int = 0,
                          argv: Sequence[str] | None = None) -> str:
    """Measure (:func:`measure_backends`) and write ``backends.csv``,
    ``backends.md`` (with the registry's cost and accuracy of each backend)
    and ``backends.png`` in ``out``; return the markdown."""
    out.mkdir(parents=True, exist_ok=True)
    rows = measure_backends(natoms, backends, reference, repeats, seed)
    report.write_csv(out / 'backends.csv', rows)
    info = report.environment(argv)
    measured = registry.installed() if backends is None else backends
    described = map(registry.get, dict.fromkeys([reference, *measured]))
    info['backends'] = '; '.join(f'{b.name}: cost {b.cost}, {b.accuracy}, '
                                 f'{b.summary}' for b in described)
    text = report.backends_markdown(rows, info)
    (out / 'backends.md').write_text(text)
    report.plot_backends(rows, out / 'backends.png')
    return text
