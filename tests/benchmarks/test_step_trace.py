"""dev/step_trace.py: the traced run is the package's run, bit for bit,
and its rows and summary count what the run did."""

import runpy

import numpy as np
import pytest

from ase_maud import Maud
from ase_maud.counting import fresh_copy
from ase_maud.scenes.catalogue import build

from helpers import ROOT

TOOL = runpy.run_path(str(ROOT / 'dev' / 'step_trace.py'))


@pytest.mark.parametrize('spec', ['hanging_net:8:3', 'hub_net:6:5'])
def test_the_trace_is_the_untraced_run_and_counts_its_steps(spec):
    rows, summary = TOOL['trace'](spec, 'springs', 1e-4, 500)
    name, size, seed = spec.split(':')
    atoms = fresh_copy(build(name, int(size), seed=int(seed)))
    opt = Maud(atoms, model='springs', logfile=None)
    assert opt.run(fmax=1e-4, steps=500) and summary['converged']
    assert len(rows) == opt.nsteps and summary['calls'] == opt.nsteps + 1
    assert summary['energy'] == atoms.get_potential_energy()   # the same run, bit for bit
    np.testing.assert_array_equal([r['energy'] for r in rows[:3]],
                                  [r['energy'] for r in TOOL['trace'](spec, 'springs', 1e-4,
                                                                      500)[0][:3]])
    assert summary['taken_back'] == sum(not r['accepted'] for r in rows)
    back = sum(summary[f'back {d:g}'] for d in TOOL['DECADES'])
    assert back == summary['taken_back']
    reached = [summary[f'to {d:g}'] for d in TOOL['DECADES']]
    assert reached == sorted(reached) and reached[-1] == len(rows)
    for row in rows:
        assert 0 < row['bound_kept'] <= 1 + 1e-12 and row['pairs'] <= 20
    # a step taken back raised the energy (the direct sum is exact: no noise)
    accepted_energy = rows[0]['energy']
    for row in rows[1:]:
        if row['accepted']:
            accepted_energy = row['energy']
        else:
            assert row['energy'] > accepted_energy - 1e-12 * abs(accepted_energy)
