"""Run one optimiser from one start, with a sample at every calculator call.

A *sample* is ``(calls, time_s, fmax, energy)`` taken right after each call of
``calc.calculate``: ``calls`` counts those calls (line-search trials and
stiffness requests included, optimiser steps not), ``time_s`` is wall time
since the run began (the optimiser's construction included, the sampling
itself left out), ``fmax`` the largest atomic force norm after the atoms'
constraints, ``energy`` the potential energy.
"""

import time
from dataclasses import dataclass

import numpy as np

from .optimizers import OPTIMIZERS

#: Fields of one sample, the columns of :attr:`Run.samples`.
SAMPLE_FIELDS = ('calls', 'time_s', 'fmax', 'energy')


class CallRecorder:
    """Context manager counting and sampling the calls of ``calc.calculate``.

    It shadows the method on this calculator instance only and restores it
    on exit. ``samples`` is the list of sample tuples so far.
    """

    def __init__(self, calc):
        self.calc = calc
        self.samples = []
        self._overhead = 0.0
        self._t0 = time.perf_counter()

    def __enter__(self):
        self._calculate = self.calc.calculate
        self.calc.calculate = self._calculate_and_sample
        return self

    def __exit__(self, *exc):
        del self.calc.calculate

    def _calculate_and_sample(self, *args, **kwargs):
        self._calculate(*args, **kwargs)
        now = time.perf_counter()
        atoms, results = self.calc.atoms, self.calc.results
        forces = results['forces'].copy()
        for constraint in atoms.constraints:
            constraint.adjust_forces(atoms, forces)
        self.samples.append((len(self.samples) + 1,
                             now - self._t0 - self._overhead,
                             np.sqrt((forces**2).sum(axis=1).max()),
                             results['energy']))
        self._overhead += time.perf_counter() - now


@dataclass
class Run:
    """One optimiser's run from one start.

    ``samples`` is an array (n, 4) of :data:`SAMPLE_FIELDS`; ``status`` is
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

    def reached(self, fmax):
        """(calls, time_s) of the first sample with fmax <= ``fmax``, or
        (inf, inf) if none, or if the run ended in another minimum."""
        hit = np.flatnonzero(self.samples[:, 2] <= fmax)
        if self.status == 'other_minimum' or not hit.size:
            return np.inf, np.inf
        calls, time_s = self.samples[hit[0], :2]
        return calls, time_s

    def rows(self):
        """One dict per sample: the columns of the benchmark's samples CSV."""
        for calls, time_s, fmax, energy in self.samples:
            yield {'scene': self.scene, 'size': self.size, 'seed': self.seed,
                   'optimiser': self.optimiser, 'calls': int(calls),
                   'time_s': time_s, 'fmax': fmax, 'energy': energy,
                   'energy_error': energy - self.e_ref, 'status': self.status}


def fresh_copy(atoms):
    """A copy of ``atoms`` (constraints included) with a new calculator of
    the same class and parameters: the same start, no shared results."""
    copy = atoms.copy()
    copy.calc = type(atoms.calc)(**atoms.calc.parameters)
    return copy


def run_optimizer(start, optimiser, fmax, steps):
    """Relax a fresh copy of ``start`` with ``OPTIMIZERS[optimiser]``.

    Returns ``(samples, converged, error)``: the (n, 4) sample array, whether
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
    samples = np.array(recorder.samples, dtype=float).reshape(-1, 4)
    return samples, converged, error


def classify(samples, converged, error, e_ref, energy_rtol):
    """The status of a run (see :class:`Run`): a converged run is in the
    reference minimum if its last energy is within ``energy_rtol`` (relative)
    of ``e_ref``."""
    if error:
        return 'error'
    if not converged:
        return 'not_converged'
    if abs(samples[-1, 3] - e_ref) > energy_rtol * abs(e_ref):
        return 'other_minimum'
    return 'converged'
