"""Maud: nodal-Newton dynamic relaxation (the tensor and scalar Maud steps).

Each point m moves by its own out-of-balance force divided by its own
stiffness, every other point held fixed (the specification's step, with ASE's
force sign ``f = -dE/dr``)::

    tensor:  dr_m = gamma * K_mm^-1 f_m
    scalar:  dr_m = gamma * f_m / Tr(K_mm)

and, after Day's dynamic relaxation, the previous move is carried over with a
damping weight: ``v <- beta * v + dr; r <- r + v``. The rules that make this a
robust optimiser (chosen on the scene suite, see docs/optimizer.md):

- ``target='minimum'``: each block is replaced by its absolute value
  ``V |Lambda| V^T`` (eigenvalues floored at ``floor * max|lambda|``), so no
  point steps uphill along a negative principal direction and a singular block
  (a point with no spring in 3D has ``Tr K_mm = 0``) stays invertible.
  ``target='stationary'`` keeps the signs: the plain Newton-like step of the
  specification, which can converge on saddles and maxima.
- Kinetic-damping restarts: the carried velocity is dropped when it points
  against the new Maud direction (``v . K^-1 f < 0``; with the absolute-value
  blocks of ``'minimum'`` this is FIRE's and Barnes's ``v . f < 0`` measured
  in the nodal metric),
  and gamma shrinks by ``overshoot_shrink``: an overshoot means the step was
  too long (the two-point problem, for one, needs gamma = 1/2).
- A step that raises the merit (the energy for ``'minimum'``, ``|f|**2`` for
  ``'stationary'``) is taken back at no extra force call: the optimiser returns
  to the previous point, whose forces it kept, halves gamma and restarts.
  Gamma grows by ``gamma_growth`` after each accepted step, up to ``gamma_max``.
- The momentum weight grows with the steps since the last restart,
  ``beta_k = min(k / (k + 3), beta_max)`` (Nesterov's schedule).
- No point moves further in one step than ``maxstep_nn`` (< 1/2) times its
  distance to its nearest other point (nor than ``maxstep`` if given): two
  points stepping towards each other keep at least ``1 - 2 maxstep_nn`` of
  their distance, so no step can make two points meet.
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

import numpy as np
from ase.optimize.optimize import DEFAULT_MAX_STEPS, Optimizer
from scipy.spatial import cKDTree

from .topology import describe_unbounded, unbounded_components

class MaudError(RuntimeError):
    """A run that cannot go on; the message (also in the log) says why."""


class DivergenceError(MaudError):
    """The points flew apart: the scene has no finite stationary point."""


class StagnationError(MaudError):
    """No progress: gamma underflowed or fmax stopped improving."""


_METHODS = ('tensor', 'scalar')
_TARGETS = ('minimum', 'stationary')


class Maud(Optimizer):
    """The Maud optimiser; see the module docstring for the step rules.

    Parameters
    ----------
    atoms : Atoms (or anything with ``__ase_optimizable__``)
        The system to relax. Its calculator should offer the ``stiffness``
        property (as :class:`ase_maud.MaudCalculator` does); otherwise the
        nodal blocks are estimated as ``kappa I`` with ``kappa`` the secant
        (Barzilai-Borwein) curvature ``s.y / s.s`` of the last step, starting
        from ``kappa0``, and the log says so once.
    method : 'tensor' (default) or 'scalar'
        ``K_mm^-1 f_m`` or ``f_m / Tr K_mm``.
    target : 'minimum' (default) or 'stationary'
        Move only downhill, or seek any stationary point (see above).
    gamma : float
        Initial step factor (default 1: the full nodal Newton step).
    gamma_max : float
        Largest step factor gamma may grow to (default 1.5).
    gamma_growth : float
        Factor gamma grows by after each accepted step (default 1.1).
    overshoot_shrink : float
        Factor gamma shrinks by at a kinetic-damping restart (default 0.6).
    beta_max : float
        Largest momentum weight (default 0.98).
    floor : float
        Relative eigenvalue floor of a nodal block (default 1e-2).
    maxstep_nn : float
        Largest move of a point in one step, as a fraction of its distance to
        its nearest other point, in (0, 0.5) (default 0.45: a distance keeps
        at least a tenth of itself per step).
    maxstep : float or None
        Largest move of a point in one step, in length units (default None:
        only ``maxstep_nn`` applies).
    kappa0 : float
        Initial stiffness estimate when the calculator has no ``stiffness``
        (default 70, ASE's BFGS initial Hessian in eV/A**2).
    divergence_factor : float
        Growth of the scene's size (largest distance from the centroid) over
        its reference, ``max(start size, a N)``, that counts as divergence
        (default 3: a relaxed scene is smaller than ``a N``; a free chain's
        half-length is about 0.85 a N at N = 100, a ring's radius 0.3 a N).
        Free components in 2D drift apart ever more slowly (force ~ 1/L**2),
        so the steps to reach the limit grow as its cube.
    patience : int
        Steps without progress (fmax down by 0.1 %, or for ``'minimum'`` a new
        lowest energy) after which the run stops as stagnant (default 2000).
    restart, logfile, trajectory, append_trajectory, **kwargs
        As for every ASE optimizer.
    """

    def __init__(self, atoms, restart=None, logfile='-', trajectory=None,
                 append_trajectory=False, method='tensor', target='minimum',
                 gamma=1.0, gamma_max=1.5, gamma_growth=1.1, beta_max=0.98,
                 floor=1e-2, maxstep_nn=0.45, maxstep=None, kappa0=70.0,
                 overshoot_shrink=0.6, divergence_factor=3.0, patience=2000,
                 **kwargs):
        if method not in _METHODS:
            raise ValueError(f'method must be one of {_METHODS}, got {method!r}')
        if target not in _TARGETS:
            raise ValueError(f'target must be one of {_TARGETS}, got {target!r}')
        for name, value in (('gamma', gamma), ('gamma_max', gamma_max),
                            ('floor', floor), ('maxstep_nn', maxstep_nn),
                            ('kappa0', kappa0)):
            if not value > 0:
                raise ValueError(f'{name} must be positive, got {value!r}')
        if not divergence_factor > 1:
            raise ValueError('divergence_factor must exceed 1, got '
                             f'{divergence_factor!r}')
        if not maxstep_nn < 0.5:
            raise ValueError('maxstep_nn must be below 0.5 (two points could '
                             f'meet), got {maxstep_nn!r}')
        if not 0 <= beta_max < 1:
            raise ValueError(f'beta_max must be in [0, 1), got {beta_max!r}')
        if not 0 < overshoot_shrink <= 1:
            raise ValueError('overshoot_shrink must be in (0, 1], got '
                             f'{overshoot_shrink!r}')
        if gamma_growth < 1:
            raise ValueError(f'gamma_growth must be >= 1, got {gamma_growth!r}')
        self.method = method
        self.target = target
        self.gamma0 = gamma
        self.gamma_max = gamma_max
        self.gamma_growth = gamma_growth
        self.overshoot_shrink = overshoot_shrink
        self.beta_max = beta_max
        self.floor = floor
        self.maxstep_nn = maxstep_nn
        self.maxstep = maxstep
        self.kappa0 = kappa0
        self.divergence_factor = divergence_factor
        self.patience = patience
        super().__init__(atoms, restart, logfile, trajectory,
                         append_trajectory=append_trajectory, **kwargs)
        self._said_estimate = False

    def todict(self):
        d = super().todict()
        d.update(method=self.method, target=self.target, gamma=self.gamma0,
                 gamma_max=self.gamma_max, gamma_growth=self.gamma_growth,
                 overshoot_shrink=self.overshoot_shrink,
                 beta_max=self.beta_max, floor=self.floor,
                 maxstep_nn=self.maxstep_nn)
        return d

    def initialize(self):
        self.v = None           # last move, (N, 3)
        self.gamma = self.gamma0
        self.k = 0              # accepted steps since the last restart
        self.kappa = self.kappa0
        self.last = None        # x, merit, forces, blocks where the last step began
        self.size0 = None       # reference size for the divergence test
        self.unbounded = []     # spring components that make E unbounded
        self.best = (np.inf, 0)  # best fmax so far, and the step it was seen
        self.lowest = (np.inf, 0)  # lowest merit so far ('minimum'), and step

    def read(self):
        state = self.load()
        self.initialize()
        self.gamma, self.k, self.kappa = state['gamma'], state['k'], state['kappa']
        self.size0, self.best = state['size0'], tuple(state['best'])
        self.lowest = tuple(state['lowest'])
        if state['v'] is not None:
            self.v = np.asarray(state['v'], dtype=float)
        if state['last'] is not None:
            self.last = {key: value if key == 'merit' or value is None
                         else np.asarray(value, dtype=float)
                         for key, value in state['last'].items()}

    def _dump_state(self):
        self.dump({'gamma': self.gamma, 'k': self.k, 'kappa': self.kappa,
                   'v': self.v, 'last': self.last, 'size0': self.size0,
                   'best': list(self.best), 'lowest': list(self.lowest)})

    # -- the pieces of a step -------------------------------------------------

    def _atoms(self):
        """The Atoms behind the optimizable, or None (a filter, say)."""
        return getattr(self.optimizable, 'atoms', None)

    def _stiffness(self):
        """Nodal blocks (N, d, d) from the calculator, or None."""
        atoms = self._atoms()
        calc = getattr(atoms, 'calc', None)
        if calc is None or 'stiffness' not in calc.implemented_properties:
            if not self._said_estimate:
                self.logfile.write(
                    'Maud: the calculator gives no stiffness; nodal blocks '
                    'are estimated as kappa I (secant curvature)\n')
                self._said_estimate = True
            return None
        return calc.get_property('stiffness', atoms)

    def _merit(self, forces):
        if self.target == 'minimum':
            return self.optimizable.get_value()
        return float(np.vdot(forces, forces))

    def _direction(self, forces, blocks):
        """The Maud direction ``K_mm^-1 f_m`` (or ``f_m / Tr``) per point."""
        if blocks is None:
            return forces / self.kappa
        d = blocks.shape[-1]
        tiny = np.finfo(float).tiny
        f = forces[:, :d]
        step = np.zeros_like(forces)
        lam, vec = np.linalg.eigh(blocks)
        size = np.abs(lam)
        floor = np.maximum(self.floor * size.max(axis=1), tiny)
        if self.method == 'scalar':
            trace = size.sum(axis=1) if self.target == 'minimum' else lam.sum(axis=1)
            trace = np.where(trace < 0, -1.0, 1.0) * np.maximum(np.abs(trace), floor)
            step[:, :d] = f / trace[:, None]
            return step
        safe = np.maximum(size, floor[:, None])
        if self.target == 'stationary':
            safe *= np.where(lam < 0, -1.0, 1.0)
        proj = np.einsum('nij,ni->nj', vec, f) / safe
        step[:, :d] = np.einsum('nij,nj->ni', vec, proj)
        return step

    def _bound(self, step, x):
        """Scale each point's move down to its allowed length."""
        length = np.linalg.norm(step, axis=1)
        limit = np.full(len(x), np.inf)
        if len(x) > 1:
            nn = cKDTree(x).query(x, k=2)[0][:, 1]
            limit = self.maxstep_nn * nn
        if self.maxstep is not None:
            limit = np.minimum(limit, self.maxstep)
        scale = np.divide(limit, length, out=np.ones_like(length),
                          where=length > limit)
        return step * scale[:, None]

    def step(self):
        opt = self.optimizable
        x = opt.get_x().reshape(-1, 3)
        forces = -opt.get_gradient().reshape(-1, 3)
        blocks = self._stiffness()
        merit = self._merit(forces)

        last = self.last
        if last is not None and self._uphill(last, x, merit, forces):
            # Uphill: go back to where the last step began, gently.
            x, merit = last['x'], last['merit']
            forces, blocks = last['forces'], last['blocks']
            self.gamma *= 0.5
            self.v = None
            self.k = 0
        elif last is not None:
            if blocks is None:
                self._update_kappa(x, forces)
            self.gamma = min(self.gamma * self.gamma_growth, self.gamma_max)
        self._check_progress(x, merit, forces)
        direction = self._direction(forces, blocks)
        if self.v is not None and np.vdot(self.v, direction) < 0:
            # Overshoot: kinetic-damping restart, and a smaller gamma.
            self.gamma *= self.overshoot_shrink
            self.v = None
            self.k = 0
        direction *= self.gamma
        if self.v is not None:
            beta = min(self.k / (self.k + 3.0), self.beta_max)
            direction += beta * self.v
        self.k += 1
        move = self._bound(direction, x)
        self.last = {'x': x.copy(), 'merit': merit, 'forces': forces.copy(),
                     'blocks': blocks}
        opt.set_x((x + move).ravel())
        self.v = opt.get_x().reshape(-1, 3) - x   # the move constraints allowed
        self._dump_state()
        self._stiffness()   # blocks, energy and forces in one calculator call

    # Both check the scene first and ask for the blocks, so that the
    # calculator computes them together with the first forces, in one call.
    def irun(self, fmax=0.05, steps=DEFAULT_MAX_STEPS):
        self._preflight()
        return super().irun(fmax, steps)

    def run(self, fmax=0.05, steps=DEFAULT_MAX_STEPS):
        self._preflight()
        return super().run(fmax, steps)

    def _preflight(self):
        """Say in the log if the scene has no finite minimum; get blocks."""
        atoms = self._atoms()
        calc = getattr(atoms, 'calc', None)
        springs = getattr(calc, 'springs', None)
        if springs is not None and self.target == 'minimum':
            self.unbounded = unbounded_components(
                atoms, springs, calc.parameters.get('dim', 3))
            if self.unbounded:
                self.logfile.write('Maud: warning: '
                                   f'{describe_unbounded(self.unbounded)}\n')
        self._stiffness()

    def _stop(self, error, message):
        self.logfile.write(f'Maud: stopped: {message}\n')
        raise error(message)

    def _uphill(self, last, x, merit, forces):
        """Whether the step from ``last`` raised the merit.

        Energies that agree within rounding (:func:`_merit_tol`) are told
        apart by the trapezoid estimate ``-(f_last + f) . dx / 2`` of the
        energy change, which has no cancellation error.
        """
        change, tol = merit - last['merit'], _merit_tol(last['merit'])
        if self.target != 'minimum' or abs(change) > tol:
            return change > tol
        return -0.5 * np.vdot(last['forces'] + forces, x - last['x']) > 0

    def _check_progress(self, x, merit, forces):
        """Raise DivergenceError or StagnationError; see the module docstring."""
        size = np.linalg.norm(x - x.mean(axis=0), axis=1).max()
        if self.size0 is None:
            calc = getattr(self._atoms(), 'calc', None)
            a = getattr(calc, 'parameters', {}).get('a', 0.0)
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
                and merit < self.lowest[0] - _merit_tol(merit)):
            self.lowest = (merit, self.nsteps)
        if self.nsteps - max(self.best[1], self.lowest[1]) > self.patience:
            self._stop(StagnationError,
                       f'stagnant at step {self.nsteps}: no progress for '
                       f'{self.patience} steps (fmax {fmax:.3g}, best '
                       f'{self.best[0]:.3g}{self._lowest_text()}; a requested '
                       'fmax below the rounding noise of the forces, or an '
                       'oscillation)')
        if self.gamma < 1e-12 * self.gamma0:
            self._stop(StagnationError,
                       f'stagnant at step {self.nsteps}: gamma fell to '
                       f'{self.gamma:.3g}; every step raised the '
                       f'{"energy" if self.target == "minimum" else "|f|^2"}'
                       ' (energy and forces may disagree)')

    def _lowest_text(self):
        if self.target != 'minimum':
            return ''
        return f', energy {self.lowest[0]:.12g} lowest since step {self.lowest[1]}'

    def _update_kappa(self, x, forces):
        """Secant curvature of the last step, for calculators with no blocks."""
        s = (x - self.last['x']).ravel()
        y = (self.last['forces'] - forces).ravel()
        sy, ss = np.vdot(s, y), np.vdot(s, s)
        if sy > 0 and ss > 0:
            self.kappa = sy / ss


def _merit_tol(merit):
    """Rounding slack when comparing merits (energies sum N**2 terms)."""
    return 1e-12 * max(abs(merit), 1e-300)
