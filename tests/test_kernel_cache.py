"""numba's kernel cache (ase_maud.kernel_cache): per user, a user's
NUMBA_CACHE_DIR kept, README's quick start compiling once into it."""

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from ase_maud.kernel_cache import COMPILE_NOTICE


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
