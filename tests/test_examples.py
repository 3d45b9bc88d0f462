"""The runnable examples and README's quick start run, and say what they should."""

import os
import runpy
import subprocess
import sys
import time
from pathlib import Path

import pytest

from ase_maud.kernel_cache import COMPILE_NOTICE

ROOT = Path(__file__).parent.parent


def run_example(name, argv, monkeypatch, tmp_path, folder='examples'):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, 'argv', [name, *argv])
    runpy.run_path(str(ROOT / folder / name), run_name='__main__')


@pytest.mark.integration
def test_saddle_and_minima(monkeypatch, tmp_path, capsys):
    run_example('saddle_and_minima.py', [], monkeypatch, tmp_path)
    out = capsys.readouterr().out
    assert out.count('index 1 (saddle') == 2
    assert out.count('index 0 (minimum)') == 4
    assert (tmp_path / 'saddle_and_minima.png').stat().st_size > 0


def test_classify_large_net(monkeypatch, tmp_path, capsys):
    run_example('classify_large_net.py', ['--size', '8', '--k', '4'],
                monkeypatch, tmp_path)
    out = capsys.readouterr().out
    assert 'net2d 8: 64 points' in out
    assert 'relaxed: converged=True' in out
    assert 'classified: minimum (index 0)' in out


def test_kernel_throughput(monkeypatch, tmp_path, capsys):
    pytest.importorskip('numba')
    run_example('kernel_throughput.py', ['--sizes', '300', '--seconds',
                                         '0.05', '--out', 'k.csv'],
                monkeypatch, tmp_path, folder='benchmarks')
    assert (tmp_path / 'k.csv').read_text().count('\n') >= 3


def _fresh_python(code, tmp_path, **env):
    """Run ``python -c code`` in ``tmp_path`` with ``XDG_CACHE_HOME`` there and
    ``NUMBA_CACHE_DIR`` unset unless given; return its stdout and stderr."""
    env = {**{k: v for k, v in os.environ.items() if k != 'NUMBA_CACHE_DIR'},
           'XDG_CACHE_HOME': str(tmp_path / 'xdg'), **env}
    done = subprocess.run([sys.executable, '-c', code], cwd=tmp_path, env=env,
                          capture_output=True, text=True, check=True)
    return done.stdout, done.stderr


KERNEL_CACHE = 'import ase_maud, numba; print(numba.config.CACHE_DIR, ase_maud.kernels_cached())'


@pytest.mark.parametrize('numba_first', [False, True])
def test_kernels_cache_per_user(tmp_path, numba_first):
    """numba's cache is $XDG_CACHE_HOME/ase_maud/numba, also when numba was
    imported before ase_maud; an empty cache says the kernels are not compiled."""
    code = ('import numba; ' if numba_first else '') + KERNEL_CACHE
    assert _fresh_python(code, tmp_path)[0].split() == [
        str(tmp_path / 'xdg' / 'ase_maud' / 'numba'), 'False']


def test_user_numba_cache_dir_is_kept(tmp_path):
    mine = str(tmp_path / 'mine')
    assert _fresh_python(KERNEL_CACHE, tmp_path, NUMBA_CACHE_DIR=mine)[0].split() == [
        mine, 'False']


@pytest.mark.integration
def test_quick_start_relax_compiles_once_into_the_user_cache(tmp_path):
    """README's first command on a small net, twice in fresh processes: one
    notice before compiling, machine code in the user's cache (none beside the
    package), no notice the second time."""
    import ase_maud

    relax = ('import sys\nfrom ase_maud.cli import main\n'
             "sys.exit(main(['relax', '--size', '4', '--traj', 'm.traj']))")
    start = time.time()
    first = _fresh_python(relax, tmp_path)
    second = _fresh_python(relax, tmp_path)
    assert first[1].splitlines() == [COMPILE_NOTICE]
    assert 'converged: weighted_net 16 points' in first[0]
    assert list((tmp_path / 'xdg' / 'ase_maud' / 'numba').rglob('*.nbi'))
    package = Path(ase_maud.__file__).parent
    assert not [f for f in package.rglob('*.nb[ic]') if f.stat().st_mtime >= start]
    assert second[1] == ''
    assert second[0].splitlines()[-1] == first[0].splitlines()[-1]


def test_form_finding(monkeypatch, tmp_path, capsys):
    """The canopy hangs from its outer rim: the reactions balance its load,
    the cables round the opening carry it, and the files are written."""
    run_example('form_finding.py', ['--weight', '0.3'], monkeypatch, tmp_path)
    out = capsys.readouterr().out
    assert 'canopy.obj: 100 points, 180 members, 36 supports, a = 0.0' in out
    assert '4 cables round the opening at q = 3.0' in out
    balance = float(out.split('reactions + loads = ')[1].split()[0])
    assert balance < 1e-9 * 0.3 * 64
    assert float(out.split('sag at the opening: ')[1].split()[0]) > 0.1
    for name in ('canopy_forces.csv', 'canopy.json', 'canopy.png'):
        assert (tmp_path / name).stat().st_size > 0
