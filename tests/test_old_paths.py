"""ase_maud 0.1's module paths (ase_maud.old_paths): every public name of
0.1 imports from its old path, is the very object of its new home, and the
old path warns once, naming the new one."""

import importlib
import json
import sys
import warnings
from pathlib import Path

import pytest

from ase_maud import old_paths

#: The public names of every module of ase_maud 0.1 (main at ba7ce1a).
NAMES = json.loads((Path(__file__).parent / 'old_public_names.json').read_text())
#: 0.1's command functions of ``ase_maud.cli`` (each took the parsed arguments)
#: whose names are now the modules of the commands, ``ase_maud.cli.relax`` and
#: so on: the one place where an old name means something else.
COMMAND_MODULES = {'relax', 'show', 'classify', 'saddles', 'bench', 'backends'}
#: 0.1's constants of the saddle search's exact release and of the settling
#: of its surroundings, removed in 0.3 with what they tuned (CHANGELOG.md); and
#: classify's bound of the dense lowest eigenpairs, which 'auto' no longer takes.
REMOVED = {'ase_maud.activation': {'RELEASE_CAP_DOFS', 'RELEASE_CAP_STEPS',
                                   'RELEASE_EXACT_MAX_DOFS', 'SETTLE_CYCLES', 'SETTLE_GAIN',
                                   'SETTLE_RATIO', 'SETTLE_STEPS'},
           'ase_maud.analysis': {'LOWEST_MAX_DOFS'},
           'ase_maud.transition': {'BAND_GAMMA_MAX'}}


def _quietly(module: str):
    with warnings.catch_warnings():
        warnings.simplefilter('ignore', FutureWarning)
        return importlib.import_module(module)


@pytest.mark.parametrize('module', sorted(NAMES))
def test_every_public_name_of_0_1_is_its_new_home_s(module):
    old = _quietly(module)
    names = (set(NAMES[module]) - (COMMAND_MODULES if module == 'ase_maud.cli' else set())
             - REMOVED.get(module, set()))
    for name in sorted(names):
        with warnings.catch_warnings():
            warnings.simplefilter('ignore', FutureWarning)
            value = getattr(old, name)
        home, new_name = (old_paths.new_home(module.removeprefix('ase_maud.'), name)
                          if module != 'ase_maud' else (module, name))
        assert value is getattr(_quietly(home), new_name), (module, name)


@pytest.mark.parametrize('old', sorted(set(old_paths.OLD_MODULES) - {
    'physics', 'calculator', 'analysis', 'io', 'scenes', 'cli'}))
def test_a_moved_module_warns_once_naming_its_new_home(old):
    sys.modules.pop(f'ase_maud.{old}', None)
    new = old_paths.OLD_MODULES[old]
    with pytest.warns(FutureWarning, match=f'ase_maud.{old} is now ase_maud.{new}'):
        importlib.import_module(f'ase_maud.{old}')
    with warnings.catch_warnings():
        warnings.simplefilter('error', FutureWarning)
        importlib.import_module(f'ase_maud.{old}')   # imported: no second warning


@pytest.mark.parametrize('package, name, home', [
    ('physics', 'repulsion_block', 'ase_maud.physics.pair_law.repulsion_block'),
    ('analysis', 'Work', 'ase_maud.counting.Work'),
    ('cli', 'describe', 'ase_maud.cli.classify.describe'),
    ('io', 'CALC_NAME', 'ase_maud.calculator.identify.CALC_NAME'),
])
def test_a_module_that_became_a_subpackage_hands_its_old_names_on(package, name, home):
    with pytest.warns(FutureWarning, match=f'ase_maud.{package}.{name} is now {home}'):
        getattr(importlib.import_module(f'ase_maud.{package}'), name)


def test_a_name_0_1_never_had_is_an_attribute_error():
    with pytest.raises(AttributeError, match='no attribute'):
        assert _quietly('ase_maud.stiffness').NoSuchModel
    with pytest.raises(AttributeError, match='no attribute'):
        assert importlib.import_module('ase_maud.bench.runner').no_such_name


@pytest.mark.parametrize('name', ['minimum_proved', 'no_equilibrium', 'unbounded_components'])
def test_the_calculator_s_scene_proofs_of_0_1_are_its_potential_s(name):
    from ase_maud.scenes import build
    atoms = build('ring', 8, seed=3)
    with pytest.warns(FutureWarning, match=f'calc.potential.{name}'):
        method = getattr(atoms.calc, name)
    assert method(atoms) == getattr(atoms.calc.potential, name)(atoms)
    with pytest.raises(AttributeError, match='no attribute'):
        assert atoms.calc.no_such_method
