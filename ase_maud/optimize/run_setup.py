"""What a Maud run is made of: what the model sees of the system, the local
model, the target, the step rule and the strategy, decided once, in one
place, when the optimizer is made.

The system is an ASE ``Atoms`` (or anything with ``__ase_optimizable__``):
the model sees the atoms themselves; behind a ``Filter`` (a subset of the
atoms) the whole scene with the atoms left out held
(:class:`~ase_maud.optimize.subset.SubsetView`); for a band of images (ASE's NEB)
the band, whose forces are not the gradient of its energy, so the target is
``'stationary'`` unless one is given; for a cell filter nothing (its rows are
not points: they get ASE's usual ``maxstep`` instead of the
nearest-neighbour bound, and no spread is watched).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from ase import Atoms
from ase.calculators.singlepoint import SinglePointCalculator
from ase.filters import Filter, StrainFilter, UnitCellFilter

from ase_maud.calculator import accuracy
from ase_maud.calculator.identify import potential_of
from ase_maud.calculator.maud_calculator import MaudCalculator
from ase_maud.checks import check
from ase_maud.optimize.models.base import StiffnessModel
from ase_maud.optimize.models.registry import choose_model
from ase_maud.optimize.models.secant import SecantModel
from ase_maud.optimize.step_rules import STEP_DEFAULTS, StepRule, step_rule
from ase_maud.optimize.strategy import Strategy, compose
from ase_maud.optimize.subset import SubsetView
from ase_maud.physics.dofs import PROJECTIONS, free_dofs, held_in_a_plane
from ase_maud.physics.neighbours import NearestDistances

#: The longest move of a row of a cell filter's coordinates when ``maxstep``
#: is not given (ASE's BFGS default).
CELL_MAXSTEP = 0.2


@dataclass(frozen=True)
class Assembly:
    """A run's parts: the local ``model``, the ``strategy`` over it, the
    ``subset`` view behind a Filter (or None), whether the coordinates are
    ``points`` (their spread is watched), and the ``notes`` for the run's
    log (lines: a target chosen for a band of images, a model learnt from
    the forces)."""

    model: StiffnessModel
    strategy: Strategy
    subset: SubsetView | None
    points: bool
    notes: tuple[str, ...]


def _check_cell_filter(atoms: Any) -> None:
    """A ValueError, before any step, for a cell filter (ASE's UnitCellFilter,
    FrechetCellFilter, StrainFilter) whose calculator gives no stress, as
    BFGS says at its first step (Maud would first meet the zero cell of a
    scene without one: a singular matrix)."""

    if not isinstance(atoms, (UnitCellFilter, StrainFilter)):
        return
    calc = getattr(atoms.atoms, 'calc', None)
    offers = getattr(calc, 'implemented_properties', ('stress',))
    if calc is not None and 'stress' not in offers:
        raise ValueError(f'{type(atoms).__name__}: stress property not implemented by the '
                         f'calculator ({type(calc).__name__}): a cell filter relaxes the '
                         'cell by the stress; relax the atoms alone (no filter)')


def assemble(atoms: Any, model: str | StiffnessModel, target: str | None,
             steps: dict[str, Any], order: int, mode: Any,
             **options: Any) -> Assembly:
    """The :class:`Assembly` of a run on ``atoms`` (module docstring):
    ``model`` a name (:func:`~ase_maud.optimize.models.registry.choose_model`, with
    ``options``: ``method``, ``floor``, ``kappa0``) or a model; ``steps`` the
    user's step keywords (checked), ``order`` and ``mode`` a saddle search's."""
    system = atoms.__ase_optimizable__() if hasattr(
        atoms, '__ase_optimizable__') else atoms
    _check_cell_filter(atoms)
    subset = SubsetView(atoms) if type(atoms) is Filter else None
    images = image_size(system)
    scene = (subset.current() if subset is not None
             else getattr(system, 'atoms', None if images is None else atoms))
    chosen = target is None and not isinstance(model, StiffnessModel)
    struts = compressed(scene)
    if chosen:   # NEB forces are not the gradient of its energy
        target = 'minimum' if images is None and not len(struts) else 'stationary'
    elif len(struts) and (target or getattr(model, 'target', None)) == 'minimum':
        raise ValueError(f'{_STRUTS.format(len(struts))}: it has no minimum to find, '
                         "target='minimum' cannot be met; use target='stationary' (an "
                         'equilibrium) or, at a = 0, solve_force_density')
    nearest = NearestDistances(images) if subset is None else subset.nearest()
    if isinstance(model, StiffnessModel):
        if target is not None and check('target', target) != model.target:
            raise ValueError(f'target={target!r} differs from the target of the '
                             f'model given ({model.target!r}): leave target out')
    else:
        model = choose_model(scene, model, target, nearest=nearest, **options)
    if model.target == 'saddle':
        check_free(scene)
    rule = rule_for(model, scene, images, steps, order)
    notes = ((["Maud: target='stationary' (the forces of a band of images are not the "
               'gradient of its energy)\n'] if chosen and images is not None else [])
             + ([f"Maud: target='stationary': {_STRUTS.format(len(struts))}; the point "
                 'found is an equilibrium (a stationary point), not a minimum\n']
                if chosen and len(struts) else [])
             + ([f'Maud: the calculator gives no stiffness; it is learnt from the forces '
                 f'({model.name} model)\n'] if isinstance(model, SecantModel) else []))
    points = None if scene is None else len(scene) if subset is None else len(subset.index)
    learns_noise = not accuracy.is_aware(getattr(scene, 'calc', None))
    return Assembly(model, compose(model, rule, nearest, check_mode(mode, points),
                                   quadratic=_quadratic(scene), learns_noise=learns_noise),
                    subset, scene is not None, tuple(notes))


#: What members in compression do to the energy (:func:`compressed`).
_STRUTS = ('the net has {} members in compression (q < 0): its energy is no longer '
           'convex and is unbounded below')


def compressed(scene) -> np.ndarray:
    """The springs of ``scene``'s MaudPotential with ``q < 0`` (none for
    anything else)."""
    potential = potential_of(scene)
    return np.zeros(0, dtype=int) if potential is None else potential.compressed


def _quadratic(scene: Any):
    """Whether ``scene``'s energy is now quadratic (a MaudCalculator without
    repulsion, ``a = 0``: springs and constant loads), asked at each step
    (``calc.set(a=...)`` may change it); None for a scene of other atoms."""
    if scene is None:
        return None

    def quadratic() -> bool:
        potential = potential_of(scene)
        return potential is not None and potential.a == 0
    return quadratic


def check_calculator(scene: Atoms | None) -> None:
    """A ValueError unless the Atoms ``scene`` (None: a band of images or a
    cell filter, not checked here) has a calculator that computes forces
    at new positions, and one the atoms fit: a MaudCalculator checks them
    (:meth:`~ase_maud.calculator.maud_calculator.MaudCalculator.check_atoms`: a spring to an
    atom deleted since, say, is named)."""
    if not isinstance(scene, Atoms):
        return
    calc = scene.calc
    fix = ('attach one that computes forces (atoms.calc = MaudCalculator(springs), '
           'or read a net with ase_maud.io.nets.read_net)')
    if calc is None:
        raise ValueError(f'the atoms have no calculator: Maud needs forces; {fix}')
    if isinstance(calc, SinglePointCalculator):
        raise ValueError('the atoms\' calculator is a SinglePointCalculator (results '
                         'read from a file, as ase.io.read gives): it computes no '
                         f'forces at new positions; {fix}')
    if isinstance(calc, MaudCalculator):
        calc.check_atoms(scene)


def check_free(scene: Atoms | None) -> None:
    """A ValueError if FixAtoms and FixCartesian hold every coordinate of
    the Atoms ``scene`` (a saddle search has nothing to climb along)."""
    if not isinstance(scene, Atoms) or not len(scene):
        return
    dim = scene.calc.dim if isinstance(scene.calc, MaudCalculator) else 3
    if not free_dofs(scene, dim).any():
        raise ValueError(f"target='saddle' with every coordinate of the {len(scene)} "
                         'atoms held by a constraint: nothing is free to climb '
                         'along; free some atoms')


def check_mode(mode: Any, points: int | None) -> int | np.ndarray | None:
    """``mode`` (see :class:`Maud`) checked: None, a whole number >= 0, or a
    finite move of the N ``points`` the run moves (a Filter's atoms, else
    the scene's; None: no scene), shape (N, 3) or (3 N,)."""
    if mode is None:
        return None
    if isinstance(mode, (int, np.integer)) and not isinstance(mode, bool):
        if mode < 0:
            raise ValueError(f'mode must be an index >= 0 of the Hessian\'s modes, '
                             f'got {mode!r}')
        return int(mode)
    n = points or 0
    try:
        move = np.asarray(mode, dtype=float)
    except (TypeError, ValueError):
        move = None
    if move is None or move.size != 3 * n or not np.isfinite(move).all():
        raise ValueError(f'mode must be None, an index of the Hessian\'s modes or a '
                         f'finite move of the {n} points, shape ({n}, 3); got {mode!r}')
    return move.reshape(n, 3)


def rule_for(model: StiffnessModel, scene: Atoms | None, images: int | None,
             steps: dict[str, Any], order: int | None = None) -> StepRule:
    """The step rule of ``model`` (:func:`~ase_maud.optimize.step_rules.step_rule`, with
    the user's ``steps`` and the saddle ``order``) for what the model sees: a
    cell filter's coordinates (``scene`` None) get ASE's usual ``maxstep``
    instead of the nearest-neighbour bound; atoms under constraints ASE adjusts
    every move for (SHAKE for a bond length, which fails on a move long against
    the distances between points) keep the nearest-neighbour bound in every
    model. A ``memory_reach`` becomes a length (:func:`memory_reach`)."""
    rule = step_rule(model, images, order=order, **steps)
    if rule.memory_reach is not None:
        rule = replace(rule, memory_reach=memory_reach(rule.memory_reach, scene))
    if scene is None:
        return replace(rule, maxstep_nn=None, maxstep=rule.maxstep or CELL_MAXSTEP)
    if rule.maxstep_nn is None and not all(isinstance(c, PROJECTIONS)
                                           for c in getattr(scene, 'constraints', ())):
        return replace(rule, maxstep_nn=STEP_DEFAULTS['common']['maxstep_nn'])
    return rule


def memory_reach(reach: float, scene: Any) -> float | None:
    """The length ``reach`` times ``a`` of ``scene``'s MaudCalculator where
    the scene has repulsion (``a > 0``) and is held in a plane
    (:func:`~ase_maud.physics.dofs.held_in_a_plane`: a net on its supports);
    None elsewhere. A held net takes its large-scale stiffness from its
    springs and supports, which ``P`` has; its memory learns the near
    repulsion, whose curvature changes as the net takes its shape. A free
    scene, or one hanging from a point (a tree from its root), unfolds under
    the repulsion, and its memory learns the repulsion's large-scale
    stiffness too, which ages slowly: forgetting it took more calls
    (docs/optimizer.md)."""
    calc = getattr(scene, 'calc', None)
    if (not isinstance(calc, MaudCalculator) or not calc.potential.a
            or not held_in_a_plane(scene)):
        return None
    return reach * calc.potential.a


def image_size(system: Any) -> int | None:
    """Points per image if ``system`` optimizes a band of images (ASE's
    NEB optimizable, which has ``neb``), else None."""
    neb = getattr(system, 'neb', None)
    return None if neb is None else len(neb.images[0])
