"""dev/family_trace.py: the traced run is the package's run, bit for bit, and
the Hessian blocks it prints are the dense Hessian's."""

import csv
import runpy

import numpy as np
import pytest

from ase_maud import Maud
from ase_maud.scenes.families import FAMILIES

from helpers import ROOT

TOOL = runpy.run_path(str(ROOT / 'dev' / 'family_trace.py'))


@pytest.mark.parametrize('family, seed', [('saddle_dome', 3), ('sagging_net', 4)])
def test_the_trace_is_the_untraced_run(tmp_path, family, seed):
    out = tmp_path / 'trace.csv'
    TOOL['main'](['--family', family, '--seed', str(seed), '--sizes', '40', '80',
                  '--out', str(out)])
    rows = list(csv.DictReader(out.open()))
    atoms = FAMILIES[family](seed, (40, 80))
    opt = Maud(atoms, logfile=None)
    assert opt.run(fmax=1e-4)
    assert len(rows) == opt.nsteps + 1   # the start and every step
    assert rows[-1]['energy'] == f'{atoms.get_potential_energy():.6f}'
    forces = np.linalg.norm(atoms.get_forces(), axis=1)
    assert float(rows[-1]['fmax']) == pytest.approx(forces.max(), rel=1e-3)
    assert 1 <= float(rows[-1]['participation']) <= len(atoms)
    with pytest.raises(SystemExit):   # an existing file is never replaced
        TOOL['main'](['--family', family, '--seed', str(seed), '--sizes', '40', '80',
                      '--out', str(out)])


@pytest.mark.parametrize('seed', [0, 1])
def test_a_block_is_the_dense_hessians(seed):
    atoms = FAMILIES['saddle_dome'](seed, (40, 80))
    hessian = atoms.calc.get_property('hessian', atoms).reshape(len(atoms), 3, len(atoms), 3)
    for point in np.random.default_rng(seed).choice(len(atoms), 3, replace=False):
        block = hessian[point, :, point, :]
        np.testing.assert_allclose(TOOL['block_eigenvalues'](atoms, point),
                                   np.linalg.eigvalsh(0.5 * (block + block.T)),
                                   rtol=1e-10, atol=1e-10)
