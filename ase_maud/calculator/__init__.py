"""The ASE calculator: :class:`MaudCalculator` (energy, forces, nodal
stiffness blocks, Hessian) over :class:`MaudPotential` (the scene's springs,
force densities, loads and the backend that sums the repulsion), and the
accuracy a run asks of it (:mod:`~ase_maud.calculator.accuracy`).
"""

from ase_maud.calculator.maud_calculator import MaudCalculator
from ase_maud.calculator.potential import MaudPotential
from ase_maud.old_paths import old_names

__all__ = ['MaudCalculator', 'MaudPotential']
#: The names of ase_maud 0.1's ``ase_maud.calculator`` module, handed on with a warning.
__getattr__ = old_names('calculator')
