"""Saddle searches with ``Maud(target='saddle')`` from the starts of
ase_maud.saddles.starts: the index and mode climbed, their errors, large scenes,
resumed runs and damaged restart files."""

import json
import zlib

import numpy as np
import pytest
from ase.constraints import FixAtoms
from ase.io import read
from ase.mep import NEB
from ase.optimize.optimize import Optimizer

from ase_maud import Maud, MaudError, WrongIndexError
from ase_maud.analysis.stationary import classify, displace_along_mode, same_point
from ase_maud.counting import fresh_copy
from ase_maud.optimize.models.exact import ExactModel
from ase_maud.optimize.restart_file import FORMAT, STATE_ROWS, RestartFile
from ase_maud.optimize.step_rules import LOWEST_MODES
from ase_maud.saddles.starts import saddle_start
from ase_maud.scenes.catalogue import build
from ase_maud.scenes.saddle_scenes import chords

FMAX = 1e-6


def test_same_point_sees_rigid_motion_not_a_different_point():
    atoms = saddle_start('all_pairs', 5, 0, 0.0)
    moved = fresh_copy(atoms)
    rotation = np.linalg.qr(np.random.default_rng(1).normal(size=(3, 3)))[0]
    moved.positions = atoms.positions[::-1] @ rotation.T + 0.7
    assert same_point(atoms, moved)
    moved.positions[0] += 1e-3
    assert not same_point(atoms, moved)


# -- target='saddle': eigenvector following --------------------------------------

def _verified_index(atoms):
    """The index of ``atoms``' end point from the analytic Hessian of a fresh
    calculator (not the run's), and whether it is stationary to ``FMAX``."""
    point = classify(fresh_copy(atoms), ftol=FMAX)
    return point.index, point.stationary and not point.n_zero


@pytest.mark.parametrize('seed', range(3))
@pytest.mark.parametrize('order', [1, 2])
@pytest.mark.parametrize('size', [9, 10])
def test_saddle_search_climbs_the_intershell_rotation(size, order, seed):
    """From a 2D trap cluster's minimum moved along its lowest mode (the
    rotation of the inner shell against the outer one), ``target='saddle'``
    converges on a point whose index, from a fresh analytic Hessian, is the
    order sought; the run says so in ``found``."""
    start = saddle_start('all_pairs2d', size, seed, 'up')
    atoms = fresh_copy(start)
    opt = Maud(atoms, target='saddle', order=order, logfile=None)
    assert opt.run(fmax=FMAX, steps=300)
    assert opt.found.index == order and opt.found.verdict == 'saddle'
    assert _verified_index(atoms) == (order, True)


@pytest.mark.parametrize('seed', range(4))
def test_ring_buckles_through_an_index_two_saddle(seed):
    """A ring's minimum climbed along two modes (the sixth lowest named by
    ``mode``, with the lowest) reaches an index-2 buckled ring."""
    atoms = build('ring', 12, seed=seed)
    Maud(atoms, logfile=None).run(fmax=1e-9, steps=3000)
    opt = Maud(atoms, target='saddle', order=2, mode=5, logfile=None)
    assert opt.run(fmax=FMAX, steps=300)
    assert _verified_index(atoms) == (2, True)


@pytest.mark.slow   # 6 s
def test_ring_triangular_buckling_is_a_saddle_or_says_it_is_not():
    """Climbing a ring's minimum along the triangular buckling (radial
    ``cos 3 theta``) reaches a verified index-1 saddle from some seeds
    (measured: 1 of 6); from the others the climb does not level off and the
    run raises (the ring spreads: DivergenceError) or returns False (no
    silent success)."""
    found = 0
    for seed in range(6):
        atoms = build('ring', 12, seed=seed)
        Maud(atoms, logfile=None).run(fmax=1e-9, steps=3000)
        x = atoms.positions - atoms.positions.mean(axis=0)
        angle = np.arctan2(x[:, 1], x[:, 0])
        buckling = x / np.linalg.norm(x, axis=1)[:, None] * np.cos(3 * angle)[:, None]
        try:
            converged = Maud(atoms, target='saddle', mode=buckling,
                             logfile=None).run(fmax=FMAX, steps=300)
        except MaudError:
            continue
        if converged:
            assert _verified_index(atoms) == (1, True)
            found += 1
    assert found >= 1


@pytest.mark.parametrize('seed', range(3))
@pytest.mark.parametrize('how', ['index', 'vector'])
def test_mode_picks_the_mode_climbed(seed, how):
    """``mode`` (an index of the Hessian's modes at the start, or a move
    along one) is the mode the first step climbs."""
    atoms = build('all_pairs2d', 9, seed=seed)
    Maud(atoms, logfile=None).run(fmax=1e-9, steps=3000)
    modes = ExactModel('saddle').at(atoms).eigenpairs(0, None)[1]
    mode = 3 if how == 'index' else -2.0 * modes[3]
    opt = Maud(atoms, target='saddle', mode=mode, logfile=None)
    opt.run(fmax=FMAX, steps=1)
    assert abs(np.vdot(opt.state.modes[0], modes[3])) == pytest.approx(1.0, abs=1e-9)
    assert np.vdot(opt.state.v, modes[3]) * (1 if how == 'index' else -1) > 0


def test_converging_on_another_index_raises(monkeypatch):
    """A run that stops at a stationary point of another index than the
    order sought raises WrongIndexError (here ASE's fmax test alone, so that
    the minimum it starts from counts as converged)."""
    atoms = build('all_pairs2d', 9)
    Maud(atoms, logfile=None).run(fmax=1e-9, steps=3000)
    monkeypatch.setattr(Maud, 'gradient_converged', Optimizer.gradient_converged)
    with pytest.raises(WrongIndexError, match='minimum of index 0, not of index 1'):
        Maud(atoms, target='saddle', logfile=None).run(fmax=FMAX)


@pytest.mark.parametrize('mode, why', [
    (-1, 'an index >= 0'), (np.ones((3, 3)), 'finite move of the 9 points'),
    ('lowest', 'finite move'), (99, 'not one of the 15 internal modes')])
def test_bad_mode_is_named(mode, why):
    atoms = build('all_pairs2d', 9)
    with pytest.raises(ValueError, match=why):
        Maud(atoms, target='saddle', mode=mode, logfile=None).run(fmax=FMAX, steps=2)


def test_order_beyond_the_modes_is_named():
    atoms = build('all_pairs2d', 4)
    with pytest.raises(ValueError, match='order=6 exceeds the 5 internal modes'):
        Maud(atoms, target='saddle', order=6, logfile=None).run(fmax=FMAX, steps=2)


@pytest.mark.parametrize('seed', range(3))
def test_climbing_image_neb_between_the_joined_minima_meets_the_saddle(seed):
    """The minima an index-1 saddle found by ``target='saddle'`` joins (relaxed
    from either side of its unstable mode), joined again by ASE's NEB with a
    climbing image (relaxed by Maud): the highest image is the saddle, in
    energy to 1e-9 relative."""
    atoms = fresh_copy(saddle_start('all_pairs2d', 9, seed, 'up'))
    Maud(atoms, target='saddle', logfile=None).run(fmax=1e-8, steps=300)
    point = classify(atoms, ftol=1e-7)
    ends = displace_along_mode(atoms, point)
    for end in ends:
        Maud(end, logfile=None).run(fmax=1e-8, steps=2000)
        assert classify(end).verdict == 'minimum'
    images = [ends[0], *(fresh_copy(ends[0]) for _ in range(5)), ends[1]]
    neb = NEB(images, climb=True, method='improvedtangent')
    neb.interpolate()
    with Maud(neb, logfile=None) as opt:
        assert opt.run(fmax=1e-4, steps=2000)
    highest = max(image.get_potential_energy() for image in images)
    assert highest == pytest.approx(atoms.get_potential_energy(), rel=1e-9)


@pytest.mark.integration
@pytest.mark.parametrize('seed', range(2))
@pytest.mark.parametrize('order', [1, 2])
def test_large_scene_saddle_search_follows_the_lowest_modes(seed, order):
    """Above the exact model's size (here 160 free DOFs) ``target='saddle'``
    takes the springs model: the lowest modes from Hessian-vector products,
    the truncated Newton move on the rest; it reaches a point of the index
    sought, verified from the dense analytic Hessian (seeds 2-4 pass too,
    both orders, 22-75 steps: measured 2026-12-03)."""
    start = saddle_start('all_pairs2d', 80, seed, 'up')
    atoms = fresh_copy(start)
    opt = Maud(atoms, target='saddle', order=order, logfile=None)
    assert opt.model.name == 'springs'
    assert opt.run(fmax=FMAX, steps=1000)
    assert _verified_index(atoms) == (order, True)


@pytest.mark.parametrize('seed', range(3))
def test_springs_search_leaves_a_converged_minimum(seed):
    """From a minimum relaxed to fmax 1e-8 (its first step already meets
    ``fmax``: the index test runs before any move, where main raised a
    TypeError in ``gradient_converged``) the springs model's search leaves
    it and ends on a verified index-1 saddle."""
    atoms = build('hanging_net', 6, seed=seed)
    assert Maud(atoms, logfile=None).run(fmax=1e-8, steps=5000)
    opt = Maud(atoms, target='saddle', order=1, model='springs', logfile=None)
    assert opt.run(fmax=FMAX, steps=500)
    assert opt.nsteps > 0
    assert _verified_index(atoms) == (1, True)


@pytest.mark.parametrize('seed', range(3))
def test_first_index_check_starts_from_the_mode_given(seed):
    """At a converged minimum the index test runs before any move; its LOBPCG
    starts from the move given as ``mode``: at most half the products of a
    cold start (measured 2026-12-04: 25 against 105-111)."""
    atoms = chords(40, seed)
    assert Maud(atoms, logfile=None).run(fmax=1e-9, steps=5000)
    lowest = classify(atoms).modes[0]
    vectors = []
    for mode in (None, lowest):
        opt = Maud(fresh_copy(atoms), target='saddle', model='springs', mode=mode,
                   logfile=None)
        assert not next(opt.irun(fmax=FMAX, steps=10))   # the minimum is not reported
        vectors.append(opt.work.hvp_vectors)
    assert 0 < vectors[1] <= vectors[0] / 2


@pytest.mark.parametrize('seed', range(3))
@pytest.mark.parametrize('scene, size', [('all_pairs2d', 5), ('all_pairs2d', 7),
                                         ('all_pairs', 6), ('all_pairs', 8), ('all_pairs2d', 8)])
def test_springs_search_on_a_tiny_constrained_scene(scene, size, seed):
    """With 8 points or fewer and one of them fixed the springs model takes
    its dense path for the lowest modes (SciPy's LOBPCG refuses so few
    rows, its dense fallback the constraint): from a minimum moved along its
    lowest mode it reaches a verified index-1 saddle."""
    atoms = build(scene, size, seed=seed)
    atoms.set_constraint(FixAtoms([0]))
    assert Maud(atoms, logfile=None).run(fmax=1e-9, steps=5000)
    mode = classify(atoms).modes[0]
    atoms.positions += 0.1 * mode / np.linalg.norm(mode, axis=1).max()
    opt = Maud(atoms, target='saddle', order=1, model='springs', logfile=None)
    assert opt.run(fmax=FMAX, steps=500)
    assert _verified_index(atoms) == (1, True)


def _frames(start, directory, stop=None, **keywords):
    """The frames of a search from ``start`` to ``FMAX``, run whole
    (``stop`` None) or stopped after ``stop`` steps and resumed from its
    restart file with ``Maud.resume``; and its end point."""
    directory.mkdir()
    atoms = fresh_copy(start)
    restart, trajectory = directory / 'maud.json', directory / 'maud.traj'
    if stop is not None:
        with Maud(atoms, target='saddle', restart=restart, trajectory=trajectory,
                  logfile=None, **keywords) as opt:
            assert not opt.run(fmax=FMAX, steps=stop)
        atoms = fresh_copy(start)
        opt = Maud.resume(atoms, restart=restart, trajectory=trajectory,
                          target='saddle', logfile=None, **keywords)
    else:
        opt = Maud(atoms, target='saddle', trajectory=trajectory, logfile=None,
                   **keywords)
    with opt:
        assert opt.run(fmax=FMAX, steps=300)
    return [frame.positions for frame in read(trajectory, ':')], atoms


def _assert_same_search(whole, resumed):
    (frames, end), (again, resumed_end) = whole, resumed
    assert len(again) == len(frames)
    for k, (x, y) in enumerate(zip(frames, again, strict=True)):
        assert np.abs(x - y).max() <= 1e-12, f'frame {k} differs'
    np.testing.assert_allclose(resumed_end.positions, end.positions, rtol=0, atol=1e-12)


@pytest.mark.parametrize('seed', range(3))
@pytest.mark.parametrize('order', [1, 2])
def test_saddle_search_resumes_exactly_after_any_step(tmp_path, seed, order):
    """A search stopped after any of its steps and resumed from its restart
    file makes the uninterrupted search's steps (the followed modes, the
    trust fraction and the prediction it is judged by carry over) and ends
    on the same point, of the index sought."""
    start = saddle_start('all_pairs2d', 12, seed, 'up')
    whole = _frames(start, tmp_path / 'whole', order=order)
    steps = len(whole[0]) - 1
    assert steps >= 3
    for stop in range(1, steps):
        resumed = _frames(start, tmp_path / f'stop{stop}', stop, order=order)
        _assert_same_search(whole, resumed)
    assert _verified_index(whole[1]) == (order, True)


@pytest.mark.parametrize('seed', range(2))
def test_large_scene_saddle_search_resumes_exactly(tmp_path, seed):
    """The same with the lowest modes only (the springs model: LOBPCG
    started from the last step's modes, the trust ratio judged by the last
    move's prediction), stopped after early steps, while the trust fraction
    still changes."""
    start = saddle_start('all_pairs2d', 12, seed, 'up')
    whole = _frames(start, tmp_path / 'whole', model='springs')
    for stop in (2, 6):
        _assert_same_search(whole, _frames(start, tmp_path / f'stop{stop}', stop,
                                           model='springs'))
    assert _verified_index(whole[1]) == (1, True)


@pytest.mark.parametrize('seed', range(3))
def test_large_scene_search_keeps_its_next_lowest_modes_for_the_next_step(tmp_path, seed):
    """With the lowest modes only, a search keeps the mode it follows and the
    :data:`LOWEST_MODES` next lowest of its last step (orthonormal, the
    start of the next step's LOBPCG), and its restart file holds them all."""
    start = saddle_start('all_pairs2d', 12, seed, 'up')
    restart = tmp_path / 'maud.json'
    with Maud(fresh_copy(start), target='saddle', model='springs', restart=restart,
              logfile=None) as opt:
        assert not opt.run(fmax=FMAX, steps=3)
    modes = opt.state.modes
    assert modes.shape == (1 + LOWEST_MODES, len(start), 3)
    np.testing.assert_allclose(np.einsum('kij,mij->km', modes, modes),
                               np.eye(len(modes)), atol=1e-8)
    assert json.loads(restart.read_text())['modes'] == 1 + LOWEST_MODES
    saved = RestartFile(restart, 1 + LOWEST_MODES).read()['state'].modes
    np.testing.assert_array_equal(saved, modes)


def _modes_rows(document):
    """The rows of the arrays file that hold the saddle search's modes."""
    first = document['slot'] * (STATE_ROWS + document['modes']) + STATE_ROWS
    return slice(first, first + document['modes'])


def _change_a_mode(value, crc):
    """Set one number of the followed modes (chosen by ``rng``) to ``value``
    of it, and the CRC-32 of their rows to match if ``crc``."""
    def edit(document, table, rng):
        rows = _modes_rows(document)
        row, column = rng.integers(rows.start, rows.stop), rng.integers(table.shape[1])
        table[row, column] = value(table[row, column])
        if crc:
            document['crc']['modes'] = zlib.crc32(table[rows].tobytes())
    return edit


def _set(key, value):
    def edit(document, table, rng):
        document[key] = value
    return edit


def _unchanged(document, table, rng):
    pass


#: A restart file of an order-2 search damaged, or resumed with other
#: keywords: (the damage, the resumed run's keywords, the error's words).
MODES_DAMAGES = {
    'a mode changed': (_change_a_mode(lambda v: v + 0.5, crc=False), {'order': 2},
                       r": rows \d+-\d+ of '.*maud.json.arrays' are not what it wrote "
                       r"\(the saddle search's modes, 'modes'"),
    'a mode NaN': (_change_a_mode(lambda v: np.nan, crc=True), {'order': 2},
                   r"hold non-finite numbers \(the saddle search's modes, 'modes'\)"),
    'modes negative': (_set('modes', -1), {'order': 2},
                       "is damaged: 'modes' must be null or a whole number"),
    'modes a string': (_set('modes', '2'), {'order': 2},
                       "is damaged: 'modes' must be null or a whole number"),
    'predicted a string': (_set('predicted', 'x'), {'order': 2},
                           "is damaged: 'predicted' must be null or a finite number"),
    'no CRC of the modes': (lambda d, t, r: d['crc'].pop('modes'), {'order': 2},
                            'is damaged: \'crc\' must be {"state": a CRC-32, "modes"'),
    'resumed with order 1': (_unchanged, {'order': 1},
                             "is of another run: 'modes' 2 in it, 1 in this run"),
    'resumed as a minimisation': (_unchanged, {'target': 'minimum'},
                                  "is of another run: 'modes' 2 in it, None in this run"),
    'the layout before the modes': (
        _set('format', 'maud-restart-3'), {'order': 2},
        r"was not written by this version of Maud \(format 'maud-restart-3', this "
        rf"version reads '{FORMAT}'\); delete it and its arrays file"),
}


@pytest.mark.parametrize('damage', sorted(MODES_DAMAGES))
@pytest.mark.parametrize('seed', range(3))
def test_damaged_or_other_modes_of_a_restart_file_are_named(tmp_path, damage, seed):
    """The followed modes of a restart file are checked as its other rows and
    fields are: damaged ones, or a file of a run that follows another number
    of modes, are refused naming the file and the field, before the atoms
    move."""
    edit, keywords, match = MODES_DAMAGES[damage]
    start = saddle_start('all_pairs2d', 12, seed, 'up')
    restart = tmp_path / 'maud.json'
    with Maud(fresh_copy(start), target='saddle', order=2, restart=restart,
              logfile=None) as opt:
        assert not opt.run(fmax=FMAX, steps=3)
    document = json.loads(restart.read_text())
    arrays = tmp_path / 'maud.json.arrays'
    table = np.fromfile(arrays).reshape(-1, document['rows'])
    edit(document, table, np.random.default_rng(seed))
    table.tofile(arrays)
    restart.write_text(json.dumps(document))
    atoms = fresh_copy(start)
    with pytest.raises(ValueError, match=r"restart file '.*maud.json'.*" + match):
        Maud(atoms, restart=restart, logfile=None, **{'target': 'saddle', **keywords})
    np.testing.assert_array_equal(atoms.positions, start.positions)
