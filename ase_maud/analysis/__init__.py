"""What a configuration is: :func:`classify` (minimum, saddle of index k,
maximum, or not stationary, from the analytic Hessian), the Hessian's products
and lowest modes (:mod:`~ase_maud.analysis.stationary`), and vibration modes
through phonopy and ASE (:mod:`~ase_maud.analysis.modes`).
"""

from ase_maud.analysis.stationary import StationaryPoint, classify, displace_along_mode, same_point
from ase_maud.old_paths import old_names

__all__ = ['StationaryPoint', 'classify', 'displace_along_mode', 'same_point']
#: The names of ase_maud 0.1's ``ase_maud.analysis`` module, handed on with a warning.
__getattr__ = old_names('analysis')
