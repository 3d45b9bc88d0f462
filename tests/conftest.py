"""Shared test helpers."""

import numpy as np
import pytest


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
