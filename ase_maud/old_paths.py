"""The module paths of ase_maud 0.1, working for one more release.

ase_maud 0.2 put its modules in subpackages by layer (``ase_maud.optimize``,
``ase_maud.saddles``, ...). A module path of 0.1 (``ase_maud.stiffness``,
``ase_maud.results``, ...) still imports: :class:`OldPathFinder` gives a thin
module that hands each name on from its new home, with a ``FutureWarning``
naming that home once per path; a 0.1 module whose name is now a subpackage
(``ase_maud.physics``, ``ase_maud.io``, ...) hands its old names on through
the subpackage's ``__getattr__`` (:func:`old_names`). The public names of the
top level (``ase_maud.Maud``, ...) never moved. Remove this module in 0.3.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import types
import warnings
from collections.abc import Callable
from typing import Any

#: A 0.1 module (below ``ase_maud.``) and its new home.
OLD_MODULES = {
    'accuracy': 'calculator.accuracy',
    'activation': 'saddles.search',
    'analysis': 'analysis.stationary',
    'arrays': 'optimize.array_loop',
    'assembly': 'optimize.run_setup',
    'atomic': 'files.atomic_replace',
    'calculator': 'calculator.maud_calculator',
    'cli': 'cli.command',
    'descent': 'optimize.directions',
    'dofs': 'physics.dofs',
    'evaluation': 'optimize.evaluation',
    'forcedensity': 'form.force_density',
    'formats': 'io.net_data',
    'formats.compas': 'io.compas',
    'formats.mesh': 'io.mesh',
    'formats.obj': 'io.obj',
    'formats.tables': 'io.tables',
    'formats.text': 'io.text',
    'hardcases': 'scenes.hard_cases',
    'io': 'io.nets',
    'landscape': 'saddles.landscape',
    'lock': 'files.run_lock',
    'models': 'optimize.models.registry',
    'modes': 'analysis.modes',
    'monitor': 'optimize.monitor',
    'nearfield': 'optimize.models.near',
    'neighbours': 'physics.neighbours',
    'optimizer': 'optimize.maud',
    'paths': 'files.output_paths',
    'physics': 'physics.pair_law',
    'pictures': 'form.pictures',
    'potential': 'calculator.potential',
    'precon': 'optimize.precon',
    'restart': 'optimize.restart_file',
    'results': 'form.member_forces',
    'resuming': 'optimize.resume',
    'run_files': 'optimize.run_files',
    'scenes': 'scenes.builders',
    'search': 'optimize.step_length',
    'springs': 'physics.spring_list',
    'stiffness': 'optimize.models.base',
    'strategy': 'optimize.strategy',
    'subset': 'optimize.subset',
    'topology': 'physics.topology',
    'trajectory': 'files.trajectory',
    'transition': 'saddles.between_minima',
}
#: The 0.1 packages among them (their modules are in :data:`OLD_MODULES`).
OLD_PACKAGES = {'formats'}
#: Names carried out of a 0.1 module to another home (``module:new_name`` where
#: renamed).
CARRIED = {
    'accuracy': {
        'noise': 'calculator.accuracy:force_noise',
    },
    'activation': {
        'Attempt': 'saddles.attempts',
        'GROWTH': 'saddles.attempts',
        'RADIUS': 'saddles.attempts',
        'REGION_STEPS': 'saddles.attempts',
        'SAME_DIRECTION': 'saddles.attempts',
    },
    'analysis': {
        'Work': 'counting',
    },
    'bench.runner': {
        'CallRecorder': 'counting',
        'classify': 'bench.runner:run_status',
        'fresh_copy': 'counting',
    },
    'calculator': {
        'CLOSEST_REDUCED_DISTANCE': 'physics.pair_law',
        'PLANE_TOLERANCE': 'calculator.potential',
        'raise_on_closest': 'physics.pair_law',
    },
    'cli': {
        'backends': 'cli.bench:backends_command',
        'bench': 'cli.bench:bench_command',
        'check_outputs': 'cli.options',
        'classify': 'cli.classify:classify_command',
        'describe': 'cli.classify',
        'relax': 'cli.relax:relax_command',
        'saddles': 'cli.saddles:saddles_command',
        'show': 'cli.show:show_command',
    },
    'formats.obj': {
        'MERGE_TOLERANCE': 'io.net_data',
        'merge_coincident': 'io.net_data',
    },
    'forcedensity': {
        'unsupported': 'physics.topology',
    },
    'io': {
        'A_PER_MEAN_SPRING': 'physics.topology',
        'default_a': 'physics.topology',
        'write_net': 'io.net_writer',
        'CALC_NAME': 'calculator.identify',
        'stored_parameters': 'calculator.identify',
    },
    'lock': {
        'FileInUseError': 'errors',
    },
    'monitor': {
        'DivergenceError': 'errors',
        'MaudError': 'errors',
        'NoEquilibriumError': 'errors',
        'StagnationError': 'errors',
        'WrongIndexError': 'errors',
    },
    'restart': {
        'RestartFileError': 'errors',
    },
    'resuming': {
        'Resumable': 'optimize.maud:Maud',
    },
    'scenes': {
        'COLLECTIVE': 'scenes.catalogue',
        'LARGE': 'scenes.catalogue',
        'SCENES': 'scenes.catalogue',
        'SUITE': 'scenes.catalogue',
        'SUITES': 'scenes.catalogue',
        'build': 'scenes.catalogue',
        'scene_sizes': 'scenes.catalogue',
    },
    'stiffness': {
        'AMG_MIN_DOFS': 'optimize.models.sparse',
        'BFGSModel': 'optimize.models.secant',
        'DENSE_GRAPH_FRACTION': 'optimize.models.global_model',
        'DENSE_MIN_DOFS': 'optimize.models.global_model',
        'EXACT_MAX_DOFS': 'optimize.models.exact',
        'ExactModel': 'optimize.models.exact',
        'GlobalModel': 'optimize.models.global_model',
        'MODES_MAXITER': 'optimize.models.springs',
        'MODES_RTOL': 'optimize.models.springs',
        'MODES_WARM_MAXITER': 'optimize.models.springs',
        'NodalModel': 'optimize.models.nodal',
        'SOLVE_RTOL': 'optimize.models.sparse',
        'SPRINGS_RTOL': 'optimize.models.springs',
        'SecantModel': 'optimize.models.secant',
        'SpringsModel': 'optimize.models.springs',
        'spd_inverse': 'optimize.models.sparse',
    },
    'strategy': {
        'CLIMB_SIDE': 'optimize.step_rules',
        'LOWEST_MODES': 'optimize.step_rules',
        'LocalAt': 'optimize.state',
        'MaudState': 'optimize.state',
        'Point': 'optimize.state',
        'STEP_DEFAULTS': 'optimize.step_rules',
        'StepRule': 'optimize.step_rules',
        'defaults': 'optimize.step_rules',
        'step_rule': 'optimize.step_rules',
    },
}


def new_home(old: str, name: str) -> tuple[str, str]:
    """The module and name that ``name`` of the 0.1 module ``old`` (below
    ``ase_maud.``) has now."""
    home = CARRIED.get(old, {}).get(name, OLD_MODULES.get(old, old))
    module, _, new_name = home.partition(':')
    return f'ase_maud.{module}', new_name or name


def _warn(old: str, name: str | None = None) -> None:
    """The FutureWarning of the 0.1 path ``ase_maud.old`` (``.name``)."""
    if name is None:
        what, now = f'ase_maud.{old}', f'ase_maud.{OLD_MODULES[old]}'
    else:
        module, new_name = new_home(old, name)
        what, now = f'ase_maud.{old}.{name}', f'{module}.{new_name}'
    warnings.warn(f'{what} is now {now}: the old path works until ase_maud 0.3',
                  FutureWarning, stacklevel=3)


def old_names(old: str, warn: bool = True) -> Callable[[str], Any]:
    """A module ``__getattr__`` handing on the names of the 0.1 module ``old``
    (below ``ase_maud.``) from their new homes, with a FutureWarning if
    ``warn``."""
    def __getattr__(name: str) -> Any:
        module, new_name = new_home(old, name)
        if (module, new_name) == (f'ase_maud.{old}', name):   # a module that stayed
            raise AttributeError(f'module ase_maud.{old} has no attribute {name!r}')
        try:
            value = getattr(importlib.import_module(module), new_name)
        except AttributeError:
            raise AttributeError(f'module ase_maud.{old} has no attribute {name!r}') from None
        if warn:
            _warn(old, name)
        return value
    return __getattr__


class OldPathFinder(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Finds the 0.1 module paths that are no module now, as thin modules
    (:func:`old_names`)."""

    def find_spec(self, fullname: str, path: Any, target: Any = None) -> Any:
        old = fullname.removeprefix('ase_maud.')
        if not fullname.startswith('ase_maud.') or old not in OLD_MODULES:
            return None
        return importlib.util.spec_from_loader(fullname, self,
                                               is_package=old in OLD_PACKAGES)

    def create_module(self, spec: Any) -> types.ModuleType:
        return types.ModuleType(spec.name, f'Moved to ase_maud.{OLD_MODULES[spec.name[9:]]}.')

    def exec_module(self, module: types.ModuleType) -> None:
        old = module.__name__[9:]
        _warn(old)
        module.__getattr__ = old_names(old, warn=False)
