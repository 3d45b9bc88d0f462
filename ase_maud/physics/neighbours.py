"""Each point's distance to its nearest other point, one k-d tree per positions."""

from __future__ import annotations

import numba
import numpy as np
from scipy.spatial import cKDTree

#: Images of at most this many points get their distances from a full
#: distance matrix, larger ones from a k-d tree.
DENSE_MAX_POINTS = 64


class NearestDistances:
    """``nearest(x)``: each point's distance to its nearest other point of
    ``x`` (N, 3), or within its image for a chain of ``image_size`` points
    per image (ASE's NEB). The last answer is kept with its positions: the
    step bound and a model that ages with the positions ask for the same
    positions in one step, and get one k-d tree."""

    def __init__(self, image_size: int | None = None):
        self.image_size = image_size
        self._kept: tuple[np.ndarray, np.ndarray] | None = None

    def __call__(self, x: np.ndarray) -> np.ndarray:
        if self._kept is not None and np.array_equal(self._kept[0], x):
            return self._kept[1]
        size = self.image_size or len(x)
        if size < 2:
            distances = np.full(len(x), np.inf)
        elif size == len(x):
            distances = _nearest(x)
        else:
            distances = np.concatenate([_nearest(image)
                                        for image in x.reshape(-1, size, x.shape[1])])
        self._kept = x.copy(), distances
        return distances


def _nearest(points: np.ndarray) -> np.ndarray:
    """Each point's distance to its nearest other point (N >= 2)."""
    if len(points) > DENSE_MAX_POINTS:
        return cKDTree(points).query(points, k=2)[0][:, 1]
    return nearest_over_pairs(np.asarray(points, dtype=float))


@numba.njit(cache=True)
def nearest_over_pairs(points: np.ndarray) -> np.ndarray:
    """Each point's distance to its nearest other point over every pair
    (SciPy's ``cdist`` formula, the squares summed in order, the same digits,
    compiled: a step of a small scene asks once)."""
    n = points.shape[0]
    nearest = np.full(n, np.inf)
    for i in range(n):
        for j in range(n):
            if j != i:
                square = 0.0
                for k in range(points.shape[1]):
                    d = points[i, k] - points[j, k]
                    square += d * d
                nearest[i] = min(nearest[i], np.sqrt(square))
    return nearest
