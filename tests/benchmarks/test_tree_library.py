"""benchmarks/tree_library.py: its summary takes the fastest tree setting within
the tolerance, and its rows measure each setting's error against the direct
sum (pytreegrav, not a dependency, stood in for by a perturbed direct sum)."""

import runpy

import numpy as np
import pytest

from ase_maud.backends import direct

from helpers import ROOT, run_example


@pytest.fixture
def tool(monkeypatch):
    monkeypatch.syspath_prepend(str(ROOT / 'benchmarks'))   # it imports fmm_threads
    return runpy.run_path(str(ROOT / 'benchmarks' / 'tree_library.py'))


def row(what, wall, error=0.0, theta='', quad=''):
    return {'geometry': 'cube', 'n': 100, 'what': what, 'theta': theta, 'quadrupole': quad,
            'force_error': error, 'energy_error': 0.0, 'wall_s': wall, 'x_direct': wall / 2.0}


def test_the_summary_takes_the_fastest_setting_within_the_tolerance(tool):
    rng = np.random.default_rng()
    fast, slow = sorted(rng.uniform(0.1, 1.0, 2))
    rows = [row('numba', 2.0), row('auto', 1.5),
            row('pytreegrav', fast / 2, 1e-3, 0.7, False),   # fastest, outside
            row('pytreegrav', fast, 5e-5, 0.5, True), row('pytreegrav', slow, 1e-6, 0.3, True)]
    line, = tool['summary'](rows, 1e-4)
    assert f'theta 0.5, quadrupole True: {fast:.3g} s' in line and 'auto 1.5 s, 0.75x' in line
    line, = tool['summary'](rows, 1e-7)
    assert line.endswith('pytreegrav none within tol')


def test_rows_measure_each_setting_against_the_direct_sum(tool, monkeypatch):
    seed = int(np.random.default_rng().integers(1000))   # drawn in the test: the
    # workers of pytest-xdist must collect the same test ids

    def stand_in(p, theta, quadrupole):   # an error that grows with theta
        energy, forces, _ = direct.evaluate(p, False)
        scale = np.linalg.norm(forces, axis=1).max()
        noise = np.random.default_rng(seed).normal(size=forces.shape)
        noise *= theta * (0.1 if quadrupole else 1.0) * 1e-3 * scale / np.linalg.norm(
            noise, axis=1).max()
        return energy, forces + noise
    monkeypatch.setitem(tool['rows_of'].__globals__, 'tree_call', stand_in)
    rows = tool['rows_of']('cube', 300, (0.5, 0.2), 1, 1e-4)
    assert [r['what'] for r in rows] == ['numba', 'auto'] + ['pytreegrav'] * 4
    assert rows[0]['force_error'] == 0.0 and rows[0]['x_direct'] == 1.0
    errors = {(r['theta'], r['quadrupole']): r['force_error'] for r in rows[2:]}
    for (theta, quadrupole), error in errors.items():
        assert error == pytest.approx(theta * (0.1 if quadrupole else 1.0) * 1e-3, rel=1e-9)


def test_without_pytreegrav_it_says_how_to_install_it_and_writes_nothing(
        monkeypatch, tmp_path, capsys):
    import importlib.util
    find_spec = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, 'find_spec',
                        lambda name, *a: None if name == 'pytreegrav' else find_spec(name, *a))
    monkeypatch.syspath_prepend(str(ROOT / 'benchmarks'))
    with pytest.raises(SystemExit):
        run_example('tree_library.py', ['--out', 'run'], monkeypatch, tmp_path,
                    folder='benchmarks')
    assert 'pip install pytreegrav' in capsys.readouterr().err
    assert not (tmp_path / 'run').exists()
