"""What a computation cost, counted: calculator calls (:class:`CallRecorder`)
and the work beyond them (:class:`Work`: Hessian-vector products and dense
Hessians), the CPU seconds spent (:func:`cpu_seconds`, worker processes
included), and :func:`fresh_copy`, a start with a calculator of its own.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass

import numpy as np
from ase import Atoms
from ase.calculators.calculator import Calculator

#: CPU seconds that worker processes spent on this process's calls (the
#: FMM's, :mod:`ase_maud.backends.fmm`): ``time.process_time`` leaves them out.
_worker_cpu_s = 0.0
_WORKER_CPU_LOCK = threading.Lock()


def add_worker_cpu(seconds: float) -> None:
    """Count ``seconds`` of CPU a worker process spent on a call of this one
    (from any thread)."""
    global _worker_cpu_s
    with _WORKER_CPU_LOCK:
        _worker_cpu_s += seconds


def worker_cpu_seconds() -> float:
    """CPU seconds so far of the worker processes that served this process's
    calls."""
    return _worker_cpu_s


def cpu_seconds() -> float:
    """CPU seconds so far of this process (``time.process_time``: every
    thread) and of the worker processes that served its calls: the clock of
    every CPU figure (differences of two readings)."""
    return time.process_time() + _worker_cpu_s


@dataclass
class Work:
    """What a search computed beyond its calculator calls, in force-call
    equivalents: ``hvp_vectors``, the vectors multiplied by the Hessian
    (:func:`hessian_operator`; a block of k vectors is k, each costing about
    one force call), and ``hessians``, the dense Hessians computed. Apart,
    not in :attr:`total`: ``near_products``, the products with the
    near-field model's sparse ``P`` (:mod:`ase_maud.optimize.models.near`), each
    O(near pairs), far below a force call."""

    hvp_vectors: int = 0
    hessians: int = 0
    near_products: int = 0

    @property
    def total(self) -> int:
        """Hessian-vector products and Hessians, one equivalent each."""
        return self.hvp_vectors + self.hessians


class CallRecorder:
    """Context manager counting and sampling the calls of ``calc.calculate``.

    It shadows the method on this calculator instance only and restores it
    on exit. ``samples`` is the list of sample tuples so far.
    """

    def __init__(self, calc: Calculator):
        self.calc = calc
        self.samples: list[tuple[float, ...]] = []
        self._overhead = np.zeros(2)           # wall, CPU seconds
        self._t0 = self._clocks()

    @staticmethod
    def _clocks() -> np.ndarray:
        """(wall, process CPU) seconds now."""
        return np.array([time.perf_counter(), cpu_seconds()])

    def __enter__(self):
        self._calculate = self.calc.calculate
        self.calc.calculate = self._calculate_and_sample
        return self

    def __exit__(self, *exc):
        del self.calc.calculate

    def _calculate_and_sample(self, *args, **kwargs):
        self._calculate(*args, **kwargs)
        now = self._clocks()
        atoms, results = self.calc.atoms, self.calc.results
        forces = results['forces'].copy()
        for constraint in atoms.constraints:
            constraint.adjust_forces(atoms, forces)
        wall, cpu = now - self._t0 - self._overhead
        self.samples.append((len(self.samples) + 1, wall, cpu,
                             np.sqrt((forces**2).sum(axis=1).max()),
                             results['energy']))
        self._overhead += self._clocks() - now


def fresh_copy(atoms: Atoms) -> Atoms:
    """A copy of ``atoms`` (constraints included) with a new calculator of
    the same class and parameters: the same start, no shared results."""
    copy = atoms.copy()
    copy.calc = type(atoms.calc)(**atoms.calc.parameters)
    return copy
