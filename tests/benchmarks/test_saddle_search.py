"""benchmarks/saddle_search.py as a whole: it says so when no start is a minimum."""

import runpy

from helpers import ROOT


def test_the_benchmark_says_so_when_no_start_is_a_minimum(tmp_path, capsys):
    """benchmarks/saddle_search.py leaves out a start that relaxes to no minimum; where
    every start is left out it writes nothing and exits 1, saying why."""
    tool = runpy.run_path(str(ROOT / 'benchmarks' / 'saddle_search.py'))
    main = tool['main']

    def no_minimum(scene, size, seed):
        raise ValueError(f'{scene} {size} seed {seed} relaxed to a saddle, not a minimum')

    main.__globals__['minimum'] = no_minimum
    out = tmp_path / 'out'
    assert main(['--starts', 'ring:5', '--seeds', '0', '1', '--out', str(out)]) == 1
    assert not out.exists()
    captured = capsys.readouterr()
    assert captured.out.count('left out: ring 5 seed') == 2
    assert 'no start was a minimum' in captured.err
