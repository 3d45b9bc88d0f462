"""Shared test helpers, and the two test tiers.

Tests of whole workflows (a command line, a relaxation compared with other
optimisers over a suite, a killed run resumed, a benchmark) are marked
``integration``: every test of the modules in :data:`INTEGRATION_MODULES`,
and any test marked so by hand. ``pytest -m "not integration"`` is the unit
tier (README.md gives its time); ``pytest`` runs both.
"""

import numpy as np
import pytest

#: Test modules whose every test is an integration test.
INTEGRATION_MODULES = {'test_accuracy', 'test_bench', 'test_cli', 'test_drivers',
                       'test_examples', 'test_filters', 'test_landscape',
                       'test_restart_kill', 'test_run_files', 'test_ase_restart'}


def pytest_collection_modifyitems(config, items):
    """Mark every test of :data:`INTEGRATION_MODULES` ``integration``."""
    for item in items:
        if item.module.__name__.rpartition('.')[2] in INTEGRATION_MODULES:
            item.add_marker(pytest.mark.integration)


def _random_points(n, dim=3, seed=0, spacing=1.0):
    """``n`` random points, shape (n, 3), about ``spacing`` apart.

    The points are a random subset of a grid twice as large, each moved by up
    to ``0.3 * spacing`` per axis, so no two are closer than ``0.4 * spacing``
    and finite differences stay well conditioned. ``dim=2`` puts every point
    on the plane ``z = 0``.
    """
    rng = np.random.default_rng(seed)
    side = int(np.ceil((2 * n) ** (1.0 / dim)))
    grid = np.stack(np.meshgrid(*[np.arange(side)] * dim), -1).reshape(-1, dim)
    points = np.zeros((n, 3))
    points[:, :dim] = rng.permutation(grid)[:n]
    points[:, :dim] += rng.uniform(-0.3, 0.3, size=(n, dim))
    return spacing * points


@pytest.fixture
def random_points():
    """The factory ``random_points(n, dim=3, seed=0, spacing=1.0)``."""
    return _random_points
