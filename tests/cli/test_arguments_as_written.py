"""Arguments as users write them (issue 52, item 3): numbers in any notation
Python reads (``--load 0 0 -1e-3``), and a flat net under out-of-plane loads
is 3D unless the user forced ``--dim 2``; the documented
``canopy.ply --fix outer --loads`` example runs verbatim."""

from __future__ import annotations

import contextlib
import io
import os
import shlex

import meshio
import numpy as np
import pytest

from ase_maud.cli.command import main
from ase_maud.io.nets import read_net


def run(folder, line):
    """``ase-maud`` on ``line`` (as typed) in ``folder``: status and stderr."""
    error = io.StringIO()
    cwd = os.getcwd()
    os.chdir(folder)
    try:
        with contextlib.redirect_stderr(error), contextlib.redirect_stdout(io.StringIO()):
            try:
                status = main(shlex.split(line)[1:])
            except SystemExit as stop:
                status = stop.code
    finally:
        os.chdir(cwd)
    return status, error.getvalue()


def canopy(folder, n=6, seed=0):
    """A flat n x n quad net as PLY, and a loads table of seeded vertical loads."""
    rng = np.random.default_rng(seed)
    x, y = np.meshgrid(np.arange(n, dtype=float), np.arange(n, dtype=float))
    points = np.c_[x.ravel(), y.ravel(), np.zeros(n * n)]
    quads = [[i * n + j, i * n + j + 1, (i + 1) * n + j + 1, (i + 1) * n + j]
             for i in range(n - 1) for j in range(n - 1)]
    meshio.write(folder / 'canopy.ply', meshio.Mesh(points, [('quad', np.array(quads, np.int32))]),
                 binary=False)
    loads = rng.uniform(-0.3, -0.1, n * n)
    (folder / 'loads.csv').write_text('i,px,py,pz\n' + ''.join(
        f'{k},0,0,{float(p)!r}\n' for k, p in enumerate(loads)))
    return loads


@pytest.mark.parametrize('z', ['-1e-3', '-1E-3', '-.5e-2', '-1_0e-4', '-0.001'])
def test_a_load_in_scientific_notation(tmp_path, z):
    canopy(tmp_path)
    status, error = run(tmp_path, f'ase-maud relax canopy.ply --fix outer --load 0 0 {z} '
                        '--quiet --out hung.json')
    assert status == 0, error
    atoms = read_net(tmp_path / 'hung.json')
    assert atoms.calc.dim == 3
    free = np.ones(len(atoms), bool)
    free[atoms.constraints[0].index] = False
    np.testing.assert_allclose(atoms.calc.parameters['loads'][free],
                               [[0, 0, float(z.replace('_', ''))]] * free.sum())


def test_a_bad_number_is_still_refused(tmp_path):
    canopy(tmp_path)
    status, error = run(tmp_path, 'ase-maud relax canopy.ply --load 0 0 -1e-3x')
    assert status == 2 and error.count('\n') == 1


def test_the_documented_canopy_example_runs_verbatim(tmp_path):
    """docs/cli.md: ``ase-maud relax canopy.ply --fix outer --loads loads.csv
    --forces forces.csv``; the loads hang the flat net in 3D."""
    line = next(line.split('$ ', 1)[1] for line in open(
        os.path.join(os.path.dirname(__file__), '..', '..', 'docs', 'cli.md'),
        encoding='utf-8') if 'canopy.ply --fix outer --loads' in line)
    loads = canopy(tmp_path)
    status, error = run(tmp_path, line + ' --quiet')
    assert status == 0, error
    rows = (tmp_path / 'forces.csv').read_text().splitlines()
    reactions = [row.split(',') for row in rows if row.startswith('reaction')]
    assert sum(float(r[-1]) for r in reactions) == pytest.approx(-loads.sum(), rel=1e-9)


def test_dim_2_forced_refuses_out_of_plane_loads(tmp_path):
    canopy(tmp_path)
    status, error = run(tmp_path, 'ase-maud relax canopy.ply --fix outer --loads loads.csv '
                        '--dim 2 --quiet')
    assert status == 2 and 'dim=2' in error and error.count('\n') == 1
    with open(tmp_path / 'flat.csv', 'w') as table:
        table.write('i,px,py,pz\n7,0.01,0,0\n')
    status, error = run(tmp_path, 'ase-maud relax canopy.ply --fix outer --loads flat.csv '
                        '--quiet --out flat.json')
    assert status == 0, error
    assert read_net(tmp_path / 'flat.json').calc.dim == 2
