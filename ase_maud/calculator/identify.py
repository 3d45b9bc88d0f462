"""What a scene's MaudCalculator says of it, asked by type, not by probing for
attributes: its potential (:func:`potential_of`) and dimension
(:func:`scene_dim`), and the parameters a frame read from a file stores
(:func:`stored_parameters`).
"""

from __future__ import annotations

from typing import Any

from ase import Atoms

from ase_maud.calculator.maud_calculator import MaudCalculator
from ase_maud.calculator.potential import MaudPotential


def potential_of(atoms: Any) -> MaudPotential | None:
    """The :class:`~ase_maud.calculator.potential.MaudPotential` of
    ``atoms``' calculator (its springs, ``a``, ``Q``, loads) if that is a
    MaudCalculator, a subclass too; None for another calculator, none, or an
    object without one (a band of images, a filter)."""
    calc = getattr(atoms, 'calc', None)
    return calc.potential if isinstance(calc, MaudCalculator) else None


def scene_dim(atoms: Any) -> int:
    """2 for ``atoms`` whose MaudCalculator keeps them in a plane, else 3."""
    potential = potential_of(atoms)
    return 3 if potential is None else potential.dim


#: The name under which ASE's trajectory stores a MaudCalculator.
CALC_NAME = 'maudcalculator'


def stored_parameters(frame: Atoms) -> dict[str, Any]:
    """The MaudCalculator parameters a frame read from a file stores with
    its energy and forces (an ASE trajectory does), or {}."""
    calc = frame.calc
    stored = calc is not None and getattr(calc, 'name', '') == CALC_NAME
    return {k: v for k, v in calc.parameters.items()
            if k in MaudCalculator.default_parameters} if stored else {}
