"""Each point's nearest distance: compiled for small scenes, as SciPy gives it."""

import numpy as np
import pytest
from scipy.spatial.distance import cdist

from ase_maud.physics.neighbours import DENSE_MAX_POINTS, NearestDistances


@pytest.mark.parametrize('seed', range(5))
def test_nearest_distances_are_cdists_to_the_last_bit(seed):
    """The compiled pass over every pair gives SciPy's distances exactly (the
    step bound, and so the moves, do not change with it)."""
    rng = np.random.default_rng(seed)
    points = rng.normal(size=(int(rng.integers(2, DENSE_MAX_POINTS + 1)), 3))
    points *= 10.0 ** rng.uniform(-3, 3)
    distances = cdist(points, points)
    np.fill_diagonal(distances, np.inf)
    assert np.array_equal(NearestDistances()(points), distances.min(axis=1))


def test_nearest_of_images_and_large_scenes():
    rng = np.random.default_rng(7)
    points = rng.normal(size=(2 * (DENSE_MAX_POINTS + 1), 3))
    whole = NearestDistances()(points)
    images = NearestDistances(DENSE_MAX_POINTS + 1)(points)
    assert np.all(images >= whole) and np.all(np.isfinite(whole))
    assert np.array_equal(NearestDistances()(points[:1]), [np.inf])
