"""What a Maud run carries from step to step (:class:`MaudState`): the
last point, the trust length, the secant memory; the restart file stores it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ase_maud.optimize.directions import PairRows
from ase_maud.optimize.models.base import Solver


@dataclass
class Point:
    """Where a step began: positions and forces (N, 3), the merit and its
    relative error (the calculator's tolerance when it was computed)."""

    x: np.ndarray
    merit: float
    forces: np.ndarray
    noise: float = 0.0

    def todict(self) -> dict[str, Any]:
        return {'x': self.x, 'merit': self.merit, 'forces': self.forces,
                'noise': self.noise}

    @classmethod
    def fromdict(cls, d: dict[str, Any]) -> Point:
        return cls(np.asarray(d['x'], float), float(d['merit']),
                   np.asarray(d['forces'], float), float(d['noise']))


@dataclass
class MaudState:
    """What a strategy has learnt in a run; a restart file holds
    :meth:`todict`.

    ``gamma``: the step factor (a trust fraction for :class:`Saddle`); ``k``:
    steps since the last momentum restart; ``v``: the last move (after
    constraints), or None; ``last``: where the last step began; ``pairs``:
    the L-BFGS memory ``(s, y)``; ``model``: what the stiffness model has
    learnt (:meth:`StiffnessModel.observe`); ``modes``: a saddle search's
    modes (:attr:`Saddle.kept_modes`, N, 3): the ``order`` it follows uphill,
    signed as followed, then (lowest modes only) the other lowest modes of
    its last step, from which the next step's LOBPCG starts; None before its
    first step (and for other targets); ``predicted``: the energy change
    the quadratic model predicted for a saddle search's last move (else
    None). ``solver``, the local model at ``last.x``, is not saved: after a
    restart it is built there again if a step taken back needs it.
    """

    gamma: float
    k: int = 0
    v: np.ndarray | None = None
    last: Point | None = None
    pairs: list[tuple[np.ndarray, np.ndarray]] = field(default_factory=list)
    model: dict[str, Any] = field(default_factory=dict)
    solver: Solver | None = None
    #: the pairs as rows (:class:`~ase_maud.optimize.directions.PairRows`; not saved)
    rows: PairRows = field(default_factory=PairRows)
    modes: np.ndarray | None = None
    predicted: float | None = None
    #: energy noise learnt from steps whose energy disagreed with the forces
    #: (:meth:`ase_maud.optimize.strategy.Minimum._change`; relative, not saved)
    noise_seen: float = 0.0
    noise_suspected: float = 0.0
    disagreements: int = 0

    def todict(self) -> dict[str, Any]:
        return {'gamma': self.gamma, 'k': self.k, 'v': self.v,
                'last': None if self.last is None else self.last.todict(),
                'pairs': [list(pair) for pair in self.pairs], 'model': self.model,
                'modes': self.modes, 'predicted': self.predicted}

    @classmethod
    def fromdict(cls, d: dict[str, Any]) -> MaudState:
        return cls(gamma=float(d['gamma']), k=int(d['k']),
                   v=None if d['v'] is None else np.asarray(d['v'], float),
                   last=None if d['last'] is None else Point.fromdict(d['last']),
                   pairs=[(np.asarray(s, float), np.asarray(y, float))
                          for s, y in d['pairs']],
                   model=dict(d['model']),
                   modes=None if d.get('modes') is None else np.asarray(d['modes'], float),
                   predicted=d.get('predicted'))


#: ``local_at(x)``: the local model (a :class:`~ase_maud.optimize.models.base.Solver`)
#: built at positions ``x`` (N, 3), when a step needs it.
LocalAt = Callable[[np.ndarray], Solver]
