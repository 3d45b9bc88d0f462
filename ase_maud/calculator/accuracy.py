"""The accuracy a run asks of its calculator, and the protocol to ask it by.

A calculator whose forces can be computed to a chosen relative error (a
MaudCalculator: its ``auto`` backend takes the FMM for a coarse ``tol``, the
exact direct sum for a fine one) is :class:`ToleranceAware`. An optimiser
asks it, before each evaluation, for the force error it needs then
(:func:`ask`): :data:`ACCURACY_FRACTION` of the larger of the requested
``fmax`` and the current one, at most :data:`MAX_RUN_TOL` of the largest
repulsive force (a run's first call, before any force is known, at the
calculator's own ``tol``): coarse, cheap sums far from the answer, fine ones
near it, and never a stall on evaluation noise. Forces below ``fmax`` on sums
too coarse to say so (:func:`settled`: the largest plus the promised error is
not) are computed again, at the accuracy ``fmax`` asks, before a run stops.
The energies it then compares carry the error the calculator declares for
them (:func:`energy_noise`, far below the forces': an energy sums positive
terms), a merit made of the forces that of the forces (:func:`force_noise`).
Other calculators are left alone.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any, Protocol, runtime_checkable

#: The force error a run asks for, as a fraction of the larger of the
#: requested ``fmax`` and the current one.
ACCURACY_FRACTION = 0.1
#: The coarsest ``tol`` a run asks for (relative to the largest force).
MAX_RUN_TOL = 1e-3


@runtime_checkable
class ToleranceAware(Protocol):
    """A calculator with a settable force tolerance.

    ``last_force_scale``: the largest repulsive force of the last call (force
    units; None before a call); ``last_tolerance``: the force error the
    results held promise, relative to it (0.0 exact); ``last_energy_error``:
    the error of the energy held (energy units; 0.0 exact); ``tolerance``: the
    relative force error asked of the next calls, which ``set_tolerance(tol)``
    sets.
    """

    last_force_scale: float | None
    last_tolerance: float | None
    last_energy_error: float | None
    tolerance: float

    def set_tolerance(self, tol: float) -> None: ...


_AWARE: dict[type, bool] = {}


def is_aware(calc: Any) -> bool:
    """Whether ``calc`` is :class:`ToleranceAware` (decided once per class:
    a protocol check looks at every attribute)."""
    kind = type(calc)
    if kind not in _AWARE:
        _AWARE[kind] = isinstance(calc, ToleranceAware)
    return _AWARE[kind]


def ask(calc: Any, fmax: float, fmax_now: float) -> None:
    """Set a :class:`ToleranceAware` calculator's tolerance for the next
    evaluation (module docstring); leave any other alone, and this one too
    while no call has measured its force scale (its own ``tol`` then)."""
    if not is_aware(calc) or not calc.last_force_scale:
        return
    wanted = ACCURACY_FRACTION * max(fmax, fmax_now) / calc.last_force_scale
    calc.set_tolerance(min(wanted, MAX_RUN_TOL))


def settled(calc: Any, fmax: float, fmax_now: float) -> bool:
    """Whether the forces ``calc`` holds, whose largest is ``fmax_now``, prove
    the largest force below ``fmax``: ``fmax_now`` plus their promised error
    is (always, for a calculator that is not :class:`ToleranceAware`)."""
    if not is_aware(calc) or not calc.last_force_scale:
        return fmax_now < fmax
    return fmax_now + (calc.last_tolerance or 0.0) * calc.last_force_scale < fmax


def force_noise(calc: Any) -> float:
    """The relative error of the forces ``calc`` holds: its
    ``last_tolerance`` if it is :class:`ToleranceAware`, else 0."""
    if is_aware(calc):
        return calc.last_tolerance or 0.0
    return 0.0


def energy_noise(calc: Any, energy: float) -> float:
    """The relative error of the energy ``energy`` that ``calc`` holds: its
    ``last_energy_error`` over ``|energy|`` if it is :class:`ToleranceAware`,
    else 0."""
    if is_aware(calc) and calc.last_energy_error:
        return calc.last_energy_error / max(abs(energy), 1e-300)
    return 0.0


@contextmanager
def kept(calc: Any) -> Iterator[None]:
    """Within: a run may ask a :class:`ToleranceAware` ``calc`` for other
    accuracies (:func:`ask`); after: its own tolerance is back, so that the
    calculator's settings stay the user's (any other ``calc`` is left alone)."""
    if not is_aware(calc):
        yield
        return
    before = calc.tolerance
    try:
        yield
    finally:
        calc.set_tolerance(before)
