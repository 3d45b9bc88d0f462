"""Maud: the specification's step ``dr = gamma K^-1 f`` as an ASE optimizer.

``K`` is a stiffness model (:mod:`ase_maud.stiffness`) and the step rule
around it (L-BFGS memory, Day's momentum, restarts, gamma, step bounds) is
:class:`ase_maud.method.MaudMethod`; this module is ASE's plumbing: the
optimizable, the log, the trajectory, the restart file, and the run's safety
checks.

- ``model='auto'`` (default): the whole scene's stiffness: the exact Hessian
  (saddle-free Newton) for small scenes, the sparse global model
  ``P = Q (L (x) I) + blockdiag(|K_mm - Q deg I|)`` with an L-BFGS memory for
  large ones; the specification's nodal blocks (``model='nodal'``, with
  ``method='tensor'`` or ``'scalar'``) and Day's momentum remain as options; a
  calculator with no stiffness gets the secant model ``kappa I``.
- ``target='minimum'`` makes every model positive definite (absolute
  eigenvalues, floored), so no step is meant uphill; ``'stationary'`` keeps the
  signs: saddles and maxima are fixed points too.
- A run never goes on for ever: a 3D scene whose spring graph has a free
  component beside others (no finite minimum) is reported in the log before
  the first step; :class:`DivergenceError` stops a run whose points spread
  beyond ``divergence_factor`` times their start size (or ``a N``), or, on a
  scene known to have no finite minimum, beyond twice their start size; and
  :class:`StagnationError` one whose gamma underflows or that has made no
  progress for ``patience`` steps (neither fmax fell by 0.1 % nor, for
  ``'minimum'``, the energy below its lowest beyond rounding). The
  trajectory written so far stays valid.
"""

from __future__ import annotations

from typing import IO, Any

import numpy as np
from ase import Atoms
from ase.optimize.optimize import DEFAULT_MAX_STEPS, Optimizer

from .method import MaudMethod, StepRule, _Point, merit_tolerance
from .stiffness import METHODS, TARGETS, StiffnessModel, choose_model
from .topology import describe_unbounded


class MaudError(RuntimeError):
    """A run that cannot go on; the message (also in the log) says why."""


class DivergenceError(MaudError):
    """The points flew apart: the scene has no finite stationary point."""


class StagnationError(MaudError):
    """No progress: gamma underflowed or fmax stopped improving."""




class Maud(Optimizer):
    """The Maud optimiser; see the module docstring and docs/optimizer.md.

    Parameters
    ----------
    atoms : Atoms (or anything with ``__ase_optimizable__``)
        The system to relax.
    model : 'auto', 'exact', 'global', 'nodal', 'secant' or a StiffnessModel
        The stiffness ``K`` of the step (default 'auto'; see
        :func:`ase_maud.stiffness.choose_model`).
    method : 'tensor' (default) or 'scalar'
        For ``model='nodal'``: ``K_mm^-1 f_m`` or ``f_m / Tr K_mm``.
    target : 'minimum' (default) or 'stationary'
        Move only downhill, or seek any stationary point.
    gamma : float
        Initial step factor (default 1: the full Newton step of the model).
    gamma_max : float or None
        Largest step factor (default: the model's, 1 for exact and global,
        1.5 for nodal and secant).
    gamma_growth : float
        Factor gamma grows by after each accepted step (default 1.1).
    overshoot_shrink : float
        Factor gamma shrinks by at a kinetic-damping restart (default 0.6).
    beta_max : float or None
        Largest momentum weight, in [0, 1) (default: the model's, 0 for exact
        and global, 0.98 for nodal and secant).
    memory : int or None
        L-BFGS pairs kept over ``K^-1`` (default: the model's, 30 for global,
        0 for the others).
    floor : float or None
        Relative eigenvalue floor of the model (default: the model's, 1e-8
        for exact, 1e-2 for the others).
    maxstep_nn : float
        Largest move of a point in one step, as a fraction of its distance to
        its nearest other point, in (0, 0.5) (default 0.45).
    maxstep : float or None
        Largest move of a point in one step, in length units (default None).
    kappa0 : float
        Initial stiffness of the secant model (default 70, ASE's BFGS initial
        Hessian in eV/A**2).
    divergence_factor : float
        Growth of the scene's size (largest distance from the centroid) over
        its reference, ``max(start size, a N)``, that counts as divergence
        (default 3).
    patience : int
        Steps without progress after which the run stops as stagnant
        (default 2000).
    restart, logfile, trajectory, append_trajectory, **kwargs
        As for every ASE optimizer.
    """

    def __init__(self, atoms: Atoms, restart: str | None = None,
                 logfile: IO | str | None = '-', trajectory: str | None = None,
                 append_trajectory: bool = False,
                 model: str | StiffnessModel = 'auto', method: str = 'tensor',
                 target: str = 'minimum', gamma: float = 1.0,
                 gamma_max: float | None = None, gamma_growth: float = 1.1,
                 beta_max: float | None = None, memory: int | None = None,
                 floor: float | None = None, maxstep_nn: float = 0.45,
                 maxstep: float | None = None, kappa0: float = 70.0,
                 overshoot_shrink: float = 0.6, divergence_factor: float = 3.0,
                 patience: int = 2000, **kwargs: Any):
        if target not in TARGETS:
            raise ValueError(f'target must be one of {TARGETS}, got {target!r}')
        if method not in METHODS:
            raise ValueError(f'method must be one of {METHODS}, got {method!r}')
        if isinstance(model, StiffnessModel):
            self.model = model
        else:
            system = atoms.__ase_optimizable__() if hasattr(
                atoms, '__ase_optimizable__') else atoms
            self.model = choose_model(getattr(system, 'atoms', atoms), model,
                                      target, method=method, floor=floor,
                                      kappa0=kappa0)
        defaults = self.model.step_defaults
        rule = StepRule(
            target=target, gamma=gamma,
            gamma_max=defaults['gamma_max'] if gamma_max is None else gamma_max,
            gamma_growth=gamma_growth, overshoot_shrink=overshoot_shrink,
            beta_max=defaults['beta_max'] if beta_max is None else beta_max,
            memory=defaults['memory'] if memory is None else memory,
            maxstep_nn=maxstep_nn, maxstep=maxstep,
            trust_region=defaults['trust_region'])
        if target == 'stationary':
            rule.memory = 0  # L-BFGS assumes a positive-definite model
        _check_rule(rule)
        if not kappa0 > 0:
            raise ValueError(f'kappa0 must be positive, got {kappa0!r}')
        if not divergence_factor > 1:
            raise ValueError('divergence_factor must exceed 1, got '
                             f'{divergence_factor!r}')
        self.rule = rule
        self.method = method
        self.target = target
        self.divergence_factor = divergence_factor
        self.patience = patience
        super().__init__(atoms, restart, logfile, trajectory,
                         append_trajectory=append_trajectory, **kwargs)
        if self.model.name == 'secant':
            self.logfile.write('Maud: the calculator gives no stiffness; it is '
                               'estimated as kappa I (secant curvature)\n')

    def todict(self) -> dict[str, Any]:
        d = super().todict()
        d.update(model=self.model.name, method=self.method, target=self.target,
                 gamma=self.rule.gamma, gamma_max=self.rule.gamma_max,
                 gamma_growth=self.rule.gamma_growth,
                 overshoot_shrink=self.rule.overshoot_shrink,
                 beta_max=self.rule.beta_max, memory=self.rule.memory,
                 floor=self.model.floor, maxstep_nn=self.rule.maxstep_nn)
        return d

    def initialize(self) -> None:
        self.maud = MaudMethod(self.model, self.rule)
        self.size0 = None       # reference size for the divergence test
        self.unbounded = []     # spring components that make E unbounded
        self.best = (np.inf, 0)  # best fmax so far, and the step it was seen
        self.lowest = (np.inf, 0)  # lowest merit so far ('minimum'), and step

    def read(self) -> None:
        state = self.load()
        self.initialize()
        self.maud.load(state['method'])
        self.size0, self.best = state['size0'], tuple(state['best'])
        self.lowest = tuple(state['lowest'])

    def _dump_state(self) -> None:
        self.dump({'method': self.maud.state(), 'size0': self.size0,
                   'best': list(self.best), 'lowest': list(self.lowest)})

    # -- the step ---------------------------------------------------------------

    def _atoms(self) -> Atoms | None:
        """The Atoms behind the optimizable, or None (a filter, say)."""
        return getattr(self.optimizable, 'atoms', None)

    def _evaluate(self) -> None:
        """One calculator call for the energy, the forces and what the model
        needs (the nodal blocks, say), computed together."""
        atoms = self._atoms()
        if atoms is not None and (prop := self.model.needs(atoms)) is not None:
            atoms.calc.get_property(prop, atoms)

    def _merit(self, forces: np.ndarray) -> float:
        if self.target == 'minimum':
            return self.optimizable.get_value()
        return float(np.vdot(forces, forces))

    def step(self) -> None:
        opt = self.optimizable
        x = opt.get_x().reshape(-1, 3)
        forces = -opt.get_gradient().reshape(-1, 3)
        merit = self._merit(forces)
        maud = self.maud
        if maud.uphill(x, merit, forces):
            here = maud.revert()
            if here.solver is None:  # resumed from a restart file
                opt.set_x(here.x.ravel())
                here.solver = self.model.at(self._atoms())
        else:
            maud.accept(x, forces)
            here = _Point(x.copy(), merit, forces.copy(), self.model.at(self._atoms()))
        self._check_progress(here.x, here.merit, here.forces)
        move = maud.move(here)
        opt.set_x((here.x + move).ravel())
        maud.moved(opt.get_x().reshape(-1, 3))
        self._dump_state()
        self._evaluate()

    def irun(self, fmax: float = 0.05, steps: int = DEFAULT_MAX_STEPS):
        self._preflight()
        return super().irun(fmax, steps)

    def run(self, fmax: float = 0.05, steps: int = DEFAULT_MAX_STEPS) -> bool:
        self._preflight()
        return super().run(fmax, steps)

    def _preflight(self) -> None:
        """Say in the log if the scene has no finite minimum; evaluate."""
        atoms = self._atoms()
        calc = getattr(atoms, 'calc', None)
        if hasattr(calc, 'unbounded_components') and self.target == 'minimum':
            self.unbounded = calc.unbounded_components(atoms)
            if self.unbounded:
                self.logfile.write('Maud: warning: '
                                   f'{describe_unbounded(self.unbounded)}\n')
        self._evaluate()

    def _stop(self, error: type[MaudError], message: str) -> None:
        self.logfile.write(f'Maud: stopped: {message}\n')
        raise error(message)

    def _check_progress(self, x, merit, forces):
        """Raise DivergenceError or StagnationError; see the module docstring."""
        size = np.linalg.norm(x - x.mean(axis=0), axis=1).max()
        if self.size0 is None:
            a = getattr(getattr(self._atoms(), 'calc', None), 'length_scale', 0.0)
            reference = size if self.unbounded else max(size, a * len(x))
            self.size0 = max(reference, np.finfo(float).tiny)
        factor = 2.0 if self.unbounded else self.divergence_factor
        if size > factor * self.size0:
            why = (describe_unbounded(self.unbounded) if self.unbounded
                   else 'no stationary point in reach')
            self._stop(DivergenceError,
                       f'diverged at step {self.nsteps}: the points spread to '
                       f'{size:.3g}, {size / self.size0:.3g} times their '
                       f'reference size {self.size0:.3g}; {why}')
        fmax = np.linalg.norm(forces, axis=1).max()
        if fmax < (1 - 1e-3) * self.best[0]:
            self.best = (fmax, self.nsteps)
        if (self.target == 'minimum'
                and merit < self.lowest[0] - merit_tolerance(merit)):
            self.lowest = (merit, self.nsteps)
        if self.nsteps - max(self.best[1], self.lowest[1]) > self.patience:
            self._stop(StagnationError,
                       f'stagnant at step {self.nsteps}: no progress for '
                       f'{self.patience} steps (fmax {fmax:.3g}, best '
                       f'{self.best[0]:.3g}{self._lowest_text()}; a requested '
                       'fmax below the rounding noise of the forces, or an '
                       'oscillation)')
        if self.maud.gamma < 1e-12 * self.rule.gamma:
            self._stop(StagnationError,
                       f'stagnant at step {self.nsteps}: gamma fell to '
                       f'{self.maud.gamma:.3g}; every step raised the '
                       f'{"energy" if self.target == "minimum" else "|f|^2"}'
                       ' (energy and forces may disagree)')

    def _lowest_text(self):
        if self.target != 'minimum':
            return ''
        return f', energy {self.lowest[0]:.12g} lowest since step {self.lowest[1]}'


def _check_rule(rule: StepRule) -> None:
    """Raise ValueError naming the first step-rule keyword out of range."""
    checks = (
        ('gamma', rule.gamma, rule.gamma > 0, 'a positive number'),
        ('gamma_max', rule.gamma_max, rule.gamma_max > 0, 'a positive number'),
        ('gamma_growth', rule.gamma_growth, rule.gamma_growth >= 1, 'a number >= 1'),
        ('overshoot_shrink', rule.overshoot_shrink, 0 < rule.overshoot_shrink <= 1,
         'in (0, 1]'),
        ('beta_max', rule.beta_max, 0 <= rule.beta_max < 1, 'in [0, 1)'),
        ('memory', rule.memory, isinstance(rule.memory, (int, np.integer))
         and rule.memory >= 0, 'a whole number >= 0'),
        ('maxstep_nn', rule.maxstep_nn, 0 < rule.maxstep_nn < 0.5,
         'in (0, 0.5) (at 0.5 two points could meet)'),
        ('maxstep', rule.maxstep, rule.maxstep is None or rule.maxstep > 0,
         'None or a positive length'),
    )
    for name, value, ok, what in checks:
        if not ok:
            raise ValueError(f'{name} must be {what}, got {value!r}')
