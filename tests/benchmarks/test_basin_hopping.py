"""benchmarks/basin_hopping.py: the same hops and calls to the best minimum."""

import csv
import runpy

from helpers import ROOT


def read_csv(path):
    with open(path, newline='') as fd:
        return list(csv.DictReader(fd))


def test_basin_hopping_tool_same_hops_and_calls_to_best(tmp_path, capsys):
    tool = runpy.run_path(str(ROOT / 'benchmarks' / 'basin_hopping.py'))
    once, again = (tool['hop'](2, 6, 1, 'BFGS', 3, 1e-3, 0.5, 0.1, 2000, 1e-6)
                   for _ in range(2))
    for row in (once, again):   # CPU seconds are the one thing a seed does not fix
        assert row.pop('cpu_s') > 0
    assert once == again     # the seed fixes BasinHopping's moves and acceptance
    assert len(once['trace']) == 4 and once['calls'] == once['trace'][-1][0]
    assert tool['main'](['--dims', '2', '3', '--sizes', '6', '--hops', '2',
                         '--out', str(tmp_path)]) == 0
    rows = read_csv(tmp_path / 'basin_hopping.csv')
    assert [(r['dim'], r['optimiser']) for r in rows] == [
        ('2', 'BFGS'), ('2', 'Maud'), ('3', 'BFGS'), ('3', 'Maud')]
    for start in (rows[:2], rows[2:]):
        best = min(float(r['lowest_energy']) for r in start)
        for r in start:
            assert float(r['best_energy']) == best and not r['error']
            assert 0 < int(r['calls_to_own_lowest']) <= int(r['calls'])
            if r['calls_to_best'] != 'inf':
                assert int(r['calls_to_own_lowest']) <= int(r['calls_to_best'])
        assert float(start[0]['calls_to_best_x_BFGS']) == 1.0
    assert '| 3 | 6 | 0 | Maud |' in capsys.readouterr().out
