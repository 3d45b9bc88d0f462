"""Saddle searches with ``Maud(target='stationary')`` against Sella (tools/saddles.py)."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip('sella')

_SPEC = importlib.util.spec_from_file_location(
    'saddles', Path(__file__).parent.parent / 'tools' / 'saddles.py')
saddles = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(saddles)

FMAX = 1e-6


def _search(start, optimiser):
    atoms, row, point = saddles.search(start, optimiser, FMAX, 500)
    return atoms, row, point


@pytest.mark.parametrize('start', [
    'six:6:0',            # 2D: the guess of examples/saddle_and_minima.py
    'all_pairs2d:9:0.3',  # 2D: a 9-point minimum left along its lowest mode
    'all_pairs:6:0.3',    # 3D: a 6-point minimum left along its lowest mode
])
def test_exact_model_reaches_a_collective_saddle_that_sella_finds(start):
    """The signed exact step converges on an index-1 saddle where every nodal block is
    positive definite (collective), so the nodal iteration ``x + gamma D^-1 f`` is
    repelled from it (``D^-1 H`` has H's negative eigenvalue, Sylvester); Sella ends on
    the same saddle."""
    scene, size, amp = start.split(':')
    atoms = saddles.make_start(scene, int(size), 0, float(amp))
    saddle, row, point = _search(atoms, 'Maud-exact')
    assert row['converged'] and not row['error']
    assert point.verdict == 'saddle' and point.index == 1 and point.fmax <= FMAX
    dim = saddle.calc.parameters['dim']
    blocks = saddle.calc.get_stiffness(saddle)[:, :dim, :dim]
    assert np.linalg.eigvalsh(blocks).min() > 0  # collective: invisible block by block

    nodal, _, nodal_point = _search(atoms, 'Maud-nodal')
    assert not (nodal_point.fmax <= FMAX and saddles.same_point(nodal, saddle))

    sella, sella_row, sella_point = _search(atoms, 'Sella')
    assert sella_row['converged'] and sella_point.index == 1
    assert saddles.same_point(sella, saddle, energy_rtol=1e-8, distance_atol=1e-4)


def test_every_search_reaches_the_cage_saddle():
    """The cage centre's instability shows in the free point's own block: the nodal
    step finds it too, and all end where Sella does."""
    atoms = saddles.make_start('cage', 8, 0, 0.0)
    ends = {}
    for name in ('Maud-exact', 'Maud-nodal', 'Sella'):
        ends[name], row, point = _search(atoms, name)
        assert row['converged'] and point.index == 1 and point.fmax <= FMAX
    free = ends['Maud-exact'].calc.get_stiffness(ends['Maud-exact'])[-1]
    assert np.linalg.eigvalsh(free).min() < 0
    for name in ('Maud-exact', 'Maud-nodal'):
        assert saddles.same_point(ends[name], ends['Sella'])


def test_same_point_sees_rigid_motion_not_a_different_point():
    atoms = saddles.make_start('all_pairs', 5, 0, 0.0)
    moved = saddles.fresh_copy(atoms)
    rotation = np.linalg.qr(np.random.default_rng(1).normal(size=(3, 3)))[0]
    moved.positions = atoms.positions[::-1] @ rotation.T + 0.7
    assert saddles.same_point(atoms, moved)
    moved.positions[0] += 1e-3
    assert not saddles.same_point(atoms, moved)


def test_analytic_hessian_for_sella_embeds_the_plane():
    atoms = saddles.make_start('six', 6, 0, 0.0)
    full = saddles.analytic_hessian(atoms)
    flat = atoms.calc.get_hessian(atoms)
    assert full.shape == (18, 18)
    np.testing.assert_array_equal(full.reshape(6, 3, 6, 3)[:, :2, :, :2].reshape(12, 12),
                                  flat)
    assert not full.reshape(6, 3, 6, 3)[:, 2].any()


def test_tool_writes_its_table(tmp_path, capsys):
    assert saddles.main(['--starts', 'cage:4:0', 'six:6:0', '--optimizers', 'Maud-exact',
                         'Sella', '--out', str(tmp_path)]) == 0
    table = (tmp_path / 'saddles.md').read_text()
    assert '| cage:4:0 | 0 | 7 |' in table and ' i1 = |' in table
    assert "- Maud-exact: an index-1 saddle (fmax <= 1e-06) from 2 of 2 starts (2 Sella's)" \
        in table
    assert (tmp_path / 'saddles.csv').read_text().count('\n') == 5
