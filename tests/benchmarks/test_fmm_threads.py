"""benchmarks/fmm_threads.py: its table picks the fastest eps within the
margin, and it runs on a small size (the two-process sums equal one
process's, which the tool asserts), refusing an --out that exists."""

import csv
import runpy

import pytest

from helpers import ROOT, run_example

pytest.importorskip('fmm3dpy')

TOOL = runpy.run_path(str(ROOT / 'benchmarks' / 'fmm_threads.py'))


def row(eps, error, cpu, geometry='cube'):
    return {'geometry': geometry, 'lib_eps': eps, 'force_error': error,
            'energy_error': 0.0, 'block_error': '', 'cpu_s': cpu}


def test_the_table_takes_the_fastest_eps_within_the_margin():
    rows = [row(1e-2, 1e-4, 1.5), row(1e-2, 2e-4, 1.5, 'net'),   # slower
            row(1e-3, 2e-5, 0.5), row(1e-3, 3e-5, 0.5, 'net'),   # the worst counts
            row(1e-4, 1e-8, 2.0), row(1e-4, 1e-9, 2.0, 'net')]
    table, worst, _ = TOOL['choose'](rows, (1e-2, 1e-3, 1e-4, 1e-6, 1e-9), 10)
    assert worst[1e-3] == 3e-5
    assert {tol: eps for tol, (eps, _, _) in table.items()} == {
        1e-2: 1e-3, 1e-3: 1e-3, 1e-4: 1e-4, 1e-6: 1e-4}   # 1e-9: none


def test_runs_small_and_refuses_to_overwrite(monkeypatch, tmp_path):
    argv = ['--out', 'run', '--sizes', '700', '--seeds', '0', '--eps', '1e-3',
            '--geometries', 'cube', 'net', '--split-eps', '1e-3',
            '--repeats', '1', '--goal', '0']
    run_example('fmm_threads.py', argv, monkeypatch, tmp_path, folder='benchmarks')
    errors = list(csv.DictReader(open(tmp_path / 'run' / 'errors.csv')))
    assert {(r['geometry'], r['computes']) for r in errors} == {
        ('cube', 'E+F'), ('cube', 'E+F+K'), ('net', 'E+F'), ('net', 'E+F+K')}
    assert all(float(r['force_error']) < 1e-3 for r in errors)
    split = list(csv.DictReader(open(tmp_path / 'run' / 'split.csv')))
    assert {r['what'] for r in split} >= {'one 0.001 E+F', 'two 0.001 E+F+K'}
    assert 'Fastest library eps' in (tmp_path / 'run' / 'summary.md').read_text()
    with pytest.raises(SystemExit):
        run_example('fmm_threads.py', argv, monkeypatch, tmp_path, folder='benchmarks')
