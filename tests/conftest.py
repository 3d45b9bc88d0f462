"""Shared fixtures, and the two test tiers.

Tests of whole workflows (a command line, a relaxation compared with other
optimisers over a suite, a killed run resumed, a benchmark) are marked
``integration``: every test of the files in :data:`INTEGRATION_MODULES`, and
any test marked so by hand; a test that took over 5 s is marked ``slow``.
``pytest -q`` is the fast tier (pyproject's addopts leave both out; README.md
gives its time), ``pytest -q -m "slow or integration"`` the rest. Helpers that
test files share are in ``tests/helpers.py``.
"""

import os
from pathlib import Path

import pytest
from ase.io import Trajectory, write

from ase_maud.io.net_writer import write_net
from ase_maud.io.nets import read_frames
from ase_maud.scenes.catalogue import build
from ase_maud.threads import STARTUP_VARIABLES, pin_blas

import helpers

#: Test files (paths under tests/) whose every test is an integration test.
INTEGRATION_MODULES = {
    'bench/test_bench.py', 'calculator/test_accuracy.py', 'cli/test_command.py',
    'optimize/test_resume.py', 'optimize/test_run_files.py', 'saddles/test_landscape.py',
    'workflows/test_ase_drivers.py', 'workflows/test_ase_filters.py',
    'workflows/test_examples.py', 'test_kernel_cache.py', 'benchmarks/test_ase_systems.py',
    'benchmarks/test_basin_hopping.py', 'benchmarks/test_kernel_throughput.py',
    'benchmarks/test_fmm_threads.py',
    'ase_suite/test_ase_restart.py'}

TESTS = Path(__file__).resolve().parent


def pytest_configure(config):
    """In a pytest-xdist worker, unless the environment sets any of
    :data:`~ase_maud.threads.STARTUP_VARIABLES`: BLAS and OpenMP on the cores
    shared among the workers, at least one thread each
    (:func:`~ase_maud.threads.pin_blas`). Left at a thread per core in every
    worker, the pools oversubscribe the machine: on 2 cores the fast tier
    took 8-10 minutes where it takes under 3 (2026-12-07)."""
    workers = os.environ.get('PYTEST_XDIST_WORKER_COUNT')
    if workers is None or any(os.environ.get(v) for v in STARTUP_VARIABLES):
        return
    pin_blas(max(1, (os.cpu_count() or 1) // int(workers)))


def pytest_collection_modifyitems(config, items):
    """Mark every test of :data:`INTEGRATION_MODULES` ``integration``."""
    for item in items:
        if item.path.resolve().relative_to(TESTS).as_posix() in INTEGRATION_MODULES:
            item.add_marker(pytest.mark.integration)


@pytest.fixture
def random_points():
    """The factory :func:`helpers.random_points`, ``(n, dim=3, seed=0, spacing=1.0)``."""
    return helpers.random_points


@pytest.fixture(params=[0, 1])
def four_frames(tmp_path, request):
    """A ring of random size relaxed for four frames, as .traj and .xyz."""
    atoms = build('ring', 5 + 3 * request.param, seed=request.param)
    atoms.get_potential_energy()
    with Trajectory(tmp_path / 'f.traj', 'w') as trajectory:
        for _ in range(4):
            atoms.positions[0, 0] += 0.01
            trajectory.write(atoms)
    frames = read_frames(tmp_path / 'f.traj')
    write_net(tmp_path / 'f.xyz', frames[0])   # and its edge list, f.edges.txt
    write(tmp_path / 'f.xyz', frames)
    return tmp_path / 'f.traj', tmp_path / 'f.xyz'
