"""What a Maud step is handed by ASE: the energy and gradient, fetched
together once per positions and checked finite, and where the last step
left the run.

- :class:`CheckedOptimizable` wraps ASE's optimizable: ASE's loop and the
  step ask for the energy and gradient several times at the same positions;
  they are fetched once, and a non-finite value stops the run (a
  :class:`~ase_maud.errors.MaudError` naming the step, the atom and the
  value) with the positions put back where the results were finite.
- :class:`Padded`: an optimizable whose number of coordinates is not a
  multiple of 3 (a function of 2 variables, say) seen as rows of 3, as the
  step works on (N, 3) arrays.
- :class:`Handoff`: the positions, calculator and potential at the end of a
  step, compared at the next run's start (the run starts afresh if any
  changed).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from ase.calculators.calculator import PropertyNotImplementedError

from ase_maud.calculator.identify import potential_of
from ase_maud.errors import MaudError


@dataclass(eq=False)
class Handoff:
    """Positions, calculator and potential at the end of a step; equal to
    another when the positions are equal in every bit and the calculator and
    potential are the same objects."""

    x: np.ndarray
    calc: Any
    potential: Any

    @classmethod
    def of(cls, x: np.ndarray, atoms: Any) -> Handoff:
        """The handoff at positions ``x`` of ``atoms`` (None: no calculator)."""
        calc = getattr(atoms, 'calc', None)
        return cls(x.copy(), calc, potential_of(atoms))

    def __eq__(self, other: object) -> bool:
        return (isinstance(other, Handoff) and np.array_equal(self.x, other.x)
                and self.calc is other.calc and self.potential is other.potential)


class CheckedOptimizable:
    """The optimizable with its energy and gradient fetched together, once
    per positions, and checked finite (everything else passes through).

    ASE's loop and the step ask for both several times at the same
    positions; they are kept with the positions ``x`` they belong to and
    fetched again as soon as ``x`` differs in any bit (the calculator's own
    change detection then decides what to recompute). A non-finite value
    puts the positions back to the last ones whose results were finite and
    stops the run with a MaudError naming the step and the value. ASE asks
    for both before it logs a step or writes its frame, so neither sees it.
    """

    def __init__(self, inner: Any, steps: Callable[[], int],
                 stop: Callable[[MaudError], None]):
        self.inner = inner
        self.steps, self.stop = steps, stop
        self.good: tuple[np.ndarray, int] | None = None  # positions, step
        # x, E, gradient, and the calculator's forces object they came from
        self.held: tuple[np.ndarray, float, np.ndarray, Any] | None = None

    def __getattr__(self, name: str) -> Any:
        return getattr(self.inner, name)

    def get_value(self) -> float:
        return self._results()[1]

    def get_gradient(self) -> np.ndarray:
        return self._results()[2].copy()

    def _results(self) -> tuple[np.ndarray, float, np.ndarray]:
        x = self.inner.get_x()
        if (self.held is not None and np.array_equal(x, self.held[0])
                and self.held[3] is self._witness()):
            return self.held[:3]
        gradient = self._checked(x, self.inner.get_gradient)
        rows = gradient.reshape(-1, 3)
        bad = np.flatnonzero(~np.isfinite(rows).all(axis=1))
        if bad.size:
            force = ', '.join(f'{v:.6g}' for v in 0.0 - rows[bad[0]])
            self._fail(f'non-finite forces (atom {bad[0]}: [{force}]'
                       f'{f" and {bad.size - 1} more atoms" if bad.size > 1 else ""})')
        value = self._checked(x, self.inner.get_value)
        if not np.isfinite(value):
            self._fail(f'a non-finite energy ({value})')
        self.good = (x.copy(), self.steps())
        self.held = (x.copy(), value, gradient, self._witness())
        return self.held[:3]

    def _checked(self, x: np.ndarray, get: Callable[[], Any]) -> Any:
        """``get()`` (the inner gradient or value), or a ValueError naming
        the calculator if its forces are not one row of three per atom (the
        positions' shape) or it lacks a property (no energy, say)."""
        atoms = getattr(self.inner, 'atoms', None)
        calc = type(getattr(atoms, 'calc', None)).__name__
        try:
            result = get()
        except PropertyNotImplementedError as error:
            raise ValueError(f'the calculator ({calc}): {error}: Maud needs the energy '
                             'and forces (as BFGS and LBFGS do; FIRE needs the forces '
                             'alone)') from None
        if np.ndim(result) and np.size(result) != x.size:
            forces = atoms.get_forces() if atoms is not None else result
            raise ValueError(f'the calculator ({calc}) returned forces of shape '
                             f'{np.shape(forces)}; an optimiser needs one row of three '
                             f'components per atom, {x.size // 3} x 3')
        return result

    def _witness(self) -> Any:
        """The calculator's forces object behind the results held: a new
        calculation or a ``calc.set`` that drops the results (from an
        observer, say) replaces it, and the results are fetched again."""
        calc = getattr(getattr(self.inner, 'atoms', None), 'calc', None)
        results = getattr(calc, 'results', None)
        return results.get('forces') if isinstance(results, dict) else None

    def _fail(self, what: str) -> None:
        if self.good is None:
            where = 'the atoms are at their start positions'
        else:
            self.inner.set_x(self.good[0])
            where = f'positions restored to step {self.good[1]}'
        self.stop(MaudError(f'the calculator returned {what} at step '
                            f'{self.steps()}; {where}'))


class Padded:
    """An optimizable of ``n`` coordinates, ``n`` not a multiple of 3, seen
    as ``ceil(n / 3)`` rows of 3: zeros after its coordinates, held there by
    a zero gradient (so no step moves them), and dropped again before its
    own ``set_x``, ``converged`` and ``gradient_norm`` see them (everything
    else passes through)."""

    def __init__(self, inner: Any):
        self.inner = inner
        self.n = inner.get_x().size
        self.pad = -self.n % 3

    def __getattr__(self, name: str) -> Any:
        return getattr(self.inner, name)

    def ndofs(self) -> int:
        return self.n + self.pad

    def get_x(self) -> np.ndarray:
        return np.concatenate([self.inner.get_x(), np.zeros(self.pad)])

    def set_x(self, x: np.ndarray) -> None:
        self.inner.set_x(x[:self.n])

    def get_gradient(self) -> np.ndarray:
        return np.concatenate([self.inner.get_gradient(), np.zeros(self.pad)])

    def converged(self, gradient: np.ndarray, fmax: float) -> bool:
        return self.inner.converged(gradient[:self.n], fmax)

    def gradient_norm(self, gradient: np.ndarray) -> float:
        return self.inner.gradient_norm(gradient[:self.n])


def in_rows_of_3(optimizable: Any) -> Any:
    """``optimizable`` itself if its coordinates are a multiple of 3, else
    :class:`Padded`."""
    return optimizable if optimizable.get_x().size % 3 == 0 else Padded(optimizable)


def no_step_error(step: int, why: str, model: Any, atoms: Any) -> MaudError:
    """The MaudError of a run that has no finite step from ``step`` because
    of ``why``, which gives way to a non-finite property of the calculator
    of ``atoms`` (None: none) if the ``model`` needs one and it is the cause
    (its first bad entry named)."""
    prop = None if atoms is None else model.needs(atoms)
    if prop is not None:
        value = np.asarray(atoms.calc.get_property(prop, atoms))
        if not np.isfinite(value).all():
            where = np.argwhere(~np.isfinite(value))[0].tolist()
            why = (f'the calculator returned a non-finite {prop} (entry '
                   f'{where}: {value[tuple(where)]})')
    return MaudError(f'no finite step from step {step}: {why}; the positions are '
                     f'those of step {step}')
