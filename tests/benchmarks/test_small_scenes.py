"""benchmarks/small_scenes.py: its passes pooled run by run (each run's CPU the
median over the passes), passes of another suite refused, and its profile's timers
around the kernel, the factorisations and the compiled step."""

import csv
import importlib.util

import numpy as np
import pytest

from helpers import ROOT

_SPEC = importlib.util.spec_from_file_location(
    'small_scenes', ROOT / 'benchmarks' / 'small_scenes.py')
small_scenes = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(small_scenes)

COLUMNS = ['scene', 'seed', 'points', 'Maud calls', 'Maud CPU s', 'L-BFGS-B (ASE) calls',
           'L-BFGS-B (ASE) CPU s', 'BFGS calls', 'FIRE calls']


def _passes(tmp_path, rng, runs, count):
    """``count`` CSVs of the suite's columns: the same ``runs`` (scene, seed),
    random CPU seconds; their paths and the CPU (count, runs, 2)."""
    cpu = rng.uniform(1e-3, 1e-1, (count, len(runs), 2))
    paths = []
    for k in range(count):
        path = tmp_path / f'pass{k}.csv'
        with path.open('w', newline='') as handle:
            writer = csv.DictWriter(handle, fieldnames=COLUMNS)
            writer.writeheader()
            for (scene, seed), (maud, lbfgsb) in zip(runs, cpu[k], strict=True):
                writer.writerow({'scene': scene, 'seed': seed, 'points': 10, 'Maud calls': 7,
                                 'Maud CPU s': maud, 'L-BFGS-B (ASE) calls': 40,
                                 'L-BFGS-B (ASE) CPU s': lbfgsb, 'BFGS calls': 50,
                                 'FIRE calls': 'inf'})
        paths.append(str(path))
    return paths, cpu


@pytest.mark.parametrize('seed', [0, 1])
def test_passes_are_pooled_run_by_run(seed, tmp_path, capsys):
    rng = np.random.default_rng(seed)
    runs = [(f'scene{k % 3}:5', 100 + k // 3) for k in range(int(rng.integers(3, 10)))]
    paths, cpu = _passes(tmp_path, rng, runs, int(rng.integers(2, 5)))
    small_scenes.pool(paths)
    out = capsys.readouterr().out.splitlines()
    median = np.median(cpu, axis=0)
    ratio = median[:, 0] / median[:, 1]
    assert out[0] == (f'{len(paths)} passes, CPU / L-BFGS-B (ASE): median '
                      f'{np.median(ratio):.3f}, worst {ratio.max():.3f}, above 0.5: '
                      f'{int((ratio > 0.5).sum())} of {len(runs)}')
    first = [k for k, run in enumerate(runs) if run[0] == 'scene0:5']
    assert out[2].split(' | ') == [
        'scene0:5', '10', '7', f'{1e3 * np.median(median[first, 0]):.1f}', '40',
        f'{1e3 * np.median(median[first, 1]):.1f}', '50', 'not converged',
        f'{np.median(ratio[first]):.2f}']


def test_passes_of_another_suite_are_refused(tmp_path):
    rng = np.random.default_rng(2)
    paths, _ = _passes(tmp_path, rng, [('ring:5', 1), ('tree:5', 1)], 1)
    (other := tmp_path / 'other').mkdir()
    more, _ = _passes(other, rng, [('ring:5', 1), ('tree:5', 2)], 1)
    with pytest.raises(SystemExit, match='other scenes or seeds'):
        small_scenes.pool(paths + more)


@pytest.mark.integration
def test_the_profile_times_the_kernel_factorisations_and_compiled_step():
    """Each timer fires, and none is counted twice: within one run the timed
    calls are disjoint spans of the process clock, so every share of the run
    is positive whatever the machine's load. The shares of the steps alone
    are differences of two runs' clocks, noisy on a busy machine: only
    finite."""
    shares = small_scenes.profile('all_pairs', 6, 3, 1e-6, repeats=2)
    keys = ('kernel', 'factorisations', 'compiled step', 'rest')
    run = [shares[f'{key} (run)'] for key in keys]
    assert all(part > 0 for part in run), run
    assert np.all(np.isfinite([shares[f'{key} (step)'] for key in keys]))
    assert shares['us a step'] > 0 and shares['us a start'] > 0
