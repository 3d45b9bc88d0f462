"""The benchmark: samples, statuses, summary, plots, interrupts, backends."""

import csv
import time

import numba
import numpy as np
import pytest
from ase.constraints import FixAtoms

from ase_maud.bench.optimizers import MAX_ATOMS, OPTIMIZERS
from ase_maud.bench.report import markdown, overall, skipped, summarize
from ase_maud.bench.runner import CPU_S, ENERGY, SAMPLE_FIELDS, Run, run_optimizer, run_status
from ase_maud.bench.suite import SAMPLE_COLUMNS, run_suite
from ase_maud.calculator.maud_calculator import MaudCalculator
from ase_maud.cli.command import build_parser, main
from ase_maud.counting import CallRecorder
from ase_maud.scenes.catalogue import LARGE, SUITES, build, scene_sizes
from ase_maud.threads import STARTUP_VARIABLES

PLOTS = ('fmax_vs_calls', 'fmax_vs_time', 'energy_error_vs_calls',
         'energy_error_vs_time')



@pytest.fixture
def pinned(monkeypatch):
    """OpenMP and BLAS variables at 1 (as --threads 1 needs them, else it
    warns), numba restored."""
    for variable in STARTUP_VARIABLES:
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
        for clock in ('time_s', 'cpu_s'):
            times = [float(r[clock]) for r in rows]
            assert np.all(np.diff(times) >= 0) and times[-1] > 0
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
        assert float(fire['cpu_s_ratio@1e-06']) == 1.0
        assert float(fire['calls@0.001']) < float(fire['calls@1e-06'])
        assert (fire['runs'], fire['converged']) == ('2', '2')
        scipy = next(r for r in summary
                     if (r['scene'], r['optimiser']) == (scene, 'L-BFGS-B'))
        assert float(scipy['cpu_s_scipy_ratio@0.001']) == 1.0
        assert float(fire['cpu_s_scipy_ratio@0.001']) == pytest.approx(
            float(fire['cpu_s@0.001']) / float(scipy['cpu_s@0.001']))
    rows = read_csv(out / 'overall.csv')
    assert [(r['optimiser'], r['statistic'], r['scenes']) for r in rows] == [
        ('FIRE', 'median', '2'), ('FIRE', 'worst', '2'),
        ('L-BFGS-B', 'median', '2'), ('L-BFGS-B', 'worst', '2')]
    assert {float(r['calls_ratio@1e-06']) for r in rows[:2]} == {1.0}
    text = (out / 'summary.md').read_text()
    assert '- OMP_NUM_THREADS: 1' in text and '| ring | 5 |' in text
    assert '- fmm_threads: 1' in text          # ASE_MAUD_FMM_THREADS unset
    assert '- fmm_workers: ' in text
    assert '| CPU s to 0.001 | x best ASE | x L-BFGS-B |' in text
    assert '| FIRE | worst | 2 | 1.00 | 1.00 |' in text
    for stem in PLOTS:
        assert_png(out / f'{stem}.png')


def test_statuses(tmp_path, monkeypatch):
    monkeypatch.setitem(OPTIMIZERS, 'broken', broken)
    start = build('chain', 8, seed=2)
    samples, converged, error = run_optimizer(start, 'FIRE', 1e-6, 3)
    assert (len(samples), converged, error) == (4, False, '')
    e_ref = samples[-1, ENERGY]
    assert run_status(samples, converged, error, e_ref, 1e-6) == 'not_converged'
    assert run_status(samples, True, '', e_ref, 1e-6) == 'converged'
    assert run_status(samples, True, '', e_ref * (1 + 1e-5), 1e-6) == \
        'other_minimum'
    samples, converged, error = run_optimizer(start, 'broken', 1e-6, 3)
    assert (len(samples), converged) == (1, False)
    assert error == 'RuntimeError: broken on purpose'
    assert run_status(samples, converged, error, e_ref, 1e-6) == 'error'
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
        calc.get_stiffness(atoms)        # forces known: one call for blocks
        atoms.positions[5] += 0.1
        calc.get_stiffness(atoms)        # all three at once: one call
    assert 'calculate' not in vars(calc)
    calls, time_s, cpu_s, fmax, energy = np.array(recorder.samples).T
    assert list(calls) == [1, 2, 3, 4]
    assert np.all(time_s > 0) and np.all(np.diff(time_s) > 0)
    assert np.all(np.diff(cpu_s) >= 0)
    assert isinstance(atoms.constraints[0], FixAtoms)
    assert np.all(forces[[0, -1]] == 0)
    assert fmax[1] == np.sqrt((forces**2).sum(axis=1).max())
    assert energy[-1] == atoms.get_potential_energy()


class Pausing(MaudCalculator):
    """A MaudCalculator whose every call also spends 50 ms of wall time:
    spinning (``busy``: CPU, at least 50 ms of it) or asleep. Both clocks are
    waited for, since process time counts every thread of the process and
    can run ahead of the wall clock."""

    def __init__(self, busy, **kwargs):
        super().__init__(**kwargs)
        self.busy = busy

    def calculate(self, *args, **kwargs):
        super().calculate(*args, **kwargs)
        wall, cpu = time.perf_counter(), time.process_time()
        while time.perf_counter() - wall < 0.05 or (
                self.busy and time.process_time() - cpu < 0.05):
            if not self.busy:
                time.sleep(0.01)


@pytest.mark.parametrize('busy', [True, False])
def test_cpu_time_is_the_process_cpu_and_wall_time_is_wall(busy):
    atoms = build('dimer')
    # The numpy backend: numba's worker threads may spin after a parallel
    # call, and process time counts them.
    atoms.calc = Pausing(busy, **{**atoms.calc.parameters, 'backend': 'numpy'})
    with CallRecorder(atoms.calc) as recorder:
        for _ in range(3):
            atoms.positions[0] += 0.01
            atoms.get_forces()
    samples = np.array(recorder.samples)
    wall, cpu = np.diff(samples[:, [1, CPU_S]], axis=0).T
    assert np.all(wall >= 0.05)
    if busy:
        assert np.all(cpu >= 0.05)
    else:
        assert np.all(cpu < 0.02)


def run_of(name, first_hits, seed=0, status='converged', scene='s'):
    """Ten samples, calls 1..10, wall time calls / 100 s, CPU time
    calls**2 / 1000 s, fmax 1e-7 from call ``first_hits`` on, else 1."""
    calls = np.arange(1, 11)
    fmax = np.where(calls >= first_hits, 1e-7, 1.0)
    samples = np.column_stack([calls, calls / 100, calls**2 / 1000, fmax,
                               np.zeros(10)])
    assert samples.shape[1] == len(SAMPLE_FIELDS)
    return Run(scene, 4, seed, 16, name, samples, status, 0.0)


def test_summary_medians_and_ratios():
    runs = [run_of('FIRE', 4), run_of('FIRE', 6, 1), run_of('BFGS', 8),
            run_of('BFGS', 10, 1), run_of('Maud-tensor', 2),
            run_of('Maud-tensor', 3, 1, 'other_minimum'),
            run_of('Maud-scalar', 1, 0, 'other_minimum'),
            run_of('L-BFGS-B', 2),
            Run('s', 4, 0, 16, 'PreconLBFGS', np.empty((0, 5)), 'skipped',
                error='too large')]
    rows = {r['optimiser']: r for r in summarize(runs, [1e-3])}
    assert 'PreconLBFGS' not in rows
    assert rows['FIRE']['calls@0.001'] == 5          # median of 4 and 6
    assert rows['BFGS']['time_s@0.001'] == pytest.approx(0.09)
    assert rows['BFGS']['cpu_s@0.001'] == pytest.approx(0.082)
    assert rows['Maud-tensor']['calls@0.001'] == np.inf   # median(2, inf)
    assert rows['Maud-tensor']['converged'] == 1
    assert rows['BFGS']['calls_ratio@0.001'] == pytest.approx(9 / 5)
    assert rows['BFGS']['cpu_s_ratio@0.001'] == pytest.approx(0.082 / 0.026)
    assert rows['FIRE']['time_s_ratio@0.001'] == pytest.approx(1)
    assert rows['FIRE']['cpu_s_scipy_ratio@0.001'] == pytest.approx(6.5)
    assert rows['L-BFGS-B']['cpu_s_ratio@0.001'] == pytest.approx(0.004 / 0.026)
    assert rows['Maud-scalar']['calls_ratio@0.001'] == np.inf
    alone = summarize([run_of('Maud-tensor', 2)], [1e-3])[0]
    assert np.isnan(alone['calls_ratio@0.001'])      # no baseline to compare
    assert np.isnan(alone['cpu_s_scipy_ratio@0.001'])
    assert skipped(runs) == 'PreconLBFGS on s 4 (too large)'
    text = markdown(summarize(runs, [1e-3]), [1e-3], {})
    assert '| s | 4 | 16 | BFGS | 2/2 | 9 | 1.80 | 90 | 1.80 | 0.082 | 3.15 | 20.50 |' \
        in text
    assert '| Maud-tensor | worst | 1 | ∞ | ∞ | ∞ |' in text
    assert '| L-BFGS-B | median | 1 | 0.40 | 0.15 | 1.00 |' in text


def test_overall_medians_and_worst():
    nan, inf = np.nan, np.inf
    ratios = {'Maud': [(0.5, 0.2, nan), (2.0, 0.4, 3.0), (inf, inf, inf),
                       (0.1, 0.3, 1.0)],
              'FIRE': [(1.0, 1.0, nan), (1.5, 1.2, nan)]}
    summary = [{'optimiser': name, 'calls_ratio@1e-06': r,
                'cpu_s_ratio@1e-06': c, 'cpu_s_scipy_ratio@1e-06': q}
               for name, rows in ratios.items() for r, c, q in rows]
    rows = {(r['optimiser'], r['statistic']): r
            for r in overall(summary, [1e-6])}
    assert [rows['Maud', s]['scenes'] for s in ('median', 'worst')] == [4, 4]
    assert rows['Maud', 'median']['calls_ratio@1e-06'] == pytest.approx(1.25)
    assert rows['Maud', 'median']['cpu_s_ratio@1e-06'] == pytest.approx(0.35)
    assert rows['Maud', 'median']['cpu_s_scipy_ratio@1e-06'] == 3.0
    assert rows['Maud', 'worst']['calls_ratio@1e-06'] == inf
    assert rows['FIRE', 'median']['calls_ratio@1e-06'] == 1.25
    assert rows['FIRE', 'worst']['cpu_s_ratio@1e-06'] == 1.2
    assert np.isnan(rows['FIRE', 'worst']['cpu_s_scipy_ratio@1e-06'])


def test_skipped_over_the_size_limit(tmp_path, monkeypatch):
    monkeypatch.setitem(MAX_ATOMS, 'FIRE', 7)
    monkeypatch.setitem(MAX_ATOMS, 'LBFGS', 7)   # the reference still runs
    runs, stopped = run_suite([('chain', 8, 2), ('chain', 6, 2)],
                              ['LBFGS', 'FIRE', 'L-BFGS-B'], tmp_path)
    assert not stopped
    assert [(r.size, r.optimiser, r.status) for r in runs] == [
        (8, 'L-BFGS-B', 'converged'), (8, 'LBFGS', 'skipped'),
        (8, 'FIRE', 'skipped'), (6, 'LBFGS', 'converged'),
        (6, 'FIRE', 'converged'), (6, 'L-BFGS-B', 'converged')]
    rows = read_csv(tmp_path / 'runs.csv')
    assert [(r['size'], r['optimiser'], r['status'], r['calls']) for r in rows
            if r['size'] == '8'] == [
        ('8', 'LBFGS', 'reference', rows[0]['calls']),
        ('8', 'L-BFGS-B', 'converged', rows[1]['calls']),
        ('8', 'LBFGS', 'skipped', '0'), ('8', 'FIRE', 'skipped', '0')]
    assert int(rows[0]['calls']) > 10
    assert rows[3]['error'] == '8 points, over the limit of 7 for FIRE'
    assert {r['optimiser'] for r in summarize(runs, [1e-3])
            if r['size'] == 8} == {'L-BFGS-B'}
    assert 'FIRE on chain 8 (8 points' in skipped(runs)


def test_suite_option_picks_the_large_suite():
    parser = build_parser()
    args = parser.parse_args(['bench', '--suite', 'collective', '--scenes', 'tree'])
    assert scene_sizes(args.scenes, args.sizes, SUITES[args.suite]) == [
        ('tree', 60), ('tree', 200)]
    args = parser.parse_args(['bench', '--suite', 'large', '--scenes', 'tree'])
    assert scene_sizes(args.scenes, args.sizes, SUITES[args.suite]) == [('tree', 2000)]
    args = parser.parse_args(['bench'])
    assert SUITES[args.suite] is not LARGE


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
