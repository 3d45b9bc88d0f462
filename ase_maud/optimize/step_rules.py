"""The step rule of a run: its parameters and their defaults per model and
target (:data:`STEP_DEFAULTS`), in one place.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from ase_maud.optimize.models.base import StiffnessModel
from ase_maud.optimize.models.exact import ExactModel
from ase_maud.optimize.models.global_model import GlobalModel
from ase_maud.optimize.models.nodal import NodalModel
from ase_maud.optimize.models.secant import BFGSModel, SecantModel
from ase_maud.optimize.models.springs import SpringsModel

#: The step rule's defaults: ``'common'`` for every model, then each model's
#: own (by its class; a model not listed takes :class:`NodalModel`'s), chosen
#: by measurement (docs/optimizer.md). The Newton-like models take gamma = 1
#: with no momentum: the exact one with no memory and a trust-region bound;
#: the global and springs ones with an L-BFGS memory over their ``P`` and the
#: whole move scaled by one factor (the springs one by the scene's size only,
#: gamma back to 1 after every accepted step and a cubic cut on a rise, as a
#: line search; on a net held in a plane its memory forgets a pair once the
#: points have moved one ``a`` since: ``memory_reach``, in units of ``a``).
#: The nodal and secant models keep Day's momentum, as the specification has
#: it; the bfgs model (a secant ``kappa I`` with a long memory, for
#: calculators with forces only) takes no momentum, 100 pairs, and the step
#: of ASE's BFGS: the whole move scaled by one factor so that no point moves
#: more than 0.2 (A; nor the common 0.45 of its nearest-neighbour distance,
#: on atoms), gamma back to 1 after every accepted step and, on a rise, the
#: pair of the step taken back learnt and the model's new move cut to the
#: cubic cut's length; chosen by measurement on ASE's systems
#: (docs/dev/benchmarks.md).
STEP_DEFAULTS: dict[Any, dict[str, Any]] = {
    'common': {'gamma': 1.0, 'gamma_growth': 1.1, 'overshoot_shrink': 0.6,
               'maxstep_nn': 0.45, 'maxstep': None, 'maxstep_size': None,
               'trust_region': False, 'interpolate': False, 'bound': 'each',
               'learn_rises': False, 'memory_reach': None},
    ExactModel: {'gamma_max': 1.0, 'beta_max': 0.0, 'memory': 0, 'trust_region': True,
                 'gamma_growth': 2.0},
    GlobalModel: {'gamma_max': 1.0, 'beta_max': 0.0, 'memory': 30, 'bound': 'whole'},
    NodalModel: {'gamma_max': 1.5, 'beta_max': 0.98, 'memory': 0},
    SecantModel: {'gamma_max': 1.5, 'beta_max': 0.98, 'memory': 0},
    BFGSModel: {'gamma_max': 1.0, 'beta_max': 0.0, 'memory': 100, 'maxstep': 0.2,
                'bound': 'whole', 'gamma_growth': 1e3, 'interpolate': True,
                'learn_rises': True},
    SpringsModel: {'gamma_max': 1.0, 'beta_max': 0.0, 'memory': 20, 'maxstep_nn': None,
                   'maxstep_size': 1.0, 'bound': 'whole', 'gamma_growth': 1e3,
                   'interpolate': True, 'memory_reach': 1.0},
}


#: A saddle search at less than this fraction of its trust length from the
#: minimum along a followed mode climbs that mode the way it is followed.
CLIMB_SIDE = 1e-3


#: Eigenpairs beyond the followed modes that a large saddle search computes
#: (LOBPCG) and steps along one by one: the next lowest, negative or soft,
#: which the truncated Newton move off them would otherwise meet (chosen by
#: measurement, docs/optimizer.md; one rather than three: LOBPCG's block of
#: two converges in far fewer products, docs/dev/bench/saddles.md).
LOWEST_MODES = 1


@dataclass(frozen=True)
class StepRule:
    """The step rule's settings (see the module docstring); made by
    :func:`step_rule`."""

    gamma: float
    gamma_max: float
    gamma_growth: float
    overshoot_shrink: float
    beta_max: float
    memory: int
    maxstep_nn: float | None
    maxstep: float | None
    maxstep_size: float | None
    trust_region: bool
    interpolate: bool
    bound: str
    learn_rises: bool
    #: The L-BFGS memory forgets a pair once the points have moved this far
    #: since it was taken (:func:`~ase_maud.optimize.directions.within_reach`;
    #: a length once :func:`~ase_maud.optimize.run_setup.memory_reach` has
    #: scaled the default by the scene's ``a``); None: kept while it fits.
    memory_reach: float | None
    #: Points per image when the positions are a chain of images (ASE's NEB):
    #: the nearest other point is sought within the same image only (the same
    #: atom in the next image is not a neighbour). None: one scene.
    image_size: int | None = None
    #: ``target='saddle'``: the negative curvatures sought (modes followed uphill).
    order: int = 0

    def todict(self) -> dict[str, Any]:
        """The user's settings, as an optimizer's ``todict`` gives them (the
        order of a saddle search too)."""
        return {**({'order': self.order} if self.order else {}),
                **{name: getattr(self, name) for name in (
                    'gamma', 'gamma_max', 'gamma_growth', 'overshoot_shrink', 'beta_max',
                    'memory', 'maxstep_nn')}}

    @property
    def gamma0(self) -> float:
        """The step factor a run starts from (the reference of the monitor's
        test of a vanishing step)."""
        return min(self.gamma, self.gamma_max)


def defaults(model: StiffnessModel) -> dict[str, Any]:
    """:data:`STEP_DEFAULTS`' common row, then the row of ``model``'s class
    (or of the nearest listed class it derives from; else
    :class:`NodalModel`'s)."""
    row = next((STEP_DEFAULTS[kind] for kind in type(model).__mro__
                if kind in STEP_DEFAULTS), STEP_DEFAULTS[NodalModel])
    return {**STEP_DEFAULTS['common'], **row}


def step_rule(model: StiffnessModel, image_size: int | None = None,
              **keywords: Any) -> StepRule:
    """The step rule of ``model``: its :func:`defaults`, then the
    ``keywords`` that are not None (the user's; already checked). For
    ``target='stationary'`` and ``'saddle'`` the memory is 0 (L-BFGS assumes
    a positive-definite model); ``order`` is a saddle search's only."""
    settings = defaults(model)
    settings.update({name: value for name, value in keywords.items()
                     if value is not None})
    if model.target in ('stationary', 'saddle'):
        settings['memory'] = 0
    if model.target != 'saddle':
        settings['order'] = 0   # no mode is followed uphill
    if model.target == 'saddle' and settings['maxstep_nn'] is None:
        settings['maxstep_nn'] = STEP_DEFAULTS['common']['maxstep_nn']
    return StepRule(image_size=image_size, **settings)
