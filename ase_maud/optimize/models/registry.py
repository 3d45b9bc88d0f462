"""The stiffness models by name (:data:`MODELS`) and the choice of one for a
scene (:func:`choose_model`): what ``Maud(model=...)`` and ``ase-maud
--model`` resolve. The models themselves are :mod:`ase_maud.optimize.models.base`'s and
:mod:`ase_maud.optimize.models.near`'s.
"""

from __future__ import annotations

from typing import Any

from ase import Atoms

from ase_maud.calculator.identify import potential_of, scene_dim
from ase_maud.checks import check
from ase_maud.optimize.models.base import StiffnessModel
from ase_maud.optimize.models.exact import EXACT_MAX_DOFS, ExactModel
from ase_maud.optimize.models.global_model import GlobalModel
from ase_maud.optimize.models.near import NearModel
from ase_maud.optimize.models.nodal import NodalModel
from ase_maud.optimize.models.secant import BFGSModel, SecantModel
from ase_maud.optimize.models.springs import SpringsModel
from ase_maud.physics.dofs import PROJECTIONS, free_dofs
from ase_maud.physics.neighbours import NearestDistances

#: The models by name.
MODELS: dict[str, type[StiffnessModel]] = {
    cls.name: cls for cls in (SecantModel, BFGSModel, NodalModel, GlobalModel,
                              ExactModel, SpringsModel, NearModel)}


def choose_model(atoms: Atoms, name: str = 'auto', target: str = 'minimum',
                 nearest: NearestDistances | None = None,
                 **options: Any) -> StiffnessModel:
    """The stiffness model ``name`` for ``atoms``' calculator.

    ``target='saddle'`` takes ``exact``, or ``springs`` above
    :data:`EXACT_MAX_DOFS` (ValueError if ``name`` is another model).
    ``'auto'``: ``exact`` while the free degrees of freedom are at most
    :data:`EXACT_MAX_DOFS`, the calculator has a ``hessian`` and every
    constraint is one of :data:`PROJECTIONS` (a Hookean tether, say, adds
    stiffness the Hessian does not hold); else ``springs`` if it has a
    ``potential`` (a :class:`~ase_maud.calculator.potential.MaudPotential`); else
    ``nodal`` if it has the nodal blocks; else ``bfgs`` for a minimum,
    ``secant`` for another target (a band of images). ``options`` go to
    the model (``floor``; ``method`` for nodal; ``kappa0`` for secant), and
    each is checked there; an option the chosen model does not take is
    checked here and dropped. ``nearest`` is shared with a model that ages
    with the positions.
    """
    calc = getattr(atoms, 'calc', None)
    offers = set(getattr(calc, 'implemented_properties', ()))
    if target == 'saddle':
        name = _saddle_model(atoms, name, offers)
    if name == 'auto':
        dim = scene_dim(atoms)
        if ('hessian' in offers and free_dofs(atoms, dim).sum() <= EXACT_MAX_DOFS
                and all(isinstance(c, PROJECTIONS) for c in atoms.constraints)):
            name = 'exact'
        elif potential_of(atoms) is not None:
            name = 'springs'
        elif 'stiffness' in offers:
            name = 'nodal'
        else:   # a minimum: a memory (its pairs assume a gradient); else momentum
            name = 'bfgs' if target == 'minimum' else 'secant'
    if not (isinstance(name, str) and name in MODELS):
        raise ValueError(f"model must be 'auto', one of {sorted(MODELS)} or a "
                         f'StiffnessModel, got {name!r}')
    cls = MODELS[name]
    if cls.prop is not None and cls.prop not in offers:
        raise ValueError(f'model={name!r} needs a calculator with the property '
                         f'{cls.prop!r} (such as MaudCalculator); this one '
                         f'offers {sorted(offers)}')
    if name in ('springs', 'near', 'global') and potential_of(atoms) is None:
        raise ValueError(f"model={name!r} needs a calculator with springs and the "
                         'repulsion (a MaudCalculator: its potential); this one is a '
                         f"{type(calc).__name__}: use model='auto', 'bfgs' or 'secant'")
    taken = {'floor', *_EXTRA_OPTIONS.get(cls, ())}
    for option in set(options) - taken:
        check(option, options[option])
    if issubclass(cls, (GlobalModel, SpringsModel)):
        options['nearest'] = nearest
        taken.add('nearest')
    return cls(target=target, **{k: v for k, v in options.items() if k in taken})


def _saddle_model(atoms: Atoms | None, name: Any, offers: set[str]) -> str:
    """The model of ``target='saddle'``: ``exact`` (all the Hessian's
    eigenpairs) up to :data:`EXACT_MAX_DOFS` free degrees of freedom,
    ``springs`` (the lowest eigenpairs from Hessian-vector products) above,
    or ``name`` if it is one of these; a ValueError for another model, a
    calculator that has neither the Hessian nor a potential, or a band of
    images."""
    if name not in ('auto', 'exact', 'springs'):
        raise ValueError(f"target='saddle' needs model='exact' or 'springs' (or 'auto'), "
                         f'got model={name!r}')
    if not ('hessian' in offers and potential_of(atoms) is not None):
        raise ValueError("target='saddle' needs one scene whose calculator gives the "
                         'Hessian and its products (such as MaudCalculator)')
    if name != 'auto':
        return name
    dim = scene_dim(atoms)
    return 'exact' if free_dofs(atoms, dim).sum() <= EXACT_MAX_DOFS else 'springs'


#: Options beyond ``target`` and ``floor`` that a model takes.
_EXTRA_OPTIONS = {NodalModel: ('method',), SecantModel: ('kappa0',),
                  BFGSModel: ('kappa0',)}
