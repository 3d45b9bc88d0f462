"""Pinning the thread pools: a restart with every variable set, a warning
from Python, and numba still compiling afterwards whatever the environment."""

import os
import sys
import warnings

import numba
import numpy as np
import pytest

from ase_maud.threads import STARTUP_VARIABLES, THREAD_VARIABLES, pin_threads


@pytest.fixture
def environment(monkeypatch):
    """The OpenMP and BLAS variables unset for the test and restored after
    it, numba's thread count restored. NUMBA_NUM_THREADS stays as the
    process started (unset or its pool size), the only values numba runs
    with."""
    for variable in STARTUP_VARIABLES:
        monkeypatch.setenv(variable, '0')   # recorded, so restored at the end
        monkeypatch.delenv(variable)
    before = numba.get_num_threads()
    yield monkeypatch
    numba.set_num_threads(before)


def launch_pool():
    """Run a parallel loop, so that numba's threads are launched."""
    @numba.njit(parallel=True)
    def total(x):
        s = 0.0
        for i in numba.prange(x.size):
            s += x[i]
        return s

    assert total(np.ones(100)) == 100


@pytest.mark.parametrize('threads', [1, 2])
def test_restart_passes_every_variable(environment, threads):
    numba_variable = os.environ.get('NUMBA_NUM_THREADS')
    restarts = []

    def execve(path, args, env):
        restarts.append((args, env))
        raise SystemExit

    environment.setattr(os, 'execve', execve)
    with pytest.raises(SystemExit):   # numpy is loaded: start again
        pin_threads(threads, restart=True)
    args, env = restarts[0]
    assert args == [sys.executable, '-m', 'ase_maud', *sys.argv[1:]]
    assert all(env[v] == str(threads) for v in THREAD_VARIABLES)
    assert os.environ.get('NUMBA_NUM_THREADS') == numba_variable
    pool = numba.config.NUMBA_NUM_THREADS
    if pool < threads:   # only a new process has a larger pool
        with pytest.raises(SystemExit):
            pin_threads(threads, restart=True)
    else:
        pin_threads(threads, restart=True)   # now in force: no restart
        assert len(restarts) == 1
    assert numba.get_num_threads() == min(threads, pool)


@pytest.mark.parametrize('threads', [1, 2])
def test_warns_from_python(environment, threads):
    for variable in STARTUP_VARIABLES:
        environment.setenv(variable, str(threads))
    environment.delenv('OPENBLAS_NUM_THREADS')
    with pytest.warns(UserWarning, match='BLAS may use another count'):
        pin_threads(threads, restart=False)
    assert os.environ['OPENBLAS_NUM_THREADS'] == str(threads)


@pytest.mark.parametrize('threads', [1, 2])
def test_numba_compiles_after_pinning(environment, threads):
    """numba reads NUMBA_NUM_THREADS again before each compilation and fails
    if it differs from its launched pool: pinning leaves it as it was."""
    launch_pool()
    numba_variable = os.environ.get('NUMBA_NUM_THREADS')
    for variable in STARTUP_VARIABLES:
        environment.setenv(variable, str(threads))
    with warnings.catch_warnings():
        warnings.simplefilter('ignore')   # a pool smaller than asked for
        pin_threads(threads, restart=False)
    assert os.environ.get('NUMBA_NUM_THREADS') == numba_variable
    assert numba.njit(lambda x: x + threads)(1) == 1 + threads   # a fresh compilation
    launch_pool()
