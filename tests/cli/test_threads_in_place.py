"""--threads N limits the BLAS and OpenMP pools in place (threadpoolctl): no
restart where numba's pool is large enough, one with every variable where it
is not, a warning from Python."""

import os
import sys

import numba
import numpy as np
import pytest
from threadpoolctl import threadpool_info, threadpool_limits

from ase_maud.threads import STARTUP_VARIABLES, THREAD_VARIABLES, pin_threads


@pytest.fixture
def restored(monkeypatch):
    """The thread variables, numba's count and every pool's limit as they were."""
    for variable in STARTUP_VARIABLES:
        monkeypatch.setenv(variable, os.environ.get(variable, '1'))
    before = numba.get_num_threads()
    with threadpool_limits(limits=None):   # restores the pools' limits on leaving
        yield monkeypatch
    numba.set_num_threads(before)


def test_blas_is_limited_in_place_without_a_restart(restored):
    np.ones((50, 50)) @ np.ones((50, 50))   # BLAS loaded
    restarts = []
    restored.setattr(os, 'execve', lambda *args: restarts.append(args))
    pin_threads(1, restart=True)
    assert restarts == []
    assert all(pool['num_threads'] == 1 for pool in threadpool_info())
    assert all(os.environ[v] == '1' for v in STARTUP_VARIABLES)
    assert numba.get_num_threads() == 1


def test_a_numba_pool_too_small_restarts_with_every_variable(restored):
    threads = numba.config.NUMBA_NUM_THREADS + 1
    restarts = []

    def execve(path, args, env):
        restarts.append((args, env))
        raise SystemExit

    restored.setattr(os, 'execve', execve)
    with pytest.raises(SystemExit):
        pin_threads(threads, restart=True)
    args, env = restarts[0]
    assert args == [sys.executable, '-m', 'ase_maud', *sys.argv[1:]]
    assert all(env[v] == str(threads) for v in THREAD_VARIABLES)
    with pytest.warns(UserWarning, match="numba's pool has"):
        pin_threads(threads, restart=False)
