"""The registry of backends: every way to evaluate the repulsion, by name.

A backend (:class:`~.base.Backend`) says what it computes, how exact it is,
whether it is installed, how its cost grows, which calculator parameters it
takes, and evaluates the unit-strength repulsion (:mod:`.base`). The
calculator, the ``ase-maud backends`` command and the benchmark read this
registry, and nothing else names a backend.

Registered: ``numba`` (:mod:`.direct`), ``numpy`` (:mod:`.reference`),
``fmm`` (:mod:`.fmm`) and ``auto`` (:mod:`.auto`, the default: per call the
cheapest of the others that meets the calculator's ``tol``). The calculator
evaluates through :func:`evaluate`, which asks the named backend for its
choices and runs the first that can meet its tolerance. Adding one (a Barnes-Hut tree,
a GPU kernel) is one new file here that defines ``BACKEND =
Backend(name=..., evaluate=..., ...)``, plus one registration line at the end
of this file, ``register(newmodule.BACKEND)`` (and its module in the import
line). The parameters it takes, with their defaults, become the calculator's
(:func:`parameter_defaults`); a new parameter's rule goes into
:data:`ase_maud.checks.RULES`.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from ase_maud.backends import auto, direct, fmm, reference
from ase_maud.backends.base import (
    VOIGT_PAIRS,
    Backend,
    BeyondTolerance,
    Choice,
    Result,
    blocks_to_voigt,
    evaluate_first,
    voigt_to_blocks,
)
from ase_maud.checks import check

__all__ = ['Backend', 'BeyondTolerance', 'Choice', 'Result', 'VOIGT_PAIRS',
           'blocks_to_voigt', 'check_parameters', 'evaluate', 'get',
           'installed', 'names', 'parameter_defaults', 'register',
           'repulsion_hvp', 'voigt_to_blocks', 'exact_choice']

_REGISTRY: dict[str, Backend] = {}


def register(backend: Backend) -> None:
    """Add ``backend``; a second backend of the same name, or an approximate
    one that neither delegates nor says its errors (``force_tolerance`` and
    ``energy_tolerance``), is a ValueError."""
    if backend.name in _REGISTRY:
        raise ValueError(f'a backend named {backend.name!r} is already '
                         'registered')
    if not backend.exact and backend.choose is None and None in (
            backend.force_tolerance, backend.energy_tolerance):
        raise ValueError(f'the approximate backend {backend.name!r} must say the errors '
                         'it promises: force_tolerance and energy_tolerance')
    _REGISTRY[backend.name] = backend
    _EXACT.clear()   # an earlier pick may have another first backend now


def get(name: str) -> Backend:
    """The backend called ``name``, or a ValueError listing them all."""
    try:
        return _REGISTRY[name]
    except (KeyError, TypeError):
        raise ValueError(f'backend must be one of {sorted(_REGISTRY)}, '
                         f'got {name!r}') from None


def names() -> list[str]:
    """Every registered backend's name, in order of registration."""
    return list(_REGISTRY)


def installed() -> list[str]:
    """The names of the backends whose modules can be imported."""
    return [name for name, backend in _REGISTRY.items() if backend.installed]


def parameter_defaults() -> dict[str, Any]:
    """Every registered backend's parameters with their defaults (the
    calculator's ``default_parameters`` beside the potential's)."""
    return {name: default for backend in _REGISTRY.values()
            for name, default in backend.parameters.items()}


def check_parameters(parameters: Mapping[str, Any]) -> None:
    """Raise ValueError unless ``parameters['backend']`` is registered and
    every backend parameter in ``parameters`` is valid (checked whichever
    backend is chosen, so a later switch of backend cannot fail)."""
    get(parameters['backend'])
    for name in parameter_defaults():
        if name in parameters:
            check(name, parameters[name])


def repulsion_hvp(positions: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The unit repulsion's Hessian-vector products ``sum_j B_ij (v_i -
    v_j)`` at ``positions`` (N, 3) for ``v`` (m, N, 3), by the first
    installed backend that has them (``hvp``)."""
    return _first_with('hvp')(positions, v)


def exact_choice(backend: str) -> Choice:
    """The :class:`Choice` whose backend gives the unit repulsion's energy,
    forces and dense Hessian in one pass (``choice.backend.hessian``) for
    the calculator parameter ``backend``: itself if it has a Hessian
    (``numba``, ``numpy``), else (``auto``, ``fmm``) the first installed one
    that has (exact: tolerance 0)."""
    if backend not in _EXACT:
        _EXACT[backend] = Choice(_hessian_backend(backend), {}, 0.0)
    return _EXACT[backend]


#: :func:`exact_choice`'s picks by parameter (the same every call until a
#: backend is registered).
_EXACT: dict[str, Choice] = {}


def _hessian_backend(name: str) -> Backend:
    """``name``'s backend if it computes the Hessian, else the first
    installed one that does."""
    own = get(name)
    if own.hessian is not None:
        return own
    return next(backend for backend in _REGISTRY.values()
                if backend.hessian is not None and backend.installed)


def _first_with(capability: str):
    for backend in _REGISTRY.values():
        if getattr(backend, capability) is not None and backend.installed:
            return getattr(backend, capability)
    raise ValueError(f'no registered backend computes {capability}')


def evaluate(parameters: Mapping[str, Any], positions: np.ndarray, dim: int,
             want_blocks: bool) -> tuple[Result, Choice]:
    """The unit repulsion at ``positions`` (N, 3) by the backend named in
    ``parameters['backend']`` (or the one it picks for these N, ``dim`` and
    ``want_blocks``), and the :class:`Choice` that computed it."""
    choices = get(parameters['backend']).choices(len(positions), dim,
                                                  want_blocks, parameters)
    return evaluate_first(choices, positions, want_blocks)


register(direct.BACKEND)
register(reference.BACKEND)
register(fmm.BACKEND)
register(auto.BACKEND)
