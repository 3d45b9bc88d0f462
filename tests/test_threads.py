"""Pinning the thread pools: numba still compiling afterwards whatever the
environment (the pools limited in place: tests/cli/test_threads_in_place.py)."""

import os
import warnings

import numba
import numpy as np
import pytest

from ase_maud.threads import STARTUP_VARIABLES, pin_threads


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
