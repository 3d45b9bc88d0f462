"""Starts of saddle searches (ase_maud.saddles.starts): a minimum whose lowest
eigenvalue is degenerate is left along the same vector whatever basis of its
eigenspace the eigensolver returns (LAPACK builds differ)."""

from dataclasses import replace

import numpy as np
import pytest

import ase_maud.saddles.starts as starts
from ase_maud import Maud
from ase_maud.analysis.stationary import classify
from ase_maud.counting import fresh_copy


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_a_degenerate_lowest_mode_gives_the_same_start_in_any_basis(monkeypatch, seed):
    """The 6-point cluster's minimum (an octahedron: its lowest eigenvalue
    three times over) left by 0.3 along its lowest mode: the same start when
    the eigenspace's basis is rotated at random, and a move within that space."""
    scene = starts.saddle_start('all_pairs', 6, 0, 0.0)
    start = starts.displaced_minimum(fresh_copy(scene), seed, 0.3)
    relaxed = fresh_copy(scene)   # the minimum displaced_minimum relaxes to
    Maud(relaxed, logfile=None).run(fmax=1e-9, steps=5000)
    point = classify(relaxed)
    values = point.eigenvalues
    lowest = np.flatnonzero(values - values[0] <= starts.DEGENERATE_RTOL * abs(values).max())
    assert len(lowest) == 3
    rotation, _ = np.linalg.qr(np.random.default_rng(seed + 100).standard_normal((3, 3)))
    modes = point.modes.copy()
    modes[lowest] = np.einsum('ab,bij->aij', rotation, point.modes[lowest])
    monkeypatch.setattr(starts, 'classify', lambda atoms: replace(point, modes=modes))
    rotated = starts.displaced_minimum(fresh_copy(scene), seed, 0.3)
    np.testing.assert_allclose(rotated.positions, start.positions, atol=1e-9)
    move = start.positions - relaxed.positions
    space = point.modes[lowest].reshape(3, -1)
    np.testing.assert_allclose(space.T @ (space @ move.ravel()), move.ravel(), atol=1e-9)
    assert np.linalg.norm(move, axis=1).max() == pytest.approx(0.3)
