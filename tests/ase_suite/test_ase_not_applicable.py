"""ASE's optimizer tests that cannot apply to Maud, each with the reason; each
is checked to still exist in the installed ``ase`` (a stale entry fails),
then skipped with its reason. Every other test of ase/test/optimize, and the
constraint, filter and NEB tests that run an optimizer, are run in the
modules beside this one."""

import importlib

import pytest

#: ``module::test`` of ``ase.test`` -> why it cannot apply to Maud.
NOT_APPLICABLE = {
    'optimize.test_fire::test_fire': "FIRE's own keywords (dt, dtmax, downhill_check, "
                                     'position_reset_callback)',
    'optimize.test_fire2::test_fire2': "FIRE2's own keywords (dt, dtmax, use_abc)",
    'optimize.test_maxstep::test_mdmin_maxstep': "MDMin's time step dt",
    'optimize.test_rfo::test_rfo_eigh_fallback': "RFO's fallback when its eigensolver fails",
    'optimize.test_cellawarebfgs::test_cellaware_bfgs': "CellAwareBFGS's cell-aware Hessian",
    'optimize.test_climb_fix_internals::test_climb_fix_internals':
        'BFGSClimbFixInternals, a climbing optimizer of its own',
    'optimize.test_minimahop::test_minimahop': "MinimaHopping's MD (and asap3, not installed)",
    'neb.test_COCu111::test_COCu111': "asserts that the trajectory's description names "
                                      "'BFGS' (test_COCu111_2, the same band, runs)",
}


@pytest.mark.parametrize('name', sorted(NOT_APPLICABLE))
def test_not_applicable(name):
    module, test = name.split('::')
    assert hasattr(importlib.import_module(f'ase.test.{module}'), test), \
        f'{name} is no longer in the installed ase: drop it from NOT_APPLICABLE'
    pytest.skip(NOT_APPLICABLE[name])
