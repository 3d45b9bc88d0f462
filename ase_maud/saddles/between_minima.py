"""The saddle between two minima: a band of images relaxed loosely as a
preconditioned string with a climbing image, its highest image refined to a
verified index-1 saddle.

:func:`saddle_between` joins two minima of one scene (a MaudCalculator scene
each: the same points, springs and constraints) by a band of ``images``
moving images (interpolated linearly or by ASE's ``'idpp'``), relaxed as a
string preconditioned by each image's stiffness model
(:class:`~ase_maud.saddles.string_method.PreconditionedString`) until the
band's largest residual force is below ``band_fmax`` (a band need not be
converged: it only has to bring its highest image near the saddle), first
without and then with a climbing image. The highest moving image is then
refined by ``Maud(target='saddle', mode=tangent)``, the tangent being the
band's chord through that image's two neighbours, to ``fmax``; the optimizer
verifies the point it converges on from the Hessian (index 1, no zero
curvature), or raises :class:`~ase_maud.errors.WrongIndexError`. The saddle
is the band's if its barrier is within :data:`AGREE` of the highest image's.
Should the refinement fail or reach another saddle, the higher neighbour of
the highest image is refined in turn (the barrier lies between the two);
should that fail too, the band is relaxed on to a tenth of its force and the
two refinements tried again, at most :data:`RETRIES` times. A
:class:`Transition` reports the saddle, both barriers, the climbing
image's energy and what the search computed: calculator calls of the band
(summed over its moving images) and of the refinement, Hessian-vector
product vectors and Hessians (each one force-call equivalent, as
:class:`~ase_maud.counting.Work` counts them), and CPU seconds.

Where a scene's second minimum is the first one's mirror image (a net with
its whole rim fixed buckles into a dome, up or down), :func:`mirrored` makes
it: the free points reflected through the plane fitted to the fixed ones,
then relaxed.
"""

from __future__ import annotations

from contextlib import ExitStack
from dataclasses import dataclass, field

import numpy as np
from ase import Atoms
from ase.mep import NEB

from ase_maud.calculator.maud_calculator import MaudCalculator
from ase_maud.checks import check_all
from ase_maud.counting import CallRecorder, Work, cpu_seconds, fresh_copy
from ase_maud.errors import MaudError
from ase_maud.optimize.maud import Maud
from ase_maud.physics.dofs import free_dofs, held_in_a_plane
from ase_maud.saddles.string_method import PreconditionedString

#: The largest residual force of a relaxed band (``band_fmax``), in units of ``Q a``.
BAND_FMAX = 0.1
#: A refined saddle's barrier within this fraction of the band's highest
#: image's is the band's saddle (measured with the NEB the string replaced:
#: within 0.9 % on 400-point domes, 4.2 % on 8x8, a refinement that led
#: elsewhere 26-49 % apart; with the string within 3 % on the 400-point domes:
#: docs/dev/bench/saddles.md).
AGREE = 0.05
#: The interpolated images' free coordinates are moved by up to this many
#: ``a`` (seeded): between two mirror images the band is nearly symmetric,
#: and its middle image would stay on the mirror plane, at the flat
#: stationary point of many negative curvatures (400-point dome, seed 2).
JITTER = 0.05
#: Times the band is relaxed on (to a tenth of its force each time) after
#: refinements that failed.
RETRIES = 2


@dataclass
class Transition:
    """What :func:`saddle_between` found: the verified index-1 ``saddle``
    (Atoms with its own calculator; None if none was reached, ``outcome``
    then says why), the relaxed ``band`` (its images, ends included), the
    ``barriers`` (the saddle's energy above the first and the second minimum,
    energy units), the energy of the band's highest image (``climbing``,
    above the first minimum), the calculator calls of the band (summed over
    its moving images) and of the refinement, the Hessian-vector product
    vectors and Hessians (``work``), the band's steps and CPU seconds.
    ``elsewhere``: the verified index-1 saddles a refinement reached that
    are not the band's (their barrier more than :data:`AGREE` from its
    highest image's), in the order reached: saddles of the scene, not
    known to lie between the two minima.

    Parameters
    ----------
    saddle : Atoms or None
        The verified index-1 saddle, or None (``outcome`` says why).
    band : list of Atoms
        The relaxed band, ends included.
    outcome : str
        How the search ended, in words.
    elsewhere : list of Atoms
        Verified saddles a refinement reached that are not the band's.
    barriers : (float, float)
        The saddle's energy above the first and the second minimum, ``Q a^2``.
    climbing : float
        The band's highest image above the first minimum, ``Q a^2``.
    band_calls, band_steps, saddle_calls : int
        Calls and steps of the band, calls of the refinement.
    work : Work
        Hessian-vector product vectors and Hessians.
    cpu_s : float
        CPU seconds.
    """

    saddle: Atoms | None
    band: list[Atoms]
    outcome: str = ''
    elsewhere: list[Atoms] = field(default_factory=list)
    barriers: tuple[float, float] = (float('nan'), float('nan'))
    climbing: float = float('nan')
    band_calls: int = 0
    band_steps: int = 0
    saddle_calls: int = 0
    work: Work = field(default_factory=Work)
    cpu_s: float = 0.0

    @property
    def calls(self) -> int:
        """Calculator calls of the band and of the refinement."""
        return self.band_calls + self.saddle_calls

    @property
    def cost(self) -> int:
        """Calls, Hessian-vector product vectors and Hessians: force-call
        equivalents."""
        return self.calls + self.work.total

    def describe(self) -> str:
        """One line: how it ended, the barrier and what it cost.

        Returns
        -------
        str
            The outcome or the barrier (``Q a^2``), then the calls, products,
            Hessians, their sum in force-call equivalents and the CPU seconds.

        Raises
        ------
        None
            It reads the record only.
        """
        found = (f'saddle {self.barriers[0]:.6g} above the first minimum (climbing image '
                 f'{self.climbing:.6g})' if self.saddle is not None else self.outcome)
        return (f'{found}: {self.band_calls} band calls ({self.band_steps} steps) + '
                f'{self.saddle_calls} calls + {self.work.hvp_vectors} HVP vectors + '
                f'{self.work.hessians} Hessians = {self.cost}, {self.cpu_s:.2f} CPU s')


def saddle_between(first: Atoms, second: Atoms, images: int = 7,
                   band_fmax: float | None = None,
                   fmax: float = 1e-6, steps: int = 200, band_steps: int = 2000,
                   interpolation: str = 'linear', seed: int = 0,
                   any_saddle: bool = False) -> Transition:
    """The :class:`Transition` between the minima ``first`` and ``second``
    (module docstring): a band of ``images`` moving images interpolated by
    ``interpolation`` ('linear' or ASE's 'idpp'), their free coordinates
    moved by up to :data:`JITTER` ``a`` (seeded by ``seed``), relaxed as a
    string without and then with a climbing image until its largest
    residual force is below ``band_fmax`` (force units; None:
    :data:`BAND_FMAX` ``Q a``; at most ``band_steps`` steps each time), then
    its highest image (else its higher neighbour) refined to ``fmax`` in at
    most ``steps`` steps each. With
    ``any_saddle`` the first verified saddle a refinement reaches ends the
    search even if it is not the band's (it is then in ``elsewhere``): what
    a saddle search wants, where the band would be relaxed on only to reach
    this path's own saddle. Neither minimum is changed. A ValueError names a
    bad argument, or what the two scenes do not share.

    Parameters
    ----------
    first, second : Atoms
        Two minima of one scene (same points, springs, ``a``, ``Q``, ``dim``,
        constraints), each with a :class:`~ase_maud.MaudCalculator`.
    images : int, default 7
        Moving images of the band.
    band_fmax : float or None, default None
        The band's convergence (its largest residual force), ``Q a`` (None:
        :data:`BAND_FMAX` ``Q a``).
    fmax : float, default 1e-6
        The refined saddle's convergence, ``Q a``.
    steps : int, default 200
        Steps of the refinement.
    band_steps : int, default 2000
        Steps of each of the band's two relaxations.
    interpolation : {'linear', 'idpp'}, default 'linear'
        The band's first images.
    seed : int, default 0
        The seed of the images' jitter (up to :data:`JITTER` ``a``).
    any_saddle : bool, default False
        Stop at the first verified index-1 saddle a refinement reaches,
        the band's or another.

    Returns
    -------
    Transition
        The verified saddle (or None and why), the band, the barriers
        (``Q a^2``) and the cost.

    Raises
    ------
    ValueError
        An argument outside its rule, or two scenes that differ (what they
        do not share is named).
    """
    checked = check_all(fmax=fmax, steps=steps)
    fmax, steps = checked['fmax'], checked['steps']
    if not (isinstance(images, int) and images >= 1):
        raise ValueError(f'images must be a whole number >= 1, got {images!r}')
    check_same_scene(first, second)
    potential = first.calc.potential
    band_fmax = BAND_FMAX * potential.force_unit if band_fmax is None else band_fmax
    if not (isinstance(band_fmax, (int, float)) and np.isfinite(band_fmax) and band_fmax > 0):
        raise ValueError(f'band_fmax must be a finite number > 0, got {band_fmax!r}')
    if not (isinstance(band_steps, int) and band_steps >= 1):
        raise ValueError(f'band_steps must be a whole number >= 1, got {band_steps!r}')
    if interpolation not in ('linear', 'idpp'):
        raise ValueError(f"interpolation must be 'linear' or 'idpp', got {interpolation!r}")
    cpu = cpu_seconds()
    band = [fresh_copy(first), *(fresh_copy(first) for _ in range(images)), fresh_copy(second)]
    NEB(band, method='improvedtangent').interpolate(method=interpolation)
    _jitter(band[1:-1], JITTER * potential.a, seed)
    found = Transition(None, band)
    string = PreconditionedString(band)
    with ExitStack() as stack:
        recorders = [stack.enter_context(CallRecorder(image.calc)) for image in band]
        # an image climbs only once the band is near its path
        found.outcome = _relax_band(string, band_fmax, band_steps, False)
        target = band_fmax
        for _ in range(RETRIES + 1 if not found.outcome else 0):
            found.outcome = _relax_band(string, target, band_steps, True)
            if found.outcome:
                break
            for image in _candidates(band):
                saddle, found.outcome = _refine(band, image, fmax, steps, found)
                if saddle is None:
                    continue
                found.outcome = _apart(band, saddle, first)
                if not found.outcome:
                    found.saddle = saddle
                    energy = saddle.get_potential_energy()
                    found.barriers = (energy - first.get_potential_energy(),
                                      energy - second.get_potential_energy())
                    break
                found.elsewhere.append(saddle)
                if any_saddle:
                    break
            if found.saddle is not None or (any_saddle and found.elsewhere):
                break
            target *= 0.1
        found.band_calls = sum(len(r.samples) for r in recorders)
        found.band_steps = string.steps
    found.climbing = max(image.get_potential_energy() for image in band[1:-1]) - (
        first.get_potential_energy())
    found.cpu_s = cpu_seconds() - cpu
    return found


def mirrored(minimum: Atoms, fmax: float = 1e-6, steps: int = 5000) -> Atoms:
    """The mirror image of ``minimum`` (:func:`reflection`) relaxed by Maud to
    ``fmax`` in at most ``steps`` steps. A ValueError if the fixed points do
    not span a plane, or the relaxation does not converge.

    Parameters
    ----------
    minimum : Atoms
        A minimum with a :class:`~ase_maud.MaudCalculator` and at least three
        fixed points not on one line.
    fmax : float, default 1e-6
        The relaxation's convergence, ``Q a``.
    steps : int, default 5000
        Its most steps.

    Returns
    -------
    Atoms
        The relaxed mirror image, with its own calculator.

    Raises
    ------
    ValueError
        The fixed points span no plane, or the relaxation did not converge.
    MaudError
        The relaxation could not go on (see :meth:`ase_maud.Maud.run`).
    """
    image = reflection(minimum)
    if not Maud(image, logfile=None).run(fmax=fmax, steps=steps):
        raise ValueError(f'the mirror image did not relax to fmax {fmax:g} in {steps} steps')
    return image


def reflection(minimum: Atoms) -> Atoms:
    """A copy of ``minimum`` (a MaudCalculator scene with at least three
    fixed points not on one line: a net with its rim fixed, say) with its own
    calculator, its free points reflected through the plane fitted (least
    squares) to the fixed points; not relaxed. A ValueError if the fixed
    points do not span a plane.

    Parameters
    ----------
    minimum : Atoms
        A scene with a :class:`~ase_maud.MaudCalculator` and at least three
        fixed points not on one line.

    Returns
    -------
    Atoms
        The reflected copy, with its own calculator.

    Raises
    ------
    ValueError
        Fewer than three fixed points, or all on one line.
    """
    fixed = ~free_dofs(minimum, 3).any(axis=1)
    rim = minimum.positions[fixed]
    if not held_in_a_plane(minimum):
        raise ValueError(f'a mirror image needs at least three fixed points not on one line '
                         f'to fit a plane to; this scene has {len(rim)} fixed points'
                         f'{"" if len(rim) < 3 else ", all on one line"}')
    centre = rim.mean(axis=0)
    normal = np.linalg.svd(rim - centre)[2][2]
    image = fresh_copy(minimum)
    positions = image.positions.copy()
    height = (positions[~fixed] - centre) @ normal
    positions[~fixed] -= 2 * height[:, None] * normal
    image.positions = positions
    return image


def _jitter(images: list[Atoms], amplitude: float, seed: int) -> None:
    """Move every free coordinate of each of ``images`` by up to
    ``amplitude`` (uniform, seeded by ``seed``)."""
    rng = np.random.default_rng(seed)
    for image in images:
        free = free_dofs(image, image.calc.dim)
        move = np.zeros_like(image.positions)
        move[:, :free.shape[1]] = rng.uniform(-amplitude, amplitude, free.shape) * free
        image.positions = image.positions + move


def check_same_scene(first: Atoms, second: Atoms) -> None:
    """A ValueError unless the two minima a band would join are
    MaudCalculator scenes of the same points, springs and fixed coordinates
    (:func:`saddle_between` asks it first, and a saddle search given a
    partner before its climbs)."""
    for name, atoms in (('first', first), ('second', second)):
        if not isinstance(atoms.calc, MaudCalculator):
            raise ValueError(f'the {name} minimum has no MaudCalculator '
                             f'(it has {type(atoms.calc).__name__})')
    if len(first) != len(second):
        raise ValueError(f'the minima have {len(first)} and {len(second)} '
                         'points: a band joins two configurations of one scene')
    springs = [np.asarray(a.calc.parameters.get('springs', ())) for a in (first, second)]
    if springs[0].shape != springs[1].shape or not np.array_equal(*springs):
        raise ValueError('the minima have different springs: a band '
                         'joins two configurations of one scene')
    held = [~free_dofs(a, a.calc.dim) for a in (first, second)]
    if not np.array_equal(*held):
        raise ValueError('the minima hold different coordinates fixed')
    dim = held[0].shape[1]
    differ = first.positions[:, :dim][held[0]] != second.positions[:, :dim][held[0]]
    if differ.any():
        point = np.argwhere(held[0])[np.flatnonzero(differ)[0]][0]
        raise ValueError(f'a fixed coordinate differs between the minima '
                         f'(near point {point})')


def _relax_band(string: PreconditionedString, target: float, steps: int, climb: bool) -> str:
    """Relax ``string`` until its largest residual force is below ``target``
    (at most ``steps`` steps; with a climbing image if ``climb``); '' if it
    got there, else why not."""
    try:
        if string.relax(target, steps, climb):
            return ''
        return (f'the band did not relax to fmax {target:.3g} in {steps} steps '
                f'(its largest residual force {string.residual:.3g})')
    except MaudError as error:
        return f'the band stopped: {type(error).__name__}: {str(error).splitlines()[0]}'


def _apart(band: list[Atoms], saddle: Atoms, first: Atoms) -> str:
    """'' if the energy of ``saddle`` is within :data:`AGREE` of the barrier
    of the highest moving image of ``band`` (both above ``first``), else
    that they differ: the refinement went to another saddle than the band's."""
    e0 = first.get_potential_energy()
    top = max(image.get_potential_energy() for image in band[1:-1]) - e0
    barrier = saddle.get_potential_energy() - e0
    if abs(barrier - top) <= AGREE * abs(top):
        return ''
    return (f'the refinement reached a saddle {barrier:.6g} above the first minimum, the '
            f'band\'s highest image is {top:.6g}: another saddle than the band\'s')


def _candidates(band: list[Atoms]) -> list[int]:
    """The moving images a refinement starts from, in turn: the highest, then
    the higher of its neighbours if that one moves (the band's barrier lies
    between the two)."""
    energies = [image.get_potential_energy() for image in band]
    top = 1 + int(np.argmax(energies[1:-1]))
    side = max((top - 1, top + 1), key=lambda k: energies[k])
    return [top] if side in (0, len(band) - 1) else [top, side]


def _refine(band: list[Atoms], top: int, fmax: float, steps: int,
            found: Transition) -> tuple[Atoms | None, str]:
    """The moving image ``top`` of ``band`` refined by a saddle search along
    the band's chord through it; (the saddle, '') or (None, why not). Its
    calls and work are added to ``found``."""
    tangent = band[top + 1].positions - band[top - 1].positions
    saddle = fresh_copy(band[top])
    opt = Maud(saddle, target='saddle', mode=tangent, logfile=None)
    with CallRecorder(saddle.calc) as calls:
        try:
            done = opt.run(fmax=fmax, steps=steps)
            why = '' if done else f'the refinement did not converge in {steps} steps'
        except MaudError as error:
            why = f'the refinement stopped: {type(error).__name__}: {str(error).splitlines()[0]}'
    found.saddle_calls += len(calls.samples)
    found.work.hvp_vectors += opt.work.hvp_vectors
    found.work.hessians += opt.work.hessians
    return (None, why) if why else (saddle, '')
