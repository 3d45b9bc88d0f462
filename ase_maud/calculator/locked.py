"""A thread-safe ASE calculator that tells changes exactly and keeps the
atoms it last computed without copying them anew at every step:
:class:`LockedCalculator`, the base of
:class:`~ase_maud.calculator.maud_calculator.MaudCalculator`.
"""

from __future__ import annotations

import threading
from collections.abc import Sequence
from typing import Any

from ase import Atoms
from ase.calculators.calculator import Calculator, all_changes


class LockedCalculator(Calculator):
    """ASE's ``Calculator`` with its property requests one thread at a time
    (its own lock, not pickled), changes compared exactly
    (:meth:`check_state`), the atoms held updated in place (:meth:`_hold`)
    and :meth:`compute`, all the properties of a move in one call."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self._lock = threading.RLock()
        super().__init__(*args, **kwargs)

    def get_property(self, name: str, atoms: Atoms | None = None,
                     allow_calculation: bool = True) -> Any:
        """ASE's, one thread at a time: threads that share this calculator
        (each with its own atoms) each get the results of their atoms, not
        those another thread's call left."""
        with self._lock:
            return super().get_property(name, atoms, allow_calculation)

    def __getstate__(self) -> dict[str, Any]:
        state = self.__dict__.copy()
        del state['_lock']   # a lock is not copied or pickled: each copy has its own
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)
        self._lock = threading.RLock()

    def check_state(self, atoms: Atoms, tol: float = 1e-15) -> list[str]:
        """What changed since the last calculation, compared exactly.

        ASE's default compares positions within an absolute ``tol``, which
        misses every move of a scene whose ``a`` is below about 1e-10 and
        costs several ``isclose`` calls per property request; the potential
        depends only on the positions (and the number of points), so those,
        the cell and pbc are compared exactly, whatever the scale.
        """
        old = self.atoms
        if old is None or len(old) != len(atoms):
            return list(all_changes)
        return [name for name, was, now in (
            ('positions', old.arrays['positions'], atoms.arrays['positions']),
            ('numbers', old.arrays['numbers'], atoms.arrays['numbers']),
            ('cell', old.cell.array, atoms.cell.array), ('pbc', old.pbc, atoms.pbc))
            if not (was == now).all()]

    def _hold(self, atoms: Atoms, system_changes: Sequence[str]) -> None:
        """Keep what :meth:`check_state` compares next time (ASE's
        ``Calculator.calculate`` keeps ``atoms.copy()``, and ASE's
        ``get_property`` has made one already): the copy held is updated in
        place when ``system_changes`` (what :meth:`check_state` found, or
        what :meth:`compute` is told) name the positions alone and the atoms
        and their constraints are as many as held, and made anew otherwise."""
        old = self.atoms
        if old is atoms:
            return
        if (old is None or len(old) != len(atoms)
                or len(old.constraints) != len(atoms.constraints)
                or not set(system_changes) <= {'positions'}):
            self.atoms = atoms.copy()
        else:
            old.arrays['positions'][:] = atoms.arrays['positions']

    def compute(self, atoms: Atoms, properties: Sequence[str]) -> dict[str, Any]:
        """The ``properties`` of ``atoms`` computed now, in one call (what
        ``get_property`` does after a move, without its change detection and
        copy of the atoms): for an optimizer that moves the positions itself,
        so ``atoms`` differ from those of the last call in their positions
        only. Returns :attr:`results`."""
        with self._lock:
            self.results = {}
            self.calculate(atoms, properties, ['positions'])
            return self.results
