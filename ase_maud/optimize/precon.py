"""MaudPrecon: the global stiffness model as an ASE preconditioner.

ASE's preconditioned optimisers (:class:`~ase.optimize.precon.PreconLBFGS`,
:class:`~ase.optimize.precon.PreconFIRE`) take a
:class:`~ase.optimize.precon.Precon`: a sparse symmetric positive-definite
``P`` (3N x 3N, ASE's interlaced x, y, z order) that they solve with at every
step. :class:`MaudPrecon` is the global model of :mod:`ase_maud.optimize.models.base`,

    P = Q (L (x) I_dim) + blockdiag(|K_mm - Q deg(m) I|)   (force per length)

on the free degrees of freedom, and ``s I`` on the others (fixed by FixAtoms
or FixCartesian, and ``z`` of a ``dim=2`` scene), with ``s`` the mean of
``P``'s diagonal, so that the whole matrix stays positive definite and a
zero force there gives a zero move.

Building ``P`` needs the nodal blocks (calculator property ``stiffness``),
which a MaudCalculator computes in a calculator call of its own when the
optimiser has only asked for the forces. ``P`` is therefore rebuilt only when
some point has moved by more than ``refresh`` times its nearest-neighbour
distance since the last build (ASE's Exp preconditioner does the same with
half the nearest-neighbour distance). PreconLBFGS's default ``maxstep`` (0.04
length units) caps every step with this preconditioner: pass a larger one
(``maxstep=1.0``, the largest ASE accepts, in units of the scene's ``a``).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from ase import Atoms
from ase.optimize.precon import Precon

from ase_maud.optimize.models.global_model import GlobalModel


class MaudPrecon(Precon):
    """ASE ``Precon`` over the global stiffness model; see the module docstring.

    Parameters
    ----------
    floor : float
        Relative eigenvalue floor of the repulsion blocks (default 1e-2).
    refresh : float
        Rebuild ``P`` when a point has moved more than this fraction of its
        nearest-neighbour distance since the last build (default 0.5, the
        global model's; 0 means at every call).

    Raises
    ------
    ValueError
        ``floor`` or ``refresh`` outside their rules (named). When ASE
        builds ``P`` (``make_precon``): atoms whose calculator offers no
        stiffness, or atoms the calculator refuses.

    Examples
    --------
    >>> from ase.optimize.precon import PreconLBFGS           # doctest: +SKIP
    >>> PreconLBFGS(atoms, precon=MaudPrecon()).run(fmax=1e-4)  # doctest: +SKIP
    """

    def __init__(self, floor: float = 1e-2, refresh: float = 0.5):
        self.model = GlobalModel(floor=floor, refresh=refresh)
        self.P: sp.csr_matrix | None = None
        self.solver = None

    def make_precon(self, atoms: Atoms, reinitialize: bool | None = None
                    ) -> sp.csr_matrix:
        """Build ``P`` at ``atoms`` (unless the kept one is recent enough,
        see :class:`~ase_maud.optimize.models.global_model.GlobalModel`); return it."""
        atoms = getattr(atoms, 'atoms', atoms)  # a Filter holds the Atoms
        if reinitialize:
            self.model = GlobalModel(floor=self.model.floor, refresh=self.model.refresh)
        solver = self.model.at(atoms)
        if solver is not self.solver:
            self.solver = solver
            free = np.zeros((len(atoms), 3), dtype=bool)
            free[:, :solver.dim] = solver.free
            self._free = free.ravel()
            inner = solver.matrix
            self._scale = float(inner.diagonal().mean()) if inner.shape[0] else 1.0
            pick = sp.eye(free.size, format='csr')[np.flatnonzero(self._free)]
            self.P = (pick.T @ inner @ pick + sp.diags(
                self._scale * ~self._free)).tocsr()
        return self.P

    def Pdot(self, x: np.ndarray) -> np.ndarray:
        """``P x`` for a flat 3N vector."""
        return self.P @ np.ravel(x)

    def solve(self, x: np.ndarray) -> np.ndarray:
        """``P^-1 x`` for a flat 3N vector."""
        x = np.ravel(x)
        y = x / self._scale
        y[self._free] = self.solver.solve(x.reshape(-1, 3)).ravel()[self._free]
        return y

    def copy(self) -> MaudPrecon:
        """A new, unbuilt preconditioner with the same settings (a
        factorisation cannot be copied; :meth:`make_precon` builds one)."""
        return MaudPrecon(self.model.floor, self.model.refresh)

    def asarray(self) -> np.ndarray:
        """``P`` as a dense array (small scenes only)."""
        return self.P.toarray()
