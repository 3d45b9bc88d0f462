"""ase_maud: the Maud algorithm for points that repel and are tied by springs.

- :class:`MaudCalculator`: the potential ``a^3 Q / L`` between every pair plus
  zero-length springs ``Q L^2 / 2`` on listed pairs, with nodal stiffness blocks.
- :class:`Maud`: the tensor/scalar Maud step with dynamic relaxation, an ASE
  optimizer.
"""

from .calculator import MaudCalculator
from .optimizer import DivergenceError, Maud, MaudError, StagnationError

__all__ = ['MaudCalculator', 'Maud', 'MaudError', 'DivergenceError',
           'StagnationError']
__version__ = '0.1.0'
