"""The benchmark: samples, statuses, summary, plots, interrupts, backends."""

import csv

import numba
import numpy as np
import pytest
from ase.constraints import FixAtoms

from ase_maud.bench.optimizers import OPTIMIZERS
from ase_maud.bench.report import summarize
from ase_maud.bench.runner import CallRecorder, Run, classify, run_optimizer
from ase_maud.bench.suite import SAMPLE_COLUMNS, run_suite
from ase_maud.cli import main
from ase_maud.scenes import build
from ase_maud.threads import THREAD_VARIABLES

PLOTS = ('fmax_vs_calls', 'fmax_vs_time', 'energy_error_vs_calls',
         'energy_error_vs_time')


@pytest.fixture
def pinned(monkeypatch):
    """Thread variables at 1 (as --threads 1 sets them), numba restored."""
    for variable in THREAD_VARIABLES:
        monkeypatch.setenv(variable, '1')
    threads = numba.get_num_threads()
    yield
    numba.set_num_threads(threads)


def read_csv(path):
    with open(path, newline='') as fd:
        return list(csv.DictReader(fd))


def assert_png(path):
    data = path.read_bytes()
    assert data[:8] == b'\x89PNG\r\n\x1a\n' and len(data) > 1000


def broken(atoms):
    """An 'optimiser' that makes one force call, then raises."""
    class Broken:
        def run(self, fmax, steps):
            atoms.get_forces()
            raise RuntimeError('broken on purpose')
    return Broken()


def interrupted(atoms):
    """FIRE on a dimer (the warm-up, the first start); Ctrl-C on the rest."""
    if len(atoms) > 2:
        raise KeyboardInterrupt
    return OPTIMIZERS['FIRE'](atoms)


def test_bench_smoke(tmp_path, pinned):
    out = tmp_path / 'bench'
    assert main(['bench', '--scenes', 'ring', 'net2d', '--sizes', '5',
                 '--seeds', '0', '7', '--optimizers', 'FIRE', 'L-BFGS-B',
                 '--out', str(out), '--no-progress']) == 0
    with open(out / 'samples.csv', newline='') as fd:
        assert tuple(next(csv.reader(fd))) == SAMPLE_COLUMNS
    samples = read_csv(out / 'samples.csv')
    runs = {}
    for row in samples:
        key = row['scene'], row['seed'], row['optimiser']
        runs.setdefault(key, []).append(row)
    assert set(runs) == {(s, k, o) for s in ('ring', 'net2d')
                         for k in ('0', '7') for o in ('FIRE', 'L-BFGS-B')}
    for rows in runs.values():
        calls = [int(r['calls']) for r in rows]
        assert calls == list(range(1, len(rows) + 1))
        assert {r['status'] for r in rows} == {'converged'}
        assert all(r['size'] == '5' for r in rows)
        first, last = rows[0], rows[-1]
        e_ref = float(last['energy']) - float(last['energy_error'])
        assert float(first['energy_error']) > 1e-3 * abs(e_ref)
        assert float(last['fmax']) <= 1e-6
        assert abs(float(last['energy_error'])) < 1e-8 * abs(e_ref)
        times = [float(r['time_s']) for r in rows]
        assert np.all(np.diff(times) >= 0) and times[0] > 0
    references = [r for r in read_csv(out / 'runs.csv')
                  if r['status'] == 'reference']
    assert [(r['scene'], r['seed'], r['optimiser']) for r in references] == [
        (s, k, 'LBFGS') for s in ('ring', 'net2d') for k in ('0', '7')]
    assert all(float(r['fmax']) <= 1e-9 for r in references)
    summary = read_csv(out / 'summary.csv')
    assert len(summary) == 4
    for scene in ('ring', 'net2d'):
        fire = next(r for r in summary
                    if (r['scene'], r['optimiser']) == (scene, 'FIRE'))
        # FIRE is the only ASE baseline here: its ratios are exactly 1
        assert float(fire['calls_ratio@1e-06']) == 1.0
        assert float(fire['time_s_ratio@0.001']) == 1.0
        assert float(fire['calls@0.001']) < float(fire['calls@1e-06'])
        assert (fire['runs'], fire['converged']) == ('2', '2')
    markdown = (out / 'summary.md').read_text()
    assert '- OMP_NUM_THREADS: 1' in markdown and '| ring | 5 |' in markdown
    for stem in PLOTS:
        assert_png(out / f'{stem}.png')


def test_statuses(tmp_path, monkeypatch):
    monkeypatch.setitem(OPTIMIZERS, 'broken', broken)
    start = build('chain', 8, seed=2)
    samples, converged, error = run_optimizer(start, 'FIRE', 1e-6, 3)
    assert (len(samples), converged, error) == (4, False, '')
    e_ref = samples[-1, 3]
    assert classify(samples, converged, error, e_ref, 1e-6) == 'not_converged'
    assert classify(samples, True, '', e_ref, 1e-6) == 'converged'
    assert classify(samples, True, '', e_ref * (1 + 1e-5), 1e-6) == \
        'other_minimum'
    samples, converged, error = run_optimizer(start, 'broken', 1e-6, 3)
    assert (len(samples), converged) == (1, False)
    assert error == 'RuntimeError: broken on purpose'
    assert classify(samples, converged, error, e_ref, 1e-6) == 'error'
    runs, stopped = run_suite([('chain', 8, 2)], ['LBFGS', 'broken'],
                              tmp_path)
    assert not stopped
    assert [(r.optimiser, r.status) for r in runs] == [
        ('LBFGS', 'converged'), ('broken', 'error')]
    rows = read_csv(tmp_path / 'runs.csv')
    assert rows[-1]['error'] == 'RuntimeError: broken on purpose'
    assert read_csv(tmp_path / 'samples.csv')[-1]['status'] == 'error'


def test_interrupt_keeps_finished_runs(tmp_path, monkeypatch, pinned):
    monkeypatch.setitem(OPTIMIZERS, 'interrupted', interrupted)
    out = tmp_path / 'bench'
    assert main(['bench', '--scenes', 'dimer', 'ring', '--sizes', '6',
                 '--optimizers', 'FIRE', 'interrupted', 'LBFGS',
                 '--out', str(out)]) == 130
    finished = {(r['scene'], r['optimiser'])
                for r in read_csv(out / 'samples.csv')}
    assert finished == {('dimer', 'FIRE'), ('dimer', 'interrupted'),
                        ('dimer', 'LBFGS'), ('ring', 'FIRE')}
    summary = (out / 'summary.md').read_text()
    assert '| ring | 6 | 6 | FIRE | 1/1 |' in summary
    assert '- runs: 4 of 6 (interrupted)' in summary
    for stem in PLOTS:
        assert_png(out / f'{stem}.png')


@pytest.mark.parametrize('seed', [0, 3])
def test_call_recorder_counts_calculations(seed):
    atoms = build('chain', 10, seed=seed)
    calc = atoms.calc
    with CallRecorder(calc) as recorder:
        atoms.get_forces()
        atoms.get_potential_energy()     # cached: no call
        atoms.positions[4] += 0.1
        forces = atoms.get_forces()
    assert 'calculate' not in vars(calc)
    calls, time_s, fmax, energy = np.array(recorder.samples).T
    assert list(calls) == [1, 2] and np.all(time_s > 0)
    assert isinstance(atoms.constraints[0], FixAtoms)
    assert np.all(forces[[0, -1]] == 0)
    assert fmax[-1] == np.sqrt((forces**2).sum(axis=1).max())
    assert energy[-1] == atoms.get_potential_energy()


def test_summary_medians_and_ratios():
    def run(name, seed, first_hits, status='converged'):
        fmax = np.where(np.arange(1, 11) >= first_hits, 1e-7, 1.0)
        samples = np.column_stack([np.arange(1, 11), np.arange(1, 11) / 100,
                                   fmax, np.zeros(10)])
        return Run('s', 4, seed, 16, name, samples, status, 0.0)
    runs = [run('FIRE', 0, 4), run('FIRE', 1, 6), run('BFGS', 0, 8),
            run('BFGS', 1, 10), run('Maud-tensor', 0, 2),
            run('Maud-tensor', 1, 3, 'other_minimum'),
            run('Maud-scalar', 0, 1, 'other_minimum')]
    rows = {r['optimiser']: r for r in summarize(runs, [1e-3])}
    assert rows['FIRE']['calls@0.001'] == 5          # median of 4 and 6
    assert rows['BFGS']['time_s@0.001'] == pytest.approx(0.09)
    assert rows['Maud-tensor']['calls@0.001'] == np.inf   # median(2, inf)
    assert rows['Maud-tensor']['converged'] == 1
    assert rows['BFGS']['calls_ratio@0.001'] == pytest.approx(9 / 5)
    assert rows['FIRE']['time_s_ratio@0.001'] == pytest.approx(1)
    assert rows['Maud-scalar']['calls_ratio@0.001'] == np.inf
    alone = summarize([run('Maud-tensor', 0, 2)], [1e-3])[0]
    assert np.isnan(alone['calls_ratio@0.001'])      # no baseline to compare


def test_backends_smoke(tmp_path, pinned):
    out = tmp_path / 'backends'
    assert main(['backends', '--natoms', '20', '50', '--repeats', '1',
                 '--out', str(out)]) == 0
    rows = read_csv(out / 'backends.csv')
    assert {(r['backend'], r['properties'], r['natoms']) for r in rows} == {
        (b, p, n) for b in ('numpy', 'numba', 'fmm eps=0.001', 'fmm eps=1e-06')
        for p in ('forces', 'stiffness') for n in ('20', '50')}
    for row in rows:
        assert float(row['time_per_call_s']) > 0 and row['threads'] == '1'
        error = float(row['rel_error'])
        # Below a few hundred points FMM3D sums directly: exact too.
        assert error == 0 if row['backend'] == 'numpy' else error < 1e-12
    assert '| numba | forces | 50 | 1 |' in (out / 'backends.md').read_text()
    assert_png(out / 'backends.png')
