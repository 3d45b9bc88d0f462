"""Run one optimiser from one start, with a sample at every calculator call.

A *sample* is ``(calls, time_s, cpu_s, fmax, energy)`` taken right after each
call of ``calc.calculate``:

- ``calls`` counts those calls: line-search trials included, optimiser steps
  not. A call that also computes the nodal stiffness blocks or the dense
  Hessian (``properties`` with ``'stiffness'`` or ``'hessian'``) counts as
  one call like any other; its extra cost shows in the seconds. Work done
  outside ``calculate`` (the constant spring Hessian, Hessian-vector
  products, the optimiser's own linear algebra) is no call and shows only in
  the seconds.
- ``time_s`` is wall time and ``cpu_s`` the CPU time of the whole process
  (``ase_maud.counting.cpu_seconds``: every thread of it, so with numba or BLAS running
  on k threads it can grow up to k times faster than the wall time), both
  since the run began: the optimiser's construction included, the sampling
  itself left out.
- ``fmax`` is the largest atomic force norm after the atoms' constraints,
  ``energy`` the potential energy.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np
from ase import Atoms

from ase_maud.bench.optimizers import OPTIMIZERS
from ase_maud.counting import CallRecorder, cpu_seconds, fresh_copy
from ase_maud.old_paths import old_names

#: Fields of one sample, the columns of :attr:`Run.samples`.
SAMPLE_FIELDS = ('calls', 'time_s', 'cpu_s', 'fmax', 'energy')
#: Column of each field in :attr:`Run.samples`.
CALLS, TIME_S, CPU_S, FMAX, ENERGY = range(len(SAMPLE_FIELDS))


@dataclass
class Run:
    """One optimiser's run from one start.

    ``samples`` is an array (n, 5) of :data:`SAMPLE_FIELDS`; ``status`` is
    ``'converged'``, ``'other_minimum'`` (converged to an energy off the
    reference), ``'not_converged'`` (step budget spent or the optimiser gave
    up) or ``'error'`` (raised; the message is ``error``). ``e_ref`` is the
    reference energy of the start.
    """

    scene: str
    size: object
    seed: int
    natoms: int
    optimiser: str
    samples: np.ndarray
    status: str
    e_ref: float = np.nan
    error: str = ''

    def reached(self, fmax: float) -> tuple[float, float, float]:
        """(calls, time_s, cpu_s) of the first sample with fmax <= ``fmax``,
        or (inf, inf, inf) if none, or if the run ended in another
        minimum."""
        hit = np.flatnonzero(self.samples[:, FMAX] <= fmax)
        if self.status == 'other_minimum' or not hit.size:
            return np.inf, np.inf, np.inf
        calls, time_s, cpu_s = self.samples[hit[0], [CALLS, TIME_S, CPU_S]]
        return calls, time_s, cpu_s

    def rows(self) -> Iterator[dict[str, Any]]:
        """One dict per sample: the columns of the benchmark's samples CSV."""
        for sample in self.samples:
            row = dict(zip(SAMPLE_FIELDS, sample, strict=True))
            yield {'scene': self.scene, 'size': self.size, 'seed': self.seed,
                   'optimiser': self.optimiser, **row,
                   'calls': int(row['calls']),
                   'energy_error': row['energy'] - self.e_ref,
                   'status': self.status}


def calls_and_cpu(atoms: Atoms, optimizer: Any, fmax: float,
                  steps: int) -> tuple[int, float, bool]:
    """Run ``optimizer`` (built on ``atoms``) to ``fmax``: its calculator
    calls, process CPU seconds and whether it converged (the tools' one-line
    measurement; :func:`run_optimizer` keeps every sample)."""
    start = cpu_seconds()
    with CallRecorder(atoms.calc) as recorder:
        converged = bool(optimizer.run(fmax=fmax, steps=steps))
    return len(recorder.samples), cpu_seconds() - start, converged


def run_optimizer(start: Atoms, optimiser: str, fmax: float,
                  steps: int) -> tuple[np.ndarray, bool, str]:
    """Relax a fresh copy of ``start`` with ``OPTIMIZERS[optimiser]``.

    Returns ``(samples, converged, error)``: the (n, 5) sample array, whether
    the optimiser reported convergence, and the message of any exception it
    raised ('' if none). KeyboardInterrupt is not caught.
    """
    atoms = fresh_copy(start)
    converged, error = False, ''
    with CallRecorder(atoms.calc) as recorder:
        try:
            converged = bool(OPTIMIZERS[optimiser](atoms).run(fmax=fmax,
                                                              steps=steps))
        except Exception as exc:  # a failed run is a result, not a crash
            error = f'{type(exc).__name__}: {exc}'
    samples = np.array(recorder.samples, dtype=float).reshape(
        -1, len(SAMPLE_FIELDS))
    return samples, converged, error


def run_status(samples: np.ndarray, converged: bool, error: str, e_ref: float,
             energy_rtol: float) -> str:
    """The status of a run (see :class:`Run`): a converged run is in the
    reference minimum if its last energy is within ``energy_rtol`` (relative)
    of ``e_ref``."""
    if error:
        return 'error'
    if not converged:
        return 'not_converged'
    if abs(samples[-1, ENERGY] - e_ref) > energy_rtol * abs(e_ref):
        return 'other_minimum'
    return 'converged'


#: The names this module had in ase_maud 0.1 and gave to ase_maud.counting
#: (``CallRecorder``, ``fresh_copy``) or renamed (``classify``: :func:`run_status`).
__getattr__ = old_names('bench.runner')
