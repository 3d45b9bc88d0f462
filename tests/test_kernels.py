"""The compiled direct sum against the numpy reference."""

import numpy as np
import pytest

from ase_maud.kernels import (_numba_blocks, _numba_forces, repulsion_numba,
                              repulsion_numpy, voigt_to_blocks)

RTOL = 1e-12


def assert_close(actual, expected):
    """Equal to ``RTOL`` relative to the largest entry of ``expected``."""
    scale = np.abs(expected).max(initial=0.0)
    np.testing.assert_allclose(actual, expected, rtol=0, atol=RTOL * scale)


@pytest.mark.parametrize('dim', [2, 3])
@pytest.mark.parametrize('n', [1, 2, 3, 4, 5, 16, 17, 64, 127, 300])
@pytest.mark.parametrize('seed', [0, 1])
def test_numba_matches_numpy(random_points, n, dim, seed):
    points = random_points(n, dim, seed, spacing=10.0 ** (seed - 0.5))
    energy, forces, blocks = repulsion_numba(points, blocks=True)
    ref_energy, ref_forces, ref_blocks = repulsion_numpy(points, blocks=True)
    assert energy == pytest.approx(ref_energy, rel=RTOL, abs=0)
    assert forces.shape == blocks.shape[:1] + (3,) == (n, 3)
    assert_close(forces, ref_forces)
    assert_close(blocks, ref_blocks)
    # Without blocks: the same energy and forces, and no blocks returned.
    e2, f2, b2 = repulsion_numba(points)
    assert b2 is None
    assert e2 == pytest.approx(energy, rel=RTOL, abs=0)
    assert_close(f2, forces)


@pytest.mark.parametrize('nchunks', [2, 3, 7])
@pytest.mark.parametrize('n', [3, 8, 13, 50])
def test_chunks_share_rows(random_points, n, nchunks):
    """Rows k and N-1-k go to chunk k % nchunks; every split sums the same.

    Calls the compiled kernels with more chunks than threads, so the split is
    tested whatever ``NUMBA_NUM_THREADS`` is.
    """
    points = random_points(n, 3, seed=n)
    ref_energy, ref_forces, ref_blocks = repulsion_numpy(points, blocks=True)
    xyz = [points[:, k].copy() for k in range(3)]
    for kernel in (_numba_forces, _numba_blocks):
        energy, forces, blocks = kernel(*xyz, nchunks)
        assert energy == pytest.approx(ref_energy, rel=RTOL, abs=0)
        assert_close(forces, ref_forces)
    assert_close(blocks, ref_blocks)


def test_blocks_in_voigt_order():
    """Entries are xx, yy, zz, xy, xz, yz of ``3 d d^T / L**5 - I / L**3``."""
    d = np.array([1.0, 2.0, 2.0])  # L = 3
    points = np.array([d, np.zeros(3)])
    expected = 3 * np.outer(d, d) / 3**5 - np.eye(3) / 3**3
    for kernel in (repulsion_numba, repulsion_numpy):
        energy, forces, block6 = kernel(points, blocks=True)
        assert energy == pytest.approx(1 / 3)
        np.testing.assert_allclose(forces, [d / 27, -d / 27], rtol=1e-14)
        blocks = voigt_to_blocks(block6, 3)
        np.testing.assert_allclose(blocks, [expected, expected], rtol=1e-14)
        np.testing.assert_array_equal(voigt_to_blocks(block6, 2),
                                      blocks[:, :2, :2])
