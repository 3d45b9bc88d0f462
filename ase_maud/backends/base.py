"""What a backend is: :class:`Backend`, and the layout of its nodal blocks.

A backend evaluates the unit-strength repulsion ``sum_{i<j} 1 / L_ij`` of
:mod:`ase_maud.physics` at every point of a scene; the calculator multiplies
by ``c = a**3 Q`` and adds the springs. Its ``evaluate(positions,
want_blocks, **options)`` takes positions of shape (N, 3) (a 2D scene has
``z = 0``) and returns ``(energy, forces (N, 3), block6 (N, 6) or None)``:
the energy counts each pair once, forces have ASE's sign, and ``block6``
holds the nodal blocks ``sum_j (3 d d^T / L**5 - I / L**3)`` as the entries
xx, yy, zz, xy, xz, yz (:data:`VOIGT_PAIRS`), computed only when
``want_blocks``. Coincident points give a non-finite energy, never an error:
the calculator names them.

A backend that cannot meet its tolerance on a scene raises
:class:`BeyondTolerance`. A backend that delegates (``auto``) has a
``choose`` function that returns, per call, the backends to try in order
(:class:`Choice`); :func:`evaluate_first` runs the first that can.
"""

from __future__ import annotations

import functools
import importlib.util
import sys
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

#: Order of the six independent entries of a symmetric 3x3 block.
VOIGT_PAIRS = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))

#: ``(energy, forces (N, 3), block6 (N, 6) or None)``, unit strength.
Result = tuple[float, np.ndarray, np.ndarray | None]


class BeyondTolerance(ValueError):
    """A backend cannot meet its tolerance on this scene; the message says
    why and names a backend that can."""


@dataclass(frozen=True)
class Backend:
    """A way to evaluate the repulsion, and what the registry says of it.

    ``name``: the calculator's ``backend`` parameter. ``evaluate``: see the
    module docstring. ``summary``: one line for help texts and reports.
    ``cost``: how the time of a call grows with the number of points N
    (``'N^2'`` or ``'N'``). ``computes``: of ``'energy'``, ``'forces'``,
    ``'blocks'``. ``tolerance``: ``None`` if the result is exact to rounding,
    else the name of the calculator parameter that sets its relative
    tolerance. ``parameters``: the calculator parameters it takes, with
    their defaults (the calculator's ``default_parameters`` are made of
    them; each is checked by its rule in :data:`ase_maud.checks.RULES`);
    ``evaluate`` receives them as keywords of the same names. ``requires``:
    modules it imports that may be missing (it is :attr:`installed` when all
    are importable). ``force_tolerance`` and ``energy_tolerance``: for an
    approximate backend, the force error it promises relative to the largest
    repulsive force, and the energy error relative to the repulsion energy,
    as functions of its options (None: exact). ``hvp``: if the backend has
    one, the unit repulsion's Hessian-vector product
    ``hvp(positions (N, 3), v (m, N, 3)) -> (m, N, 3)``,
    ``sum_j B_ij (v_i - v_j)``; ``hessian``: if it has one, the unit
    repulsion's energy, forces and dense Hessian in one call,
    ``hessian(positions (N, 3), dim) -> (energy, forces (N, 3), (dim N, dim N))``.
    """

    name: str
    evaluate: Callable[..., Result]
    summary: str
    cost: str
    computes: frozenset[str] = frozenset({'energy', 'forces', 'blocks'})
    tolerance: str | None = None
    parameters: Mapping[str, Any] = field(default_factory=dict)
    requires: tuple[str, ...] = ()
    force_tolerance: Callable[..., float] | None = None
    energy_tolerance: Callable[..., float] | None = None
    choose: Callable[..., list[Choice]] | None = None
    hvp: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None
    hessian: Callable[[np.ndarray, int], tuple[float, np.ndarray, np.ndarray]] | None = None

    @property
    def exact(self) -> bool:
        """Whether results are exact to rounding (no tolerance parameter)."""
        return self.tolerance is None

    @property
    def accuracy(self) -> str:
        """``'exact'``, or ``'approximate (<tolerance parameter>)'``."""
        return 'exact' if self.exact else f'approximate ({self.tolerance})'

    @property
    def installed(self) -> bool:
        """Whether every module in ``requires`` can be imported (looked up
        once per process: the ``auto`` backend asks at every call)."""
        return all(map(_importable, self.requires))

    def options(self, parameters: Mapping[str, Any]) -> dict[str, Any]:
        """The keywords of ``evaluate``, taken from calculator parameters."""
        return {name: parameters[name] for name in self.parameters}

    def choices(self, natoms: int, dim: int, want_blocks: bool,
                parameters: Mapping[str, Any]) -> list[Choice]:
        """The backends to try, in order, for one call on ``natoms`` points
        in ``dim`` dimensions: this backend alone, unless it delegates."""
        options = self.options(parameters)
        if self.choose is not None:
            return self.choose(natoms, dim, want_blocks, **options)
        if self.exact:
            return [Choice(self, options, 0.0)]
        return [Choice(self, options, self.force_tolerance(**options),
                       self.energy_tolerance(**options))]


@dataclass(frozen=True)
class Choice:
    """One backend picked for a call: ``backend``, the keywords ``options``
    of its ``evaluate``, ``tolerance``, the force error it promises
    relative to the largest repulsive force, and ``energy_tolerance``, the
    error of the repulsion energy it promises relative to that energy (0.0:
    exact to rounding)."""

    backend: Backend
    options: Mapping[str, Any]
    tolerance: float
    energy_tolerance: float = 0.0


def evaluate_first(choices: list[Choice], positions: np.ndarray,
                   want_blocks: bool) -> tuple[Result, Choice]:
    """Evaluate by the first of ``choices`` that does not raise
    :class:`BeyondTolerance` (the last one's error is raised); return the
    result and the choice that gave it."""
    for choice in choices[:-1]:
        try:
            return (choice.backend.evaluate(positions, want_blocks,
                                            **choice.options), choice)
        except BeyondTolerance:
            continue
    last = choices[-1]
    return last.backend.evaluate(positions, want_blocks, **last.options), last


def _importable(module: str) -> bool:
    """Whether ``module`` can be imported, without importing it: an entry
    of ``sys.modules`` (None: blocked) decides, else one lookup per process."""
    if module in sys.modules:
        return sys.modules[module] is not None
    return _findable(module)


@functools.cache
def _findable(module: str) -> bool:
    return importlib.util.find_spec(module) is not None


def voigt_to_blocks(block6: np.ndarray, dim: int) -> np.ndarray:
    """Expand (N, 6) xx, yy, zz, xy, xz, yz entries to (N, dim, dim) blocks."""
    out = np.empty((len(block6), 3, 3))
    for col, (a, b) in enumerate(VOIGT_PAIRS):
        out[:, a, b] = out[:, b, a] = block6[:, col]
    return out[:, :dim, :dim]


def blocks_to_voigt(blocks: np.ndarray) -> np.ndarray:
    """The (N, 6) xx, yy, zz, xy, xz, yz entries of (N, 3, 3) blocks."""
    return np.stack([blocks[:, a, b] for a, b in VOIGT_PAIRS], axis=1)


def diagonal_blocks(hessian: np.ndarray, dim: int) -> np.ndarray:
    """The (N, 6) xx, yy, zz, xy, xz, yz entries of the nodal blocks on the
    diagonal of a (dim N, dim N) ``hessian`` (zeros beyond ``dim``)."""
    n = len(hessian) // dim
    blocks = np.zeros((n, 3, 3))
    index = np.arange(n)
    blocks[:, :dim, :dim] = hessian.reshape(n, dim, n, dim)[index, :, index, :]
    return blocks_to_voigt(blocks)
