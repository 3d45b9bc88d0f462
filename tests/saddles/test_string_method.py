"""The preconditioned string (ase_maud.saddles.string_method): even spacing and
tangents checked on a circle, the capped step, and a climbing image at rest on
a small dome's snap-through saddle (verified index 1 by a fresh calculator, at
the energy the refinement of saddle_between reaches)."""

import threading

import numba
import numpy as np
import pytest

from ase_maud import Maud
from ase_maud.analysis.stationary import classify
from ase_maud.counting import fresh_copy
from ase_maud.saddles import string_method
from ase_maud.saddles.between_minima import mirrored, reflection, saddle_between
from ase_maud.saddles.string_method import MAX_MOVE, PreconditionedString
from ase_maud.scenes.saddle_scenes import rim


def circle_band(seed: int, images: int) -> tuple[np.ndarray, np.ndarray]:
    """Points of one 'atom' on a unit circle in the x-y plane at seeded, uneven angles in
    (0, pi/2) (the ends at 0 and pi/2), images x 1 x 3; and the angles."""
    rng = np.random.default_rng(seed)
    angles = np.concatenate([[0.0], np.sort(rng.uniform(0, np.pi / 2, images)), [np.pi / 2]])
    points = np.column_stack([np.cos(angles), np.sin(angles), np.zeros_like(angles)])
    return points[:, None, :], angles


@pytest.mark.parametrize('seed', range(4))
def test_images_are_spaced_evenly_along_the_curve(seed):
    """On a quarter circle sampled unevenly, the spaced images stay on the circle and
    their angles are even (to the cubic spline's error), the ends kept; with an image
    kept, it stays and each side is even on its own."""
    positions, angles = circle_band(seed, 9)
    spaced = string_method._spaced(positions, None)[:, 0]
    assert np.allclose(spaced[[0, -1]], positions[[0, -1], 0], atol=0)
    assert np.linalg.norm(spaced, axis=1) == pytest.approx(1, abs=5e-3)
    assert np.diff(np.arctan2(spaced[:, 1], spaced[:, 0])) == pytest.approx(
        np.full(10, np.pi / 20), abs=1e-2)
    keep = 1 + int(np.random.default_rng(seed).integers(9))
    kept = string_method._spaced(positions, keep)[:, 0]
    assert np.array_equal(kept[keep], positions[keep, 0])
    turned = np.arctan2(kept[:, 1], kept[:, 0])
    for side in (turned[:keep + 1], turned[keep:]):
        assert np.diff(side) == pytest.approx(np.full(len(side) - 1, np.diff(side).mean()),
                                              abs=1e-2)


@pytest.mark.parametrize('seed', range(4))
def test_tangents_are_the_circles(seed):
    """The unit tangent at each image of the quarter circle is (-sin, cos) of its angle
    (to the spline's error at uneven spacing)."""
    positions, angles = circle_band(seed, 9)
    tangents = string_method._tangents(positions)[:, 0]
    assert np.linalg.norm(tangents, axis=1) == pytest.approx(1)
    expected = np.column_stack([-np.sin(angles), np.cos(angles), np.zeros_like(angles)])
    assert np.abs(tangents - expected).max() < 0.05


def test_a_band_without_moving_images_is_refused():
    first = rim(4, 0)
    with pytest.raises(ValueError, match='at least one moving image.*band of 2'):
        PreconditionedString([first, fresh_copy(first)])


@pytest.mark.parametrize('seed', [0, 1])
def test_no_point_moves_more_than_the_cap_in_a_step(seed, monkeypatch):
    """A band interpolated straight through the rim's plane (large forces), spacing
    switched off: one step moves no point by more than MAX_MOVE a."""
    first = rim(6, seed)
    assert Maud(first, logfile=None).run(fmax=1e-6, steps=2000)
    second = mirrored(first, fmax=1e-6)
    band = [fresh_copy(first) for _ in range(4)] + [second]
    for t, image in zip(np.linspace(0, 1, 5), band, strict=True):
        image.positions = (1 - t) * first.positions + t * second.positions
    monkeypatch.setattr(string_method, '_spaced', lambda positions, keep: positions)
    before = np.array([image.positions for image in band])
    string = PreconditionedString(band)
    assert not string.relax(target=1e-12, steps=1, climb=False)
    moved = np.linalg.norm(np.array([image.positions for image in band]) - before, axis=2)
    assert moved.max() <= MAX_MOVE * first.calc.potential.a * (1 + 1e-12)
    assert moved.max() > 0 and string.steps == 1


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_a_climbing_image_at_rest_is_the_snap_through_saddle(seed):
    """A 5x5 dome and its mirror image: the band from saddle_between relaxed on with its
    climbing image to a residual of 1e-7 Q a holds a stationary point (forces below it)
    that a fresh calculator classifies as index 1, at the energy of the saddle the
    refinement reached."""
    first = rim(5, seed)
    assert Maud(first, logfile=None).run(fmax=1e-8, steps=5000)
    second = mirrored(first, fmax=1e-8)
    found = saddle_between(first, second)
    assert found.saddle is not None, found.outcome
    string = PreconditionedString(found.band)
    assert string.relax(target=1e-7, steps=3000, climb=True), string.residual
    top = max(found.band[1:-1], key=lambda image: image.get_potential_energy())
    assert np.abs(top.get_forces()).max() < 1e-7
    point = classify(fresh_copy(top))
    assert (point.index, point.n_zero) == (1, 0)
    assert top.get_potential_energy() == pytest.approx(
        found.saddle.get_potential_energy(), rel=1e-9)


def test_the_images_step_on_threads_of_their_own_the_same_whatever_the_count(monkeypatch):
    """A band of a 24x24 dome (576 points: numba's direct sum splits it into chunks on
    more than one thread) relaxed for a few steps with numba on one thread and on two:
    the same positions to the last bit; with numba on one every image evaluated on the
    caller's thread, with two each on a thread of its own with numba on one there, two at
    a time."""
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("numba's pool has one thread")
    seed = int(np.random.default_rng().integers(1000))
    first = rim(24, seed)
    assert Maud(first, logfile=None).run(fmax=1e-4, steps=2000)
    second = reflection(first)
    at_once, seen = [], set()
    evaluate, semaphore = string_method._evaluate, string_method.threading.BoundedSemaphore

    def recorded(image, *args):
        seen.add((id(image), threading.get_ident(), numba.get_num_threads()))
        return evaluate(image, *args)

    def counted(value):
        at_once.append(value)
        return semaphore(value)

    monkeypatch.setattr(string_method, '_evaluate', recorded)
    monkeypatch.setattr(string_method.threading, 'BoundedSemaphore', counted)
    ends = []
    for threads in (1, 2):
        band = [fresh_copy(first) for _ in range(5)] + [fresh_copy(second)]
        for t, image in zip(np.linspace(0, 1, 6), band, strict=True):
            image.positions = (1 - t) * first.positions + t * second.positions
        before = numba.get_num_threads()
        numba.set_num_threads(threads)
        seen.clear()
        try:
            PreconditionedString(band).relax(target=1e-12, steps=4, climb=True)
        finally:
            numba.set_num_threads(before)
        ends.append(np.array([image.positions for image in band]))
        assert len(seen) == 4 and {count for *_, count in seen} == {1}
        idents = {ident for _, ident, _ in seen}
        assert idents == {threading.get_ident()} if threads == 1 else (
            len(idents) == 4 and threading.get_ident() not in idents)
    assert at_once == [2]
    assert np.array_equal(*ends), seed
